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
    frame = frame_uniform;
    params = params_uniform;
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
        // Each neighbour's occluder weighed as it comes, the one held skipped (its key is
        // the pixel's). Neighbours mostly hand on the same occluder, whose repeats have the
        // key of its first offer, which a strict `<` keeps. Gathering the distinct offers
        // first in a private array and weighing each once costs more than the repeated keys,
        // which come from a grid and are cheap.
        //
        // Only the neighbours holding a record are weighed, found first from each record's w
        // alone (one load, where weighing a record costs its whole vec4 and a key): lanes run
        // in lockstep and a loop runs as many times as its busiest lane needs, so a SIMD group
        // of texels offered few records — most of the early rounds' tiles — weighs few, where
        // a loop over all eight would weigh eight.
        let held = best.xyz;
        var offers = 0u;
        for (var k = 0u; k < JUMP_NEIGHBOURS; k++) {
            let n = jump_neighbour(p, k, params.step, vec2<i32>(res));
            if n.x >= 0 && src[u32(n.y * res + n.x)].w != 0.0 { // not `is_empty`: the w alone is loaded
                offers |= 1u << k;
            }
        }
        while offers != 0u {
            let k = firstTrailingBit(offers);
            offers &= offers - 1u;
            let n = jump_neighbour(p, k, params.step, vec2<i32>(res));
            let candidate = src[u32(n.y * res + n.x)];
            if all(candidate.xyz == held) {
                continue;
            }
            let i = intensity_key(receiver.xyz, candidate.xyz);
            var key = i.x;
            if i.y == 0.0 {
                let occluder = to_light_space(candidate.xyz);
                if params.inner == 0u || receiver_depth > occluder.depth * (1.0 + params.silhouette_relative) {
                    continue;
                }
                let d = distance(occluder.uv * f32(res), vec2<f32>(p) + 0.5);
                key = SEED_KEY + d / (d + 1.0);
            }
            if key < best_key {
                best = packed(candidate.xyz, key);
                best_key = key;
            }
        }
    }
    dst[index] = best;
    if !is_empty(best) {
        mark_tile(p);
    }
}
