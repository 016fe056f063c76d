// Method `brabec` (Brabec & Seidel 2002): shared state, parameters and the neighbourhood
// search of the light depth map (§3.2 outer penumbra, §3.3 inner penumbra, §4.3 sub-pixel
// distances) used by every pass of the method. See `src/methods/brabec.rs`.

#import common/frame_inputs.wgsl
#import common/shadow.wgsl
#import common/edge_table.wgsl
#import common/pixel_list.wgsl

struct BrabecParams {
    // Search radius in texels: r_max = r_scale·z + r_bias (paper), or derived from the light
    // size when `derived.x` is 1: r_max = k·(z − d_near)/(2·z·d_near).
    r_scale: f32,
    r_bias: f32,
    // Hit rescale: r_hit = r_shrink·Δz (paper), or k·Δz/(2·z·d) when `derived.y` is 1.
    r_shrink: f32,
    // k = light width · resolution / (2 tan half-angle): a light-width in texels at unit depth.
    k: f32,
    d_near: f32,
    max_radius: f32,
    meet: f32,          // attenuation where inner and outer penumbra meet (paper: 0.5)
    bias_texels: f32,
    slope_bias_texels: f32,
    jitter: f32,        // texels of blocker-position jitter (§4.3), 0 = off
    falloff: u32,       // 0 linear, 1 sinusoid (paper §6)
    inner_depth: u32,   // 0: Δz of the blocker over P (default), 1: the paper's depth(lit) − z
    derived: vec2<u32>, // x: search radius derived, y: hit radius derived
    lattice_stride: u32, // 4 with adaptive sampling (4×4 blocks), 1 without
    use_ids: u32,        // 1: the object-id test of §3.2 (off only to show what it prevents)
    colored: u32,        // 1: the light image is not uniform: weigh its colours with the edge table
}

struct PixelState {
    t: f32,   // penumbra coordinate: 0 umbra … meet at the hard edge … 1 lit; < 0 not yet known
    key: u32, // object id (blocker's where hard-shadowed, receiver's where lit) | hard << 31
    // The occluder edge's line across the light (light coordinates, x along r, y along u):
    // its normal pointing away from the occluder, (0, 0) where the search found nothing, and
    // its signed distance from the centre along it (`edge_line`).
    normal: vec2<f32>,
    edge: f32,
}

// What the search found for one pixel.
struct Found {
    t: f32,
    normal: vec2<f32>,
    edge: f32,
}

struct Counters {
    searches: atomic<u32>,
    interpolated: atomic<u32>,
    radius_sum_16: atomic<u32>, // Σ search radius × 16 (fixed point)
    shaded: atomic<u32>,
    unresolved: atomic<u32>, // pixels left without t: a bug if ever not 0
}

@group(1) @binding(0) var<uniform> params_uniform: BrabecParams;
// Read through a private copy, as `frame` is (`common/frame_inputs.wgsl`).
var<private> params: BrabecParams;
@group(1) @binding(1) var<storage, read_write> state: array<PixelState>;
@group(1) @binding(2) var<storage, read_write> counters: Counters;
@group(1) @binding(3) var<storage, read_write> visibility_out: array<vec4<f32>>;
// The light's edge table (`light::tables::edge_table`, read through common/edge_table.wgsl).
@group(1) @binding(4) var<storage, read> edge_table: array<vec4<f32>>;
// Per block of the light depth map, what a search needs to know to skip it (summary.wgsl).
@group(1) @binding(5) var<storage, read_write> summary: array<BlockSummary>;

// The pixels to search, appended by the lattice and the marking passes; one compacted pass
// searches them all (common/pixel_list.wgsl says why).
@group(1) @binding(6) var<storage, read_write> to_search: PixelList;
@group(1) @binding(7) var<storage, read_write> search_groups: array<u32, 3>; // indirect dispatch

// The light depth map's depth (bits) and object id per texel, copied by the summary pass: the
// search reads them here, where a storage-buffer load is a plain gather and a texel fetch on
// lavapipe is not (format, robustness), and the search is nearly all loads.
@group(1) @binding(8) var<storage, read_write> map_texels: array<vec2<u32>>;

struct BlockSummary {
    near: f32,   // the block's smallest depth
    far: f32,    // its largest
    object: u32, // the id every texel of it holds, or MIXED
    pad: u32,
}

// Texels per side of a summary block; mirrors `methods::brabec::SUMMARY_BLOCK`.
const SUMMARY_BLOCK: i32 = 8;
const MIXED: u32 = 0xffffffffu;

fn summary_blocks() -> i32 {
    return (i32(frame.sizes.z) + SUMMARY_BLOCK - 1) / SUMMARY_BLOCK;
}

// Whether any texel in [lo, hi] (inclusive, inside the map) can be a hit of the search from
// w (receiver id `receiver`): the hit tests of `search` applied to each block's bounds. A
// search proved empty here returns what the ring search would without a hit. This is not in
// the paper: its searches all run to r_max, and on a CPU rasteriser the searches of lit
// pixels far from any occluder were most of the method's cost.
fn may_hit(w: Warped, receiver: u32, lo: vec2<i32>, hi: vec2<i32>) -> bool {
    let blocks = summary_blocks();
    let b0 = lo / SUMMARY_BLOCK;
    let b1 = hi / SUMMARY_BLOCK;
    for (var by = b0.y; by <= b1.y; by++) {
        for (var bx = b0.x; bx <= b1.x; bx++) {
            if block_may_hit(w, receiver, summary[by * blocks + bx]) {
                return true;
            }
        }
    }
    return false;
}

// Whether a block with summary `s` can hold a hit of the search from w (`is_hit` applied to
// the block's bounds).
fn block_may_hit(w: Warped, receiver: u32, s: BlockSummary) -> bool {
    let limit = w.depth - w.bias;
    if w.hard {
        let same_object = s.object == receiver || s.object == MIXED || params.use_ids == 0u;
        return s.far >= limit && same_object;
    }
    let other_object = s.object != receiver || params.use_ids == 0u;
    return s.near < limit && other_object;
}

const UNKNOWN: f32 = -1.0;
// t of a pixel listed for the search pass.
const MARKED: f32 = -2.0;
// A shadow-map texel deeper than an occluder point by more than this fraction of its depth
// lies beyond the occluder's silhouette (`edge_line`).
const SILHOUETTE_RELATIVE: f32 = 0.01;
const BACKGROUND_KEY: u32 = 0x7ffffffeu;

fn state_index(pixel: vec2<u32>) -> u32 {
    return pixel.y * frame.sizes.x + pixel.x;
}

// Where P lands in the light depth map and whether it is in hard shadow there.
struct Warped {
    texel: vec2<f32>, // unrounded position in texels (§4.3: distances at sub-pixel accuracy)
    depth: f32,       // P'z: linear depth from the light
    bias: f32,
    blocker: f32,     // the depth map at P'
    inside: bool,
    hard: bool,
}

fn warp(pixel: vec2<u32>) -> Warped {
    var w: Warped;
    let p = textureLoad(gbuf_position, pixel, 0).xyz;
    let n = textureLoad(gbuf_normal, pixel, 0).xyz;
    let ls = to_light_space(p);
    w.inside = ls.inside;
    w.texel = ls.uv * f32(frame.sizes.z);
    w.depth = ls.depth;
    w.bias = depth_bias(p, n, ls.depth, params.bias_texels, params.slope_bias_texels);
    w.blocker = textureLoad(shadow_depth, shadow_texel(ls.uv), 0).r;
    w.hard = ls.inside && w.blocker < ls.depth - w.bias;
    return w;
}

// Search radius r_max for a receiver at light depth z (§3.2), capped by `max_radius`.
fn search_radius(z: f32) -> f32 {
    var r: f32;
    if params.derived.x == 1u {
        r = params.k * max(z - params.d_near, 0.0) / (2.0 * z * params.d_near);
    } else {
        r = params.r_scale * abs(z) + params.r_bias;
    }
    return clamp(r, 0.0, params.max_radius);
}

// The rescaled radius once a hit gives the occluder–receiver distance Δz (§3.2).
fn hit_radius(z: f32, dz: f32) -> f32 {
    if params.derived.y == 1u {
        let d = max(z - dz, 1e-4);
        return params.k * dz / (2.0 * z * d);
    }
    return params.r_shrink * dz;
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

// The occluder's edge as a line across the light, seen from p: xy its unit normal pointing
// away from the occluder, z its signed distance from the centre along it. The occluder point
// next to the silhouette is the blocker found (outer penumbra), or the occluder texel next to
// the lit one found, one step back towards p's own (inner). The ray from p through it meets
// the light plane at q, on the edge's line; the line's direction is the silhouette's at that
// point (`silhouette_normal`), or else orthogonal to the direction the search found its texel
// in (`light_direction`). Where the ray fails (the point is not between p and the light), the
// penumbra coordinate f places the line: at f of the light's extent that way.
fn edge_line(p: vec3<f32>, w: Warped, found: vec2<i32>, f: f32) -> vec3<f32> {
    let toward = light_direction(p, w.depth, found);
    if dot(toward, toward) <= 0.0 {
        return vec3<f32>(0.0);
    }
    let e = normalize(toward);
    var texel = found;
    if w.hard {
        let back = w.texel - (vec2<f32>(found) + 0.5);
        let step = select(vec2<i32>(sign(back)), vec2<i32>(0), abs(back) < vec2<f32>(0.5 * max(abs(back.x), abs(back.y))));
        texel = clamp(found + step, vec2<i32>(0), vec2<i32>(i32(frame.sizes.z) - 1));
    }
    let occluder = shadow_point(texel).xyz;
    // The blocker lies towards e (outer), the lit surface towards e (inner): the occluder
    // faces away along −e, respectively +e.
    var normal = select(-e, e, w.hard);
    let silhouette = silhouette_normal(occluder, 2, SILHOUETTE_RELATIVE);
    if dot(silhouette, silhouette) > 0.0 {
        normal = silhouette;
    }
    let q = light_plane_hit(p, occluder);
    if q.z == 0.0 {
        return vec3<f32>(normal, select(-1.0, 1.0, w.hard) * f * light_reach(normal));
    }
    return vec3<f32>(normal, dot(q.xy, normal));
}

// The direction on the light plane, seen from receiver p (light depth `depth`), of what the
// shadow map holds at `texel`: its point's offset from the ray c→p at its own depth. A point
// beside that ray projects from p onto the light on the same side of c, so this is the side
// of the light the blocker hides (outer penumbra) or the lit surface sees (inner).
fn light_direction(p: vec3<f32>, depth: f32, texel: vec2<i32>) -> vec2<f32> {
    let c = frame.light_center.xyz;
    let point = shadow_point(texel).xyz;
    let on_ray = c + (p - c) * (dot(point - c, frame.light_n.xyz) / max(depth, 1e-6));
    let offset = point - on_ray;
    return vec2<f32>(dot(offset, frame.light_r.xyz), dot(offset, frame.light_u.xyz));
}

// Per-channel visibility of a pixel from its level v, penumbra coordinate t and the
// occluder edge's line its search found (`edge_line`). Brabec & Seidel's search finds how far
// the hard edge is, not which part of the light is hidden; the line says which (contract §1:
// V per channel): the edge table gives each channel's share of the light beyond it, away
// from the occluder. Only the hue is taken from it (`with_hue`): a uniform light keeps the
// paper's fall-off exactly.
fn colored_visibility(v: f32, t: f32, normal: vec2<f32>, edge: f32) -> vec3<f32> {
    if params.colored == 0u || dot(normal, normal) <= 0.0 || t <= 0.0 || t >= 1.0 {
        return vec3<f32>(v);
    }
    return with_hue(v, fraction_beyond(normalize(normal), edge));
}

// The key of the §4.3 interpolation test: ids and hard-shadow results must agree.
fn pixel_key(pixel: vec2<u32>) -> u32 {
    if !covered(pixel) {
        return BACKGROUND_KEY;
    }
    let w = warp(pixel);
    var id = textureLoad(gbuf_id, pixel, 0).r;
    if w.hard {
        id = textureLoad(shadow_id, shadow_texel(w.texel / f32(frame.sizes.z)), 0).r;
    }
    return (id & 0x7fffffffu) | select(0u, 0x80000000u, w.hard);
}

// Searches pixel `p` and keeps what it found.
fn search_into(p: vec2<u32>, jittered: bool) {
    let found = search(p, jittered);
    let i = state_index(p);
    state[i].t = found.t;
    state[i].normal = found.normal;
    state[i].edge = found.edge;
}

// Lists pixel `p` for the search pass unless it has its t or is listed already. Each marking
// pass lists a pixel from one invocation only (its lattice point, or a middle pixel of its own
// 5-pixel group), so the check needs no atomics.
fn mark(p: vec2<u32>) {
    let i = state_index(p);
    if state[i].t == UNKNOWN {
        state[i].t = MARKED;
        to_search.pixels[atomicAdd(&to_search.count, 1u)] = pixel_index(p);
    }
}

// Pixel `p`'s t, which the interpolation reads only where the search pass or an earlier
// interpolation gave it one. Not a search on demand: on lavapipe the search's code inlined
// into a pass costs that pass dearly even where no lane runs it.
fn known(p: vec2<u32>) -> f32 {
    return state[state_index(p)].t;
}

// §4.3 adaptive sampling along one line from pixel `a` to pixel `b` (at most 4 apart, both
// known): interpolate the inner pixels where ids and hard results agree, otherwise search the
// middle pixel and repeat on both halves. Which pixels are searched depends on the keys
// alone, so it runs twice: `marking` lists them (for the compacted search pass), then the
// interpolation runs with every t it reads known. In one pass, one lane of an 8-wide SIMD
// group searching kept the other seven waiting; the results are the same.
fn refine(a: vec2<u32>, step: vec2<u32>, span: u32, marking: bool) {
    // The stack of spans still to refine, as vectors: an array indexed by the lane's own `top`
    // lives in memory on lavapipe (a gather or a scatter lane by lane per access), a vector's
    // lane-varying component is a few selects in registers.
    var stack_lo = vec4<u32>(0u);
    var stack_hi = vec4<u32>(0u);
    var top = 1u;
    stack_lo[0] = 0u;
    stack_hi[0] = span;
    loop {
        if top == 0u {
            break;
        }
        top -= 1u;
        let lo = stack_lo[top];
        let hi = stack_hi[top];
        if hi - lo < 2u {
            continue;
        }
        let key = state[state_index(a + step * lo)].key;
        var same = true;
        for (var k = lo + 1u; k <= hi; k++) {
            same = same && state[state_index(a + step * k)].key == key;
        }
        if same && marking {
            // Nothing to list: the ends are lattice pixels (columns), or pixels of lattice
            // columns (rows), whose t the columns' interpolation has before the rows' runs.
        } else if same {
            let t0 = known(a + step * lo);
            let t1 = known(a + step * hi);
            let d0 = state[state_index(a + step * lo)].normal;
            let d1 = state[state_index(a + step * hi)].normal;
            let e0 = state[state_index(a + step * lo)].edge;
            let e1 = state[state_index(a + step * hi)].edge;
            for (var k = lo + 1u; k < hi; k++) {
                let i = state_index(a + step * k);
                if state[i].t < 0.0 {
                    let f = f32(k - lo) / f32(hi - lo);
                    state[i].t = mix(t0, t1, f);
                    state[i].normal = mix(d0, d1, f);
                    state[i].edge = mix(e0, e1, f);
                    if key != BACKGROUND_KEY {
                        atomicAdd(&counters.interpolated, 1u);
                    }
                }
            }
        } else {
            let mid = (lo + hi) / 2u;
            if marking {
                mark(a + step * mid); // searched before the interpolation reads it
            }
            stack_lo[top] = lo;
            stack_hi[top] = mid;
            stack_lo[top + 1u] = mid;
            stack_hi[top + 1u] = hi;
            top += 2u;
        }
    }
}
