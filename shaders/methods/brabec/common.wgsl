// Method `brabec` (Brabec & Seidel 2002): the state, parameters and bindings every pass of
// the method shares — the warp of a pixel into the light's depth map, the summary blocks
// that bound a search, the search radii, and the marking and interpolation of §4.3. The
// search itself is in `search.wgsl`, its colour in `colour.wgsl`. See `src/methods/brabec.rs`.

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
