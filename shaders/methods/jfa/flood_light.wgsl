// Method `jfa-l`, §4.1 "Generating Penumbra Map": one round of flooding over the shadow map.
// Each texel looks at its 8 neighbours at ±step, computes the intensity every occluder they
// carry gives its own surface point, and keeps the occluder giving the minimum intensity —
// the one that blocks the most light shapes the penumbra (§4.1). Occluders whose ray misses
// the light are not taken and not passed on (§3) — except, with `inner` on (past the paper),
// into the footprints of occluders: a texel no deeper than the occluder point keeps the
// nearest silhouette point (key 2 + d/(d + 1), d in texels, below a seed's and above any
// penumbra's), so that the final pass finds, for a receiver in hard shadow, the silhouette
// whose edge bounds what it sees of the light (its inner penumbra).

#import methods/jfa/common.wgsl

// One workgroup per listed tile (`list_tiles` in common.wgsl).
@compute @workgroup_size(8, 8)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>) {
    let p = listed_cell(group, local);
    let res = i32(frame.sizes.z);
    if p.x < 0 || any(p >= vec2<i32>(res)) {
        return;
    }
    let index = u32(p.y * res + p.x);
    var best = src[index];
    var best_key = key_of(best);
    let receiver_depth = map_depth_at(p);
    let receiver = shadow_point_at(p, receiver_depth);
    if receiver.w > 0.0 {
        // The distinct occluders the neighbours offer besides the one held, in neighbour
        // order, gathered first and then weighed: neighbours mostly hand on the same
        // occluder, and on a CPU rasteriser a key computed for one lane is paid by all 8, so
        // weighing inside the neighbour loop paid for up to 8 keys per texel where one or two
        // are new. A repeated occluder has the key of its first offer, which a strict `<`
        // keeps, so the result is the same.
        var offers: array<vec3<f32>, 8>;
        var count = 0u;
        for (var k = 0u; k < 9u; k++) {
            let n = jump_neighbour(p, k, params.step, vec2<i32>(res));
            if n.x < 0 {
                continue;
            }
            let candidate = src[u32(n.y * res + n.x)];
            if is_empty(candidate) || all(candidate.xyz == best.xyz) {
                continue;
            }
            var seen = false;
            for (var j = 0u; j < count; j++) {
                seen = seen || all(offers[j] == candidate.xyz);
            }
            if !seen {
                offers[count] = candidate.xyz;
                count++;
            }
        }
        for (var j = 0u; j < count; j++) {
            let candidate = offers[j];
            let i = intensity_key(receiver.xyz, candidate);
            var key = i.x;
            if i.y == 0.0 {
                let occluder = to_light_space(candidate);
                if params.inner == 0u || receiver_depth > occluder.depth * (1.0 + params.silhouette_relative) {
                    continue;
                }
                let d = distance(occluder.uv * f32(res), vec2<f32>(p) + 0.5);
                key = SEED_KEY + d / (d + 1.0);
            }
            if key < best_key {
                best = packed(candidate, key);
                best_key = key;
            }
        }
    }
    dst[index] = best;
    if !is_empty(best) {
        mark_tile(p);
    }
}
