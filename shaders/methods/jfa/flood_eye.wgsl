// Method `jfa-e`, §5.1 "Generating Penumbra Regions": one round of flooding over the screen.
// A pixel in hard shadow keeps the occluder giving it the highest intensity (inner penumbra),
// a lit pixel the lowest (outer); the key minimised is 1 − luminance or luminance. The two
// remedies of §5.2 against "jump too far" are switchable: flood only to pixels of the
// boundary pixel's object, and require the midpoint between the boundary pixel and this one
// to be in a penumbra of the same occluder.

#import methods/jfa/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32, @builtin(workgroup_id) group: vec3<u32>) {
    if !tile_in_reach(local, group.xy) {
        return;
    }
    let pixel = id.xy;
    let size = vec2<i32>(frame.sizes.xy);
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    let p = vec2<i32>(pixel);
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    var best = src[index];
    var best_origin = src[index + 1u];
    var best_key = key_of(best);
    let flag = flags[pixel.y * frame.sizes.x + pixel.x];
    if (flag & COVERED) != 0u {
        let here = textureLoad(gbuf_position, pixel, 0).xyz;
        let object = f32(textureLoad(gbuf_id, pixel, 0).r);
        let inside = (flag & HARD) != 0u;
        for (var k = 0u; k < 9u; k++) {
            let n = jump_neighbour(p, k, params.step, size);
            if n.x < 0 {
                continue;
            }
            let at = 2u * (u32(n.y) * frame.sizes.x + u32(n.x));
            let candidate = src[at];
            // The occluder held already has its key for this pixel: whatever its origin, the
            // same occluder gives the same key and would not replace it.
            if is_empty(candidate) || all(candidate.xyz == best.xyz) {
                continue;
            }
            let origin = src[at + 1u];
            if params.same_object == 1u && origin.z != object {
                continue;
            }
            let i = intensity(here, candidate.xyz, inside);
            let key = select(luminance(i.rgb), 1.0 - luminance(i.rgb), inside);
            if i.w == 0.0 || key >= best_key {
                continue;
            }
            // Only a candidate that would win pays for the midpoint check.
            if params.midpoint == 1u {
                // §5.2's continuity check, read as: the midpoint between the boundary pixel
                // and this one must itself be in a penumbra of the same occluder. Asking
                // instead whether the midpoint already holds a record would depend on the
                // order jump flooding reaches pixels (far ones first) and cut real penumbrae.
                let mid = vec2<u32>((vec2<i32>(origin.xy) + p) / 2);
                let mid_flag = flags[mid.y * frame.sizes.x + mid.x];
                if (mid_flag & COVERED) == 0u {
                    continue;
                }
                let at_mid = intensity(textureLoad(gbuf_position, mid, 0).xyz, candidate.xyz, (mid_flag & HARD) != 0u);
                if at_mid.w == 0.0 {
                    continue;
                }
            }
            best = packed(candidate.xyz, key);
            best_origin = origin;
            best_key = key;
        }
    }
    dst[index] = best;
    dst[index + 1u] = best_origin;
    if !is_empty(best) {
        mark_tile(p);
    }
}
