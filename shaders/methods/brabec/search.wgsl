// Method `brabec`: the neighbourhood search of the light depth map (§3.2 outer penumbra,
// §3.3 inner penumbra, §4.3 sub-pixel distances) of every pixel the lattice and the marking
// passes listed, in one compacted dispatch sized on the GPU.

#import methods/brabec/common.wgsl
#import methods/brabec/colour.wgsl

@compute @workgroup_size(1)
fn listed_size() {
    frame = frame_uniform;
    params = params_uniform;
    search_groups = list_dispatch(atomicLoad(&to_search.count));
}

// The search without jitter (`jitter_texels` 0, the default) and with it: two entry points,
// so the constant compiles the jitter out of the first (see `search`).
@compute @workgroup_size(64)
fn search_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    search_list_position(list_position(group, lane), false);
}

@compute @workgroup_size(64)
fn search_listed_jittered(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    search_list_position(list_position(group, lane), true);
}

// Searches pixel `p` and keeps what it found.
fn search_into(p: vec2<u32>, jittered: bool) {
    let found = search(p, jittered);
    let i = state_index(p);
    state[i].t = found.t;
    state[i].normal = found.normal;
    state[i].edge = found.edge;
}

fn search_list_position(i: u32, jittered: bool) {
    if i < atomicLoad(&to_search.count) {
        search_into(listed_pixel(to_search.pixels[i]), jittered);
    }
}

// A hash in [−0.5, 0.5)² per texel: the optional blocker jitter of §4.3.
fn jitter(t: vec2<i32>) -> vec2<f32> {
    var h = u32(t.x) * 0x8da6b343u ^ u32(t.y) * 0xd8163841u;
    h = (h ^ (h >> 13u)) * 0x5bd1e995u;
    h ^= h >> 15u;
    return (vec2<f32>(f32(h & 0xffffu), f32(h >> 16u)) / 65536.0 - 0.5) * params.jitter;
}

// The nearest hit of a search: its squared distance from P' (texels), depth and texel.
struct Nearest {
    dist2: f32,
    depth: f32,
    texel: vec2<i32>,
    found: bool,
}

// Whether texel `t` (depth bits and id `texel`) is a hit for the search from w: outer pixels
// hit texels nearer the light of other objects, inner ones texels as far of their own object.
fn is_hit(w: Warped, receiver: u32, texel: vec2<u32>) -> bool {
    return (bitcast<f32>(texel.x) < w.depth - w.bias) != w.hard && ((texel.y == receiver) == w.hard || params.use_ids == 0u);
}

// The paper's search order: rings of growing Chebyshev radius k around P''s texel `base`,
// stopping once no closer texel can follow (texel centres on ring k lie at least k − 0.5
// texels from P'), so its cost grows with the distance found, not with r_max. The first of
// equally near hits in the order (ring, row, column) is kept. Used with the §4.3 jitter, which
// moves each hit by up to half a texel: the rings' stopping rule then decides the result.
fn nearest_in_rings(w: Warped, receiver: u32, base: vec2<i32>, rings: i32, r_max: f32) -> Nearest {
    let res = i32(frame.sizes.z);
    var near = Nearest(r_max * r_max, 0.0, vec2<i32>(0), false);
    for (var k = 0; k <= rings; k++) {
        // One square root per ring, not per texel.
        if f32(k) - 0.5 > sqrt(near.dist2) {
            break;
        }
        for (var dy = -k; dy <= k; dy++) {
            let edge_row = dy == -k || dy == k;
            var dx = -k;
            loop {
                if dx > k {
                    break;
                }
                let t = base + vec2<i32>(dx, dy);
                if all(t >= vec2<i32>(0)) && all(t < vec2<i32>(res)) {
                    let texel = map_texels[t.y * res + t.x];
                    if is_hit(w, receiver, texel) {
                        let offset = vec2<f32>(t) + 0.5 + jitter(t) - w.texel;
                        let dist2 = dot(offset, offset);
                        if dist2 < near.dist2 {
                            near = Nearest(dist2, bitcast<f32>(texel.x), t, true);
                        }
                    }
                }
                // Inner rows of the ring: only its two end texels.
                if edge_row || dx == k {
                    dx += 1;
                } else {
                    dx = k;
                }
            }
        }
    }
    return near;
}

// The same nearest hit as `nearest_in_rings` without jitter (where the rings stop only once
// no later texel can be nearer, so theirs is the nearest hit of the whole square [lo, hi]
// within r_max, the first in ring order among equals), found block by block: the summary
// blocks around P' in rings, a block scanned only when its summary allows a hit and its
// nearest texel centre is no farther than the best so far, and ties broken by the texel's
// place in the rings' order. Past the paper, with bit-identical results: in the outer
// penumbra the texels between P' and the occluder, which the rings visit one by one, lie in
// blocks the summary rules out.
fn nearest_in_blocks(w: Warped, receiver: u32, base: vec2<i32>, lo: vec2<i32>, hi: vec2<i32>, r_max: f32) -> Nearest {
    let res = i32(frame.sizes.z);
    let blocks = summary_blocks();
    var near = Nearest(r_max * r_max, 0.0, vec2<i32>(0), false);
    var near_order = 0x7fffffff;
    // P''s own block (floor division: base may lie left of or above the map) and the blocks
    // the square spans.
    let home = vec2<i32>(floor(vec2<f32>(base) / f32(SUMMARY_BLOCK)));
    let b_lo = lo / SUMMARY_BLOCK;
    let b_hi = hi / SUMMARY_BLOCK;
    let rings = max(max(home.x - b_lo.x, b_hi.x - home.x), max(home.y - b_lo.y, b_hi.y - home.y));
    for (var kb = 0; kb <= rings; kb++) {
        // Blocks of ring kb lie outside the (kb − 1) rings around P''s own block: their texel
        // centres are at least 8(kb − 1) + 0.5 texels from P'.
        let bound = f32(SUMMARY_BLOCK * (kb - 1)) + 0.5;
        if kb > 0 && bound * bound > near.dist2 {
            break;
        }
        for (var by = max(home.y - kb, b_lo.y); by <= min(home.y + kb, b_hi.y); by++) {
            let edge_row = abs(by - home.y) == kb;
            // An inner row starts at the ring's own left block, which may lie left of the
            // square (then skipped): clamping it would visit an inner ring's block again.
            var bx = select(home.x - kb, max(home.x - kb, b_lo.x), edge_row);
            loop {
                if bx > min(home.x + kb, b_hi.x) {
                    break;
                }
                let block_lo = max(vec2<i32>(bx, by) * SUMMARY_BLOCK, lo);
                let block_hi = min(vec2<i32>(bx, by) * SUMMARY_BLOCK + SUMMARY_BLOCK - 1, hi);
                let closest = clamp(w.texel, vec2<f32>(block_lo) + 0.5, vec2<f32>(block_hi) + 0.5) - w.texel;
                if bx >= b_lo.x && dot(closest, closest) <= near.dist2 && block_may_hit(w, receiver, summary[by * blocks + bx]) {
                    for (var ty = block_lo.y; ty <= block_hi.y; ty++) {
                        for (var tx = block_lo.x; tx <= block_hi.x; tx++) {
                            let t = vec2<i32>(tx, ty);
                            let texel = map_texels[ty * res + tx];
                            let offset = vec2<f32>(t) + 0.5 - w.texel;
                            let dist2 = dot(offset, offset);
                            let d = t - base;
                            let k = max(abs(d.x), abs(d.y));
                            let order = (k << 20u) | ((d.y + 512) << 10u) | (d.x + 512);
                            if is_hit(w, receiver, texel) && (dist2 < near.dist2 || (dist2 == near.dist2 && order < near_order)) {
                                near = Nearest(dist2, bitcast<f32>(texel.x), t, true);
                                near_order = order;
                            }
                        }
                    }
                }
                // Inner rows of the ring: only its two end blocks.
                if edge_row || bx >= home.x + kb {
                    bx += 1;
                } else {
                    bx = home.x + kb;
                }
            }
        }
    }
    return near;
}

// The §3.3 search for one camera pixel; returns the penumbra coordinate t.
// Outer (lit) pixels look for the nearest texel closer to the light than P that belongs to
// another object; inner (hard-shadowed) pixels for the nearest lit texel of their own object
// (`nearest_in_rings`, `nearest_in_blocks`). Under a coloured light it also returns the
// occluder edge's line across the light (`edge_line`).
// `jittered` is a constant of the entry point (`search.wgsl`): lavapipe runs a branch's code
// even where no lane takes it, so the hash of the optional jitter, in the innermost loop, is
// compiled out when the job asks for none (it cost a third of the search).
fn search(pixel: vec2<u32>, jittered: bool) -> Found {
    var out = Found(1.0, vec2<f32>(0.0), 0.0);
    if !covered(pixel) {
        return out;
    }
    let w = warp(pixel);
    if !w.inside {
        return out;
    }
    let receiver = textureLoad(gbuf_id, pixel, 0).r;
    let r_max = search_radius(w.depth);
    atomicAdd(&counters.searches, 1u);
    atomicAdd(&counters.radius_sum_16, u32(r_max * 16.0));
    let res = i32(frame.sizes.z);
    let base = vec2<i32>(floor(w.texel));
    let rings = i32(ceil(r_max)) + 1;
    let lo = max(base - rings, vec2<i32>(0));
    let hi = min(base + rings, vec2<i32>(res - 1));
    if any(lo > hi) || !may_hit(w, receiver, lo, hi) {
        out.t = select(1.0, 0.0, w.hard);
        return out;
    }
    var near: Nearest;
    if jittered {
        near = nearest_in_rings(w, receiver, base, rings, r_max);
    } else {
        near = nearest_in_blocks(w, receiver, base, lo, hi, r_max);
    }
    let best2 = near.dist2;
    let best_depth = near.depth;
    let best_texel = near.texel;
    let found = near.found;
    if !found {
        out.t = select(1.0, 0.0, w.hard);
        return out;
    }
    let p = textureLoad(gbuf_position, pixel, 0).xyz;
    var dz: f32;
    if !w.hard {
        dz = w.depth - best_depth;
    } else if params.inner_depth == 0u {
        // Δz of the occluder over P: the distance that sets the penumbra's width, the same
        // quantity the outer search uses, so both halves meet with matching slopes.
        dz = w.depth - w.blocker;
    } else {
        dz = best_depth - w.depth; // the paper's pseudo-code, §3.3
    }
    let best = sqrt(best2);
    let f = clamp(best / max(hit_radius(w.depth, max(dz, 0.0)), 1e-6), 0.0, 1.0);
    // The paper's §3.3 pseudo-code returns 1 − 0.5·f outside and 0.5·f inside, which would
    // make the hard edge brightest; the text (§3.2: f rises from 0 at the blocker to 1) fixes
    // the intent: outside meet + (1 − meet)·f, inside meet·(1 − f).
    if w.hard {
        out.t = params.meet * (1.0 - f);
    } else {
        out.t = params.meet + (1.0 - params.meet) * f;
    }
    if params.colored == 1u {
        let line = edge_line(p, w, best_texel, f);
        out.normal = line.xy;
        out.edge = line.z;
    }
    return out;
}
