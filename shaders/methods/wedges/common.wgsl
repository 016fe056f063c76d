// Method `wedges` (Assarsson & Akenine-Möller 2003): what every pass shares — the parameters,
// the primitives (shadow-volume polygons and penumbra wedges), the work list of (primitive,
// tile) pairs that survived culling, and the light-intensity (LI) buffer. See
// `src/methods/wedges.rs`.

#import common/frame_inputs.wgsl

struct WedgeParams {
    tile: u32,          // tile side, pixels
    zfail: u32,         // 1: count volume crossings beyond the surface point (§5), 0: in front (z-pass)
    full: i32,          // full light in the LI buffer's fixed point (the paper's 255)
    polygon_count: u32, // shadow-volume polygons; wedges follow them in the primitive index space
    object_ids: u32,    // 1: no shadow from a receiver's own object where it faces away from the light centre
    channels: u32,      // LI values per pixel: 1 for a uniform light (gray), 3 for a coloured one (rgb)
    color_angles: u32,  // directions per wedge over which a coloured light's emission is integrated
    sector_angles: u32, // angular steps per turn of the sector table (which holds two turns)
    sector_stations: u32, // entries per row
    // The octagon holding the light's emitting texels (`light::tables::emitting_octagon`):
    // its extents along x, y, x + y and x − y in light coordinates, lows and highs.
    emitting_lo: vec4<f32>,
    emitting_hi: vec4<f32>,
}

// A planar convex polygon of the shadow volume from the light centre (a side quad or, for
// z-fail, a cap triangle with its last vertex repeated), counter-clockwise around its outward
// normal; w of `v0` is the silhouette multiplicity, w of `v1` the caster's object id.
struct VolumePolygon {
    v0: vec4<f32>,
    v1: vec4<f32>,
    v2: vec4<f32>,
    v3: vec4<f32>,
}

// A penumbra wedge: its silhouette edge, and its two planes through the edge tangent to the
// light (the wedge on their positive side).
struct Wedge {
    edge: WedgeEdge,
    front: vec4<f32>,
    back: vec4<f32>,
}

// A wedge's silhouette edge a → b (oriented as the boundary of the light-facing triangles), w
// of `a` the multiplicity, w of `b` the edge's object id: all that a share at a point inside
// the wedge reads (`wedge_share`), loaded alone where the planes were tested before.
struct WedgeEdge {
    a: vec4<f32>,
    b: vec4<f32>,
}

// One unit of rasterisation work: a primitive over a tile. `primitive` < polygon_count is a
// volume polygon; above it, wedge primitive − polygon_count. In the single-pass variant one
// item may carry both halves of an edge: `both` is then the wedge index + 1.
struct WorkItem {
    primitive: u32,
    tile: u32,
    both: u32,
    origin: u32, // the tile's first pixel: x in the low 16 bits, y in the high
}

@group(1) @binding(0) var<uniform> params_uniform: WedgeParams;
// Read through a private copy, as `frame` is (`common/frame_inputs.wgsl`).
var<private> params: WedgeParams;
@group(1) @binding(1) var<storage, read> polygons: array<VolumePolygon>;
@group(1) @binding(2) var<storage, read> wedges: array<Wedge>;
@group(1) @binding(3) var<storage, read> work: array<WorkItem>;
@group(1) @binding(4) var<storage, read_write> li: array<atomic<i32>>; // `channels` per pixel
// Per tile (`tiles.wgsl`): the world-space box of its receivers, and in w their view depth
// range (lo.w zmin, hi.w zmax), lo > hi for a tile of background only; and the slab they
// span along the normal at the tile's centre.
@group(1) @binding(5) var<storage, read_write> tile_ranges: array<TileRange>;

struct TileRange {
    lo: vec4<f32>,
    hi: vec4<f32>,
    axis: vec4<f32>, // xyz: the normal at the tile's centre pixel (0 where it is not covered); w: the least of axis · point
    most: vec4<f32>, // x: the greatest of axis · point; y: the object every covered pixel ignores, or NO_OBJECT
}
// 0 depth reads, 1 LI writes, 2 (wedge, pixel) pairs inside their wedge (three-pass only).
@group(1) @binding(6) var<storage, read_write> counters: array<atomic<u32>, 4>;
@group(1) @binding(7) var<storage, read_write> visibility_out: array<vec4<f32>>;
// The light's sector table (`light::tables::sector_table`): the emission (w: area) of the
// sectors from direction 0 to each angle, beyond each station.
@group(1) @binding(9) var<storage, read> sectors: array<vec4<f32>>;
// The unshadowed irradiance per channel: what a coloured wedge's blocked irradiance is a
// fraction of.
@group(1) @binding(10) var<storage, read> e0_in: array<vec4<f32>>;
// Per pixel, two vec4s written by `tiles.wgsl`: the surface point with, in w, the object whose
// volume and wedges it ignores (NO_OBJECT: none; NOT_COVERED: background), then its normal.
@group(1) @binding(8) var<storage, read_write> receivers: array<vec4<f32>>;
// The penumbra pass's (work item, pixel of its tile) pairs whose point lies inside the wedge,
// listed by `mark_inside` and shaded by `shade_listed` (rasterize_penumbra.wgsl says why).
@group(1) @binding(11) var<storage, read_write> inside: PairList;
@group(1) @binding(12) var<storage, read_write> inside_groups: array<u32, 3>; // indirect dispatch

struct PairList {
    count: atomic<u32>,
    pairs: array<vec2<u32>>, // x: work item, y: pixel of its tile
}

const NO_OBJECT: f32 = -1.0;
const NOT_COVERED: f32 = -2.0;
// cos of the angle to the light centre below which a receiver ignores its own object: one
// whose surface (the G-buffer's geometric normal) faces away from the centre, or within ~6°
// of edge-on to it. Where it faces the centre at all its own volume starts at its own face
// (its cap), so 0 would do; the margin keeps a landscape's grazing slopes, where E0 is under
// a tenth of its face-on value, from taking the whole landscape's wedges, for no loss of
// accuracy on the real-model suite (docs/methods.md weighs the margins).
const SELF_SHADOW_COS: f32 = 0.1;

fn tile_grid() -> vec2<u32> {
    return (frame.sizes.xy + params.tile - 1u) / params.tile;
}
