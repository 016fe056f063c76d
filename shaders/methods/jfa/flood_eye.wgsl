// Method `jfa-e`, §5.1 "Generating Penumbra Regions": one round of flooding over the screen.
// A pixel in hard shadow keeps the occluder giving it the highest intensity (inner penumbra),
// a lit pixel the lowest (outer); the key minimised is 1 − luminance or luminance. The two
// remedies of §5.2 against "jump too far" are switchable: flood only to pixels of the
// boundary pixel's object, and require the midpoint between the boundary pixel and this one
// to be in a penumbra of the same occluder.

#import methods/jfa/common.wgsl
#import methods/jfa/neighbours.wgsl

fn record_at(p: vec2<i32>) -> Record {
    return src[u32(p.y) * frame.sizes.x + u32(p.x)];
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    let size = vec2<i32>(frame.sizes.xy);
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    let p = vec2<i32>(pixel);
    var best = record_at(p);
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
            // Only the occluder is read until it proves useful: most neighbours carry none.
            let occluder = src[u32(n.y) * frame.sizes.x + u32(n.x)].occluder;
            if occluder.w == 0.0 {
                continue;
            }
            let carried = record_at(n);
            if params.same_object == 1u && carried.origin.z != object {
                continue;
            }
            if params.midpoint == 1u {
                // §5.2's continuity check, read as: the midpoint between the boundary pixel
                // and this one must itself be in a penumbra of the same occluder. Asking
                // instead whether the midpoint already holds a record would depend on the
                // order jump flooding reaches pixels (far ones first) and cut real penumbrae.
                let mid = vec2<u32>((vec2<i32>(carried.origin.xy) + p) / 2);
                let mid_flag = flags[mid.y * frame.sizes.x + mid.x];
                if (mid_flag & COVERED) == 0u {
                    continue;
                }
                let at_mid = intensity(textureLoad(gbuf_position, mid, 0).xyz, carried.occluder.xyz, (mid_flag & HARD) != 0u);
                if at_mid.w == 0.0 {
                    continue;
                }
            }
            let i = intensity(here, carried.occluder.xyz, inside);
            let key = select(luminance(i.rgb), 1.0 - luminance(i.rgb), inside);
            if i.w > 0.0 && key < best.intensity.w {
                best = Record(carried.occluder, vec4<f32>(i.rgb, key), carried.origin);
            }
        }
    }
    dst[pixel.y * frame.sizes.x + pixel.x] = best;
}
