// Methods `jfa-l` / `jfa-e` (Rong & Tan 2006): the flooded record, the per-round parameters,
// and the intensity of a receiver for an occluder point through the coloured edge table (§3).
// See `src/methods/jfa.rs`.

#import common/frame_inputs.wgsl
#import common/shadow.wgsl
#import common/pixel_list.wgsl
#import methods/jfa/neighbours.wgsl
#import common/edge_table.wgsl

struct JfaParams {
    step: i32,                // this round's step length: 2^(k−1) … 1 (jump) or 1 (standard)
    silhouette_relative: f32, // jfa-l: a neighbour deeper by more than depth × this marks a silhouette
    bias_texels: f32,
    slope_bias_texels: f32,
    boundary_relative: f32,   // jfa-e: a lit neighbour within view depth × this makes a boundary pixel
    same_object: u32,         // jfa-e §5.2 remedy 1: flood only to pixels of the boundary's object
    midpoint: u32,            // jfa-e §5.2 remedy 2: the midpoint must be in a penumbra of the same occluder
    light_space: u32,         // 1 for jfa-l (the grid is the shadow map), 0 for jfa-e (the screen)
    edge_model: u32,          // 1: the visible part is bounded by the silhouette's own direction at the occluder; 0: the paper's line orthogonal to c→q
    inner: u32,               // jfa-l: 1 floods silhouettes into the occluders' footprints for the inner penumbra (past the paper)
    map_pitch: u32,           // texels from one row of `map_depth` to the next
}

// What flooding carries (§4.1, §5.1), packed small because every round moves the whole grid
// of them: one vec4 per cell for jfa-l, two for jfa-e. jfa-l's holds an occluder point (xyz)
// and, in w, the key flooding minimises plus 1, so that an all-zero record — a cleared
// buffer — is empty. jfa-e's first holds the occluder point and, in w, the object id of the
// boundary pixel it came from plus 1 (0: empty), so that weighing a neighbour's record reads
// one vec4 — on lavapipe each is a gather, lane by lane; its second holds xy the boundary
// pixel, z the key, w the angle of the silhouette's normal at the occluder point in light
// coordinates (`NO_NORMAL` where there is none). The rgb intensity is not stored: the final pass recomputes it from the
// occluder (§4.1 "Generating Final Image" does so for jfa-l; jfa-e gets the same value).
@group(1) @binding(0) var<uniform> params_uniform: JfaParams;
// Read through a private copy, as `frame` is (`common/frame_inputs.wgsl`).
var<private> params: JfaParams;
// The light's edge table (`light::tables::edge_table`, read through common/edge_table.wgsl).
@group(1) @binding(1) var<storage, read> edge_table: array<vec4<f32>>;
// The rounds' keys over the light (`light::tables::key_table`): per cell of a KEY_CELLS²
// grid over the rectangle, row by row from the (−r, −u) corner, the keys at its four corners.
@group(1) @binding(15) var<storage, read> key_table: array<vec4<f32>>;
// Mirrors `light::tables::KEY_CELLS`.
const KEY_CELLS: u32 = 128u;
@group(1) @binding(2) var<storage, read> src: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> dst: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read_write> visibility_out: array<vec4<f32>>;
@group(1) @binding(5) var<storage, read_write> counters: array<atomic<u32>, 4>;
// jfa-e: per eye pixel, bit 0 covered, bit 1 in hard shadow — computed once by the boundary
// pass so that flooding rounds read a flag instead of redoing the shadow test per neighbour.
@group(1) @binding(6) var<storage, read_write> flags: array<u32>;
// Per TILE×TILE tile of the flooded grid, 1 once a cell of it holds a record: lets a round
// skip the workgroups no record can reach (`reach_holds_record` in neighbours.wgsl).
@group(1) @binding(7) var<storage, read_write> tiles: array<atomic<u32>>;

const NO_NORMAL: f32 = 100.0;

const COVERED: u32 = 1u;
const HARD: u32 = 2u;

// A seed's key: larger than any intensity, so a seed never counts as penumbra itself.
const SEED_KEY: f32 = 2.0;
// The key of an empty record: worse than any other.
const EMPTY_KEY: f32 = 3.0;

fn packed(occluder: vec3<f32>, key: f32) -> vec4<f32> {
    return vec4<f32>(occluder, key + 1.0);
}

fn is_empty(record: vec4<f32>) -> bool {
    return record.w == 0.0;
}

fn key_of(record: vec4<f32>) -> f32 {
    return select(record.w - 1.0, EMPTY_KEY, is_empty(record));
}

// A record holding a penumbra occluder, not just a seed.
fn in_penumbra(record: vec4<f32>) -> bool {
    return !is_empty(record) && key_of(record) <= 1.0;
}

// jfa-e's record (two vec4s, above): the first from an occluder point and the boundary
// pixel's object id; whether it is empty; its key; whether it holds a penumbra occluder.
fn eye_packed(occluder: vec3<f32>, object: f32) -> vec4<f32> {
    return vec4<f32>(occluder, object + 1.0);
}

fn eye_object(record: vec4<f32>) -> f32 {
    return record.w - 1.0;
}

fn eye_key(record: vec4<f32>, origin: vec4<f32>) -> f32 {
    return select(origin.z, EMPTY_KEY, is_empty(record));
}

fn eye_in_penumbra(record: vec4<f32>, origin: vec4<f32>) -> bool {
    return !is_empty(record) && origin.z <= 1.0;
}

// The flooded grid: the shadow map (jfa-l) or the screen (jfa-e).
fn grid_size() -> vec2<i32> {
    return select(vec2<i32>(frame.sizes.xy), vec2<i32>(i32(frame.sizes.z)), params.light_space == 1u);
}

fn tile_count() -> vec2<i32> {
    return (grid_size() + TILE - 1) / TILE;
}

fn tile_holds_record(tile: vec2<i32>) -> bool {
    return atomicLoad(&tiles[tile.y * tile_count().x + tile.x]) != 0u;
}

// Listed rounds: before each round `list_tiles` lists the tiles a record may reach in it
// (`reach_holds_record`), the round runs one workgroup per listed tile (an indirect dispatch
// sized by `tiles_size`), and `tiles_reset` empties the list for the next round. A tile left
// out would copy empty records over the empty records both buffers hold; on lavapipe a
// workgroup that returns at once still pays for most of its code (a CPU rasteriser runs both
// sides of a branch), so such tiles are not launched at all. Entries are tile coordinates,
// x in the low 16 bits and y in the high: a row-major index would cost every SIMD group of
// a round two divisions by the grid's width, lane by lane on lavapipe.
@group(1) @binding(12) var<storage, read_write> tile_list: PixelList;
@group(1) @binding(13) var<storage, read_write> tile_groups: array<u32, 3>;
// The shadow map's depths, row after row, `params.map_pitch` apart (`MethodContext::
// shadow_depth_copy`): read here rather than from the texture, where on lavapipe a texel fetch
// costs several buffer loads (the seed pass reads nine per texel of the map).
@group(1) @binding(14) var<storage, read> map_depth: array<f32>;

// The shadow map's depth at texel t (inside the map).
fn map_depth_at(t: vec2<i32>) -> f32 {
    return map_depth[u32(t.y) * params.map_pitch + u32(t.x)];
}

// One invocation per tile: lists it where a record may reach it this round; counts the tiles
// flooded.
@compute @workgroup_size(8, 8)
fn list_tiles(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let tile = vec2<i32>(id.xy);
    if any(tile >= tile_count()) {
        return;
    }
    if reach_holds_record(tile, params.step, tile_count()) {
        tile_list.pixels[atomicAdd(&tile_list.count, 1u)] = u32(tile.x) | u32(tile.y) << 16u;
        atomicAdd(&counters[2], 1u);
    }
}

// The round's grid: one workgroup per listed tile.
@compute @workgroup_size(1)
fn tiles_size() {
    frame = frame_uniform;
    params = params_uniform;
    let n = atomicLoad(&tile_list.count);
    tile_groups = array<u32, 3>(min(n, LIST_MAX_GROUPS), (n + LIST_MAX_GROUPS - 1u) / LIST_MAX_GROUPS, 1u);
}

@compute @workgroup_size(1)
fn tiles_reset() {
    frame = frame_uniform;
    params = params_uniform;
    atomicStore(&tile_list.count, 0u);
}

// The grid cell a lane of a listed round works on, or (−1, −1) past the list's end.
fn listed_cell(group: vec3<u32>, local: vec3<u32>) -> vec2<i32> {
    let i = group.y * LIST_MAX_GROUPS + group.x;
    if i >= atomicLoad(&tile_list.count) {
        return vec2<i32>(-1);
    }
    let t = tile_list.pixels[i];
    return vec2<i32>(vec2<u32>(t & 0xffffu, t >> 16u)) * TILE + vec2<i32>(local.xy);
}

fn mark_tile(cell: vec2<i32>) {
    atomicStore(&tiles[cell.y / TILE * tile_count().x + cell.x / TILE], 1u);
}

// The hard-shadow test of an eye point p (normal n; the same test as method `hard`), in light
// space already, inside the map.
fn hard_shadowed_in_map(p: vec3<f32>, n: vec3<f32>, ls: LightSpace) -> bool {
    let blocker = map_depth_at(shadow_texel(ls.uv));
    return ls.depth - depth_bias(p, n, ls.depth, params.bias_texels, params.slope_bias_texels) > blocker;
}

// Where the ray from receiver p through occluder point o meets the light plane, in light
// coordinates (x along r, y along u, c at the origin); w = 1 when it meets the light
// rectangle, else 0 (§3: then p is not in o's penumbra).
fn light_hit(p: vec3<f32>, o: vec3<f32>) -> vec4<f32> {
    let q = light_plane_hit(p, o);
    let on_light = q.z == 1.0 && abs(q.x) <= 0.5 * frame.light_n.w && abs(q.y) <= 0.5 * frame.light_u.w;
    return vec4<f32>(q.xy, 0.0, select(0.0, 1.0, on_light));
}

// §3: shoot a ray from receiver p through occluder point o to the light plane. If it meets
// the light at q, the visible part is the light on the centre's side of the line through q
// orthogonal to c→q (for a receiver outside hard shadow), or the other side (inside); flooding
// keeps the occluder that leaves an outside receiver the least light and an inside one the
// most. Returns the key it minimises, with y = 1 where the ray meets the light (p is in a
// penumbra), else y = 0: the luminance of the centre's side, for both (inside, the visible
// side's luminance is 1 minus it: Rec. 709's weights sum to 1, and the key is 1 minus that).
// Read from the grid of keys over the light (`key_table`, which says why a grid): luminance
// is linear, so the table's luminance is the edge table's colour's, and one load holds the
// four corners of q's cell — the look-ups are most of a round's loads.
fn intensity_key(p: vec3<f32>, o: vec3<f32>) -> vec2<f32> {
    let hit = light_hit(p, o);
    if hit.w == 0.0 {
        return vec2<f32>(0.0);
    }
    let size = vec2<f32>(frame.light_n.w, frame.light_u.w);
    let g = clamp((hit.xy / size + 0.5) * f32(KEY_CELLS), vec2<f32>(0.0), vec2<f32>(f32(KEY_CELLS)));
    let cell = min(vec2<u32>(g), vec2<u32>(KEY_CELLS - 1u));
    let f = g - vec2<f32>(cell);
    let corners = key_table[cell.y * KEY_CELLS + cell.x];
    return vec2<f32>(mix(mix(corners.x, corners.y, f.x), mix(corners.z, corners.w, f.x), f.y), 1.0);
}

// The visibility the final passes give receiver p for occluder point o (p in o's penumbra,
// `inside` where p is in hard shadow): the paper's intensity (§3), coloured. The paper's line
// orthogonal to c→q is right only for the o whose q is the foot of the perpendicular from c,
// which flooding finds only approximately; across an edge parallel to a colour boundary of
// the light it tilts and paints a hue the light cannot cast there. With `edge_model` on, the
// hue comes instead from the line through q along the silhouette's own direction at o, the
// visible part being the light beyond it, away from the occluder — the same half-plane for
// the inner and the outer penumbra, and for every o along a straight edge, so the hue does
// not hang on which o flooding kept. The level stays the paper's for the light's white twin
// (`with_hue`): measured against the reference under white lights, the silhouette line's own
// level is worse, its noisier direction costing more than its better placement gains.
// `normal` is `silhouette_normal` at o, or (0, 0), where the paper's line gives the hue too.
fn final_intensity(p: vec3<f32>, o: vec3<f32>, inside: bool, normal: vec2<f32>) -> vec4<f32> {
    let hit = light_hit(p, o);
    if hit.w == 0.0 {
        return vec4<f32>(0.0);
    }
    let f = edge_fraction_at(hit.xy);
    let paper = select(f, vec4<f32>(1.0) - f, inside);
    if params.edge_model == 1u && dot(normal, normal) > 0.0 {
        return vec4<f32>(with_hue(paper.w, fraction_beyond(normal, dot(hit.xy, normal))), 1.0);
    }
    return vec4<f32>(paper.rgb, 1.0);
}
