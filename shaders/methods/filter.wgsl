// Methods `pcss` (Fernando 2005) and `chun-oh` (Chun & Oh 2016 §3): the shared front half —
// the blocker search over the cone from the pixel to the light's corners, the filter sized by
// the blockers' average depth, and a lattice of shadow tests over that filter, counted per
// cell of its 4×4 quadtree (for chun-oh) with a few popcounts per row. See `src/methods/pcss.rs`.
//
// The passes (`src/methods/filter.rs`), after the shadow map is copied into a buffer: per pixel, the
// uncovered ones and those outside the shadow frustum written at once, the others listed; then
// the search and the filter over the listed pixels alone (common/pixel_list.wgsl says why). The importing method defines
// `unblocked_visibility()` and `filtered_visibility(filter)`, which also counts the pixel
// (`tally_add`).

#import common/frame_inputs.wgsl
#import common/shadow.wgsl
#import common/pixel_list.wgsl

struct FilterParams {
    search_taps: u32,       // blocker-search taps per side
    lattice: u32,           // filter taps per side: 4 × taps_per_cell, at most 16
    max_search_texels: f32, // cap on the search region's half-width, texels
    max_filter_texels: f32, // cap on the filter's half-width, texels
    bias_texels: f32,
    slope_bias_texels: f32,
    nearest: f32,           // depth of the nearest possible occluder (scene bounds)
    mode: u32,              // 0 pcss, 1 chun-oh adaptive, 2 chun-oh fixed
    threshold: f32,         // chun-oh: visibility variance above which a region splits
    light_threshold: f32,   // chun-oh: relative colour variance of the light part that forces a split
    map_pitch: u32,         // texels from one row of `map_depth` to the next (rows padded to 256 bytes)
    _pad: u32,
}

@group(1) @binding(0) var<storage, read_write> visibility_out: array<vec4<f32>>;
@group(1) @binding(1) var<uniform> params_uniform: FilterParams;
// Read through a private copy, as `frame` is (`common/frame_inputs.wgsl`).
var<private> params: FilterParams;
// chun-oh: the light image integrated over the filter's quadtree (`light_regions` in
// `src/methods/chun_oh.rs`): 0–15 the 4×4 cells, 16–19 the 2×2, 20 the whole light; rgb the
// emission, w the relative colour variance. Indexed in filter order: the light frame's
// mirroring is already applied there.
@group(1) @binding(2) var<storage, read> light_regions: array<vec4<f32>, 21>;
// Per-pixel counts (`Counters` in pcss.rs): 0–2 pixels by subdivision level, 3 splits the light
// forced, 4 pixels that ran the filter, 5 covered pixels.
@group(1) @binding(3) var<storage, read_write> counters: array<atomic<u32>, 8>;
// The pixels the search cannot be skipped for, and the dispatch over them.
@group(1) @binding(4) var<storage, read_write> listed: PixelList;
@group(1) @binding(5) var<storage, read_write> listed_groups: array<u32, 3>;
// The shadow map's depths, row after row, `params.map_pitch` apart: a copy of the shadow
// map (`filter::run`), which the search and the filter read instead of the texture: on
// lavapipe a storage-buffer load is a plain gather and a texel fetch is not (format,
// robustness), and these two loops are nearly all loads.
@group(1) @binding(6) var<storage, read_write> map_depth: array<f32>;

const MODE_PCSS: u32 = 0u;

// The filter pass's counts, tallied per workgroup and added to `counters` once per workgroup
// (`filter_listed`): on lavapipe an atomic is a loop over the lanes, and both cores adding to
// the same few counters for every pixel passed their cache line back and forth.
var<workgroup> tally: array<atomic<u32>, 8>;

fn tally_add(counter: u32, n: u32) {
    atomicAdd(&tally[counter], n);
}

// A pixel's filter: how many of its lattice × lattice shadow tests are lit, and whether the
// blocker search found anything (if not, the filter did not run: all lit).
struct Filter {
    lit: u32,
    taps: u32,
    found_blocker: bool,
}

// chun-oh: lit tests per cell of the filter's 4×4 quadtree, cell (x, y) at y·4 + x (x along
// the shadow map's u, y along its v). Module scope, so functions read it without copying
// (`quadtree.wgsl` reads it).
var<private> cells: array<u32, 16>;

// The half-extent, in shadow-map uv, of the cone from a receiver at depth d to the light's
// rectangle, cut at depth z: a point at depth z on the segment from the receiver to light point
// y sits y·(d − z)/(d·z) from the receiver in tangent space (lateral / depth from the light
// centre), and uv spans 2·tan_half of tangent per unit. Chun & Oh §3 "a cone as a target pixel
// and 4 corner vertices on the area light"; the rectangle keeps the light's aspect.
fn cone_half_extent(d: f32, z: f32) -> vec2<f32> {
    let size = vec2<f32>(frame.light_n.w, frame.light_u.w);
    return 0.5 * size * max(d - z, 0.0) / (d * z) / (2.0 * frame.light_proj.x);
}

// The receiver's tangent plane as the shadow map's rays see it: the tests compare each tap
// with the depth at which the map's ray through the tap meets that plane, not with the pixel's
// own depth, which keeps a wide filter on a surface tilted towards the light from shadowing the
// surface itself. The ray through map point uv runs along w = n + t.x·r + t.y·u, tangent
// t = (0.5 − uv)·2·tan_half (uv grows along −r and −u), and meets the plane at depth
// dot(p − c, N) / dot(w, N). dot(w, N) is linear in t and |w|² = 1 + |t|² (the light frame is
// orthonormal), so the pixel's part is done once here, a row's part once per row (`TapRow`),
// and a tap costs a few multiply-adds and one division. On lavapipe, where the invariant parts
// had stayed inside the loops, that halved the cost of the search and the filter (docs/performance-log.md).
struct ReceiverPlane {
    facing_n: f32, // dot(n, N), dot(r, N), dot(u, N)
    facing_r: f32,
    facing_u: f32,
    offset: f32,   // dot(p − c, N)
    depth: f32,    // the pixel's own depth d
    bias: f32,     // depth_bias: subtracted from the plane's depth
}

// One row of a lattice of taps: its row of the map (or none), and the plane's facing and
// |w|² up to the column's terms.
struct TapRow {
    first: u32,    // the row's first element in `map_depth`
    inside: bool,  // whether the row lies on the map at all
    facing: f32,
    length2: f32,
}

// A square lattice of n × n taps over uv ± half, at the taps' centres.
struct Lattice {
    first: vec2<f32>, // uv of tap (0, 0)
    step: vec2<f32>,
}

fn lattice(centre: vec2<f32>, half: vec2<f32>, n: u32) -> Lattice {
    let step = 2.0 * half / f32(n);
    return Lattice(centre - half + 0.5 * step, step);
}

fn receiver_plane(p: vec3<f32>, normal: vec3<f32>, d: f32, bias: f32) -> ReceiverPlane {
    return ReceiverPlane(
        dot(frame.light_n.xyz, normal),
        dot(frame.light_r.xyz, normal),
        dot(frame.light_u.xyz, normal),
        dot(p - frame.light_center.xyz, normal),
        d,
        bias,
    );
}

// One map coordinate of a tap (u or v): its texel, whether it lies on the map, and the ray's
// tangent along it.
struct MapAxis {
    texel: u32,
    inside: bool,
    tangent: f32,
}

fn map_axis(x: f32) -> MapAxis {
    return MapAxis(u32(shadow_texel_axis(x)), x >= 0.0 && x < 1.0, (0.5 - x) * 2.0 * frame.light_proj.x);
}

fn tap_row(plane: ReceiverPlane, grid: Lattice, j: u32) -> TapRow {
    let v = map_axis(grid.first.y + f32(j) * grid.step.y);
    return TapRow(v.texel * params.map_pitch, v.inside, plane.facing_n + v.tangent * plane.facing_u, 1.0 + v.tangent * v.tangent);
}

// Tap i of a row: whether its texel is nearer the light than the receiver's plane there (less
// the bias): a blocker. `depth` is the texel's depth (1e30 off the map: nothing was rendered
// there, no blocker).
struct Tap {
    depth: f32,
    blocked: bool,
}

fn tap(plane: ReceiverPlane, grid: Lattice, row: TapRow, i: u32) -> Tap {
    let u = map_axis(grid.first.x + f32(i) * grid.step.x);
    let t = u.tangent;
    let depth = select(1e30, map_depth[row.first + u.texel], row.inside && u.inside);
    let facing = row.facing + t * plane.facing_r;
    let z = plane.offset / facing;
    // Grazing planes (|dot(w, N)| ≤ 0.05·|w|) give wild depths; the pixel's own depth is the
    // safe answer there.
    let d = plane.depth;
    let across = select(d, z, facing * facing > 0.0025 * (row.length2 + t * t) && z > 0.5 * d && z < 2.0 * d);
    return Tap(depth, depth < across - plane.bias);
}

// PCSS steps 1–3 (Fernando 2005; Chun & Oh §3 "filter size computation"): search the cone's
// cross-section at the nearest possible occluder depth for blockers, average their depth, and
// cut the cone there for the filter; then test a lattice of taps over the filter.
fn run_filter(pixel: vec2<u32>) -> Filter {
    var f: Filter;
    f.lit = 0u;
    f.taps = params.lattice * params.lattice;
    f.found_blocker = false;
    let p = textureLoad(gbuf_position, pixel, 0).xyz;
    let normal = textureLoad(gbuf_normal, pixel, 0).xyz;
    let ls = to_light_space(p);
    if !ls.inside {
        f.lit = f.taps;
        return f;
    }
    let d = ls.depth;
    let plane = receiver_plane(p, normal, d, depth_bias(p, normal, d, params.bias_texels, params.slope_bias_texels));
    let texel = 1.0 / f32(frame.sizes.z);

    // Blocker search over the initial filter: the cone cut at the nearest occluder depth.
    let n = params.search_taps;
    let search = lattice(ls.uv, clamp(cone_half_extent(d, min(params.nearest, d)), vec2<f32>(0.5 * texel), vec2<f32>(params.max_search_texels * texel)), n);
    var blockers = 0u;
    var depth_sum = 0.0;
    for (var j = 0u; j < n; j++) {
        let row = tap_row(plane, search, j);
        for (var i = 0u; i < n; i++) {
            let t = tap(plane, search, row, i);
            if t.blocked {
                blockers++;
                depth_sum += t.depth;
            }
        }
    }
    if blockers == 0u {
        f.lit = f.taps;
        return f;
    }
    f.found_blocker = true;

    // The optimised filter (Chun & Oh §3, after Annen et al. 2008): the cone cut at the
    // blockers' average depth — the penumbra those blockers cast.
    let z_avg = depth_sum / f32(blockers);
    let m = params.lattice;
    let kernel = lattice(ls.uv, clamp(cone_half_extent(d, z_avg), vec2<f32>(0.5 * texel), vec2<f32>(params.max_filter_texels * texel)), m);
    let cell_side = m / 4u;
    let cell_mask = (1u << cell_side) - 1u;
    // chun-oh's 4×4 cells, a row of cells per vector, held in registers until the last row:
    // `cells` indexed by the lattice's row lives in memory, where on lavapipe each update was
    // a gather and a scatter lane by lane.
    var cell_row0 = vec4<u32>(0u);
    var cell_row1 = vec4<u32>(0u);
    var cell_row2 = vec4<u32>(0u);
    var cell_row3 = vec4<u32>(0u);
    for (var j = 0u; j < m; j++) {
        // The row's tests as bits: lit = set.
        let taps = tap_row(plane, kernel, j);
        var row = 0u;
        for (var i = 0u; i < m; i++) {
            row |= select(1u << i, 0u, tap(plane, kernel, taps, i).blocked);
        }
        f.lit += countOneBits(row);
        if params.mode != MODE_PCSS {
            let lit = vec4<u32>(
                countOneBits(row & cell_mask),
                countOneBits(row & (cell_mask << cell_side)),
                countOneBits(row & (cell_mask << (2u * cell_side))),
                countOneBits(row & (cell_mask << (3u * cell_side))),
            );
            let y = j / cell_side;
            cell_row0 += select(vec4<u32>(0u), lit, y == 0u);
            cell_row1 += select(vec4<u32>(0u), lit, y == 1u);
            cell_row2 += select(vec4<u32>(0u), lit, y == 2u);
            cell_row3 += select(vec4<u32>(0u), lit, y == 3u);
        }
    }
    if params.mode != MODE_PCSS {
        #unroll x in 0..4 {
            cells[x] = cell_row0[x];
            cells[4u + x] = cell_row1[x];
            cells[8u + x] = cell_row2[x];
            cells[12u + x] = cell_row3[x];
        }
    }
    return f;
}

// Pixels per invocation of pass 1: a run of a row, listed with one atomic append for the run
// (on lavapipe an append per pixel is an atomic per lane, and nearly every covered pixel is
// listed here).
const ROW_PIXELS: u32 = 8u;

// Pass 1, every pixel: uncovered pixels and those outside the shadow frustum written, the
// others listed.
@compute @workgroup_size(8, 8)
fn classify(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let first = vec2<u32>(id.x * ROW_PIXELS, id.y);
    if any(first >= frame.sizes.xy) {
        return;
    }
    // Bit k: pixel first + (k, 0) is listed.
    var listing = 0u;
    for (var k = 0u; k < ROW_PIXELS; k++) {
        let pixel = first + vec2<u32>(k, 0u);
        if pixel.x >= frame.sizes.x {
            break;
        }
        if !covered(pixel) {
            visibility_out[pixel_index(pixel)] = vec4<f32>(1.0);
            continue;
        }
        let p = textureLoad(gbuf_position, pixel, 0).xyz;
        let ls = to_light_space(p);
        // Outside the shadow frustum the filter has nothing to test: lit.
        if !ls.inside {
            visibility_out[pixel_index(pixel)] = vec4<f32>(unblocked_visibility(), 1.0);
            atomicAdd(&counters[0], 1u);
            atomicAdd(&counters[5], 1u);
        } else {
            listing |= 1u << k;
        }
    }
    if listing == 0u {
        return;
    }
    var at = atomicAdd(&listed.count, countOneBits(listing));
    var rest = listing;
    while rest != 0u {
        listed.pixels[at] = pixel_index(first + vec2<u32>(next_in_run(&rest), 0u));
        at++;
    }
}

// Pass 2: the size of pass 3's dispatch.
@compute @workgroup_size(1)
fn listed_size() {
    frame = frame_uniform;
    params = params_uniform;
    listed_groups = list_dispatch(atomicLoad(&listed.count));
}

// Pass 3: the search and the filter, over the listed pixels.
@compute @workgroup_size(64)
fn filter_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let i = list_position(group, lane);
    if i < atomicLoad(&listed.count) {
        let pixel = listed_pixel(listed.pixels[i]);
        let v = filtered_visibility(run_filter(pixel));
        tally_add(5u, 1u);
        visibility_out[pixel_index(pixel)] = vec4<f32>(v, 1.0);
    }
    workgroupBarrier();
    if lane < 8u {
        let n = atomicLoad(&tally[lane]);
        if n > 0u {
            atomicAdd(&counters[lane], n);
        }
    }
}
