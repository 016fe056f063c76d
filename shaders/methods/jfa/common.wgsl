// Methods `jfa-l` / `jfa-e` (Rong & Tan 2006): the flooded record, the per-round parameters,
// and the intensity of a receiver for an occluder point through the look-up texture (§3).
// See `src/methods/jfa.rs`.

#import common/frame_inputs.wgsl
#import common/shadow.wgsl
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
}

// What flooding carries (§4.1, §5.1), packed small because every round moves the whole grid
// of them: one vec4 per cell for jfa-l, two for jfa-e. The first holds an occluder point
// (xyz) and, in w, the key flooding minimises plus 1, so that an all-zero record — a cleared
// buffer — is empty. jfa-e's second holds where the record came from: xy the boundary pixel,
// z its object id, w the angle of the silhouette's normal at the occluder point in light
// coordinates (`NO_NORMAL` where there is none). The rgb intensity is not stored: the final pass recomputes it from the
// occluder (§4.1 "Generating Final Image" does so for jfa-l; jfa-e gets the same value).
@group(1) @binding(0) var<uniform> params: JfaParams;
// The light's edge table (`light::tables::edge_table`, read through common/edge_table.wgsl).
@group(1) @binding(1) var<storage, read> edge_table: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> src: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> dst: array<vec4<f32>>;
@group(1) @binding(4) var visibility_out: texture_storage_2d<rgba32float, write>;
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

var<workgroup> in_reach: u32;

// Whether a record may reach this workgroup's tile in this round (`reach_holds_record`), the
// same answer for the whole workgroup; counts the tiles flooded. Call it first, in uniform
// control flow.
fn tile_in_reach(local: u32, group: vec2<u32>) -> bool {
    if local == 0u {
        in_reach = u32(reach_holds_record(vec2<i32>(group), params.step, tile_count()));
        atomicAdd(&counters[2], in_reach);
    }
    return workgroupUniformLoad(&in_reach) != 0u;
}

fn mark_tile(cell: vec2<i32>) {
    atomicStore(&tiles[cell.y / TILE * tile_count().x + cell.x / TILE], 1u);
}

// The hard-shadow test of an eye pixel (the same test as method `hard`).
fn hard_shadowed(pixel: vec2<u32>) -> bool {
    let p = textureLoad(gbuf_position, pixel, 0).xyz;
    let n = textureLoad(gbuf_normal, pixel, 0).xyz;
    let ls = to_light_space(p);
    if !ls.inside {
        return false;
    }
    let blocker = textureLoad(shadow_depth, shadow_texel(ls.uv), 0).r;
    return ls.depth - depth_bias(p, n, ls.depth, params.bias_texels, params.slope_bias_texels) > blocker;
}

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// Where the ray from receiver p through occluder point o meets the light plane, in light
// coordinates (x along r, y along u, c at the origin); w = 1 when it meets the light
// rectangle, else 0 (§3: then p is not in o's penumbra).
fn light_hit(p: vec3<f32>, o: vec3<f32>) -> vec4<f32> {
    let c = frame.light_center.xyz;
    let n = frame.light_n.xyz;
    let height_p = dot(p - c, n);
    let height_o = dot(o - p, n); // negative when o lies between p and the light plane
    if height_p <= 0.0 || height_o >= -1e-5 * height_p || -height_o >= height_p {
        return vec4<f32>(0.0);
    }
    let q = p + (o - p) * (height_p / -height_o);
    let x = dot(q - c, frame.light_r.xyz);
    let y = dot(q - c, frame.light_u.xyz);
    let on_light = abs(x) <= 0.5 * frame.light_n.w && abs(y) <= 0.5 * frame.light_u.w;
    return vec4<f32>(x, y, 0.0, select(0.0, 1.0, on_light));
}

// §3: shoot a ray from receiver p through occluder point o to the light plane. If it meets
// the light at q, the visible part is the light on the centre's side of the line through q
// orthogonal to c→q (for a receiver outside hard shadow), or the other side (inside). Returns
// rgb intensity and w = 1 when the ray meets the light (p is in a penumbra), else w = 0. This
// is what flooding minimises (or maximises) to choose an occluder.
fn intensity(p: vec3<f32>, o: vec3<f32>, inside: bool) -> vec4<f32> {
    let hit = light_hit(p, o);
    if hit.w == 0.0 {
        return vec4<f32>(0.0);
    }
    let f = edge_fraction_at(hit.xy).rgb;
    return vec4<f32>(select(f, 1.0 - f, inside), 1.0);
}

// The direction, in light coordinates, in which the silhouette next to occluder point o
// faces away from its occluder: from the shadow-map texels within `radius` of o's, those
// deeper than o (by more than `silhouette_relative`, or empty) against those that are not,
// mapped from the map's axes to the light's. (0, 0) where they show no silhouette.
fn silhouette_normal(o: vec3<f32>, radius: i32) -> vec2<f32> {
    let ls = to_light_space(o);
    let res = i32(frame.sizes.z);
    let centre = shadow_texel(ls.uv);
    let limit = ls.depth * (1.0 + max(params.silhouette_relative, 1e-3));
    var beyond = vec2<f32>(0.0);
    for (var b = -radius; b <= radius; b++) {
        for (var a = -radius; a <= radius; a++) {
            let t = centre + vec2<i32>(a, b);
            if (a == 0 && b == 0) || any(t < vec2<i32>(0)) || any(t >= vec2<i32>(res)) {
                continue;
            }
            let deeper = textureLoad(shadow_position, t, 0).w == 0.0 || textureLoad(shadow_depth, t, 0).r > limit;
            let offset = normalize(vec2<f32>(f32(a), f32(b)));
            beyond += select(-offset, offset, deeper);
        }
    }
    if dot(beyond, beyond) < 1e-6 {
        return vec2<f32>(0.0);
    }
    // Texel offsets to light coordinates: how the map's uv moves along r and along u at o.
    let step = texel_size_m(ls.depth);
    let du = (to_light_space(o + frame.light_r.xyz * step).uv - ls.uv) * f32(res);
    let dv = (to_light_space(o + frame.light_u.xyz * step).uv - ls.uv) * f32(res);
    // A normal maps through the transpose of the map (r, u) → texels.
    return normalize(vec2<f32>(dot(du, beyond), dot(dv, beyond)));
}

// The fraction of each channel's emission on the far side of the line {y : y·n = λ} from
// the direction n points to: {y : y·n > λ}.
fn fraction_beyond(n: vec2<f32>, lambda: f32) -> vec3<f32> {
    // {y·n > λ} = {y·(−n) < −λ}: the centre's side of the line along −n when −λ ≥ 0.
    if lambda <= 0.0 {
        return edge_fraction(-n, -lambda / light_reach(-n)).rgb;
    }
    return vec3<f32>(1.0) - edge_fraction(n, lambda / light_reach(n)).rgb;
}

// The visibility the final passes give receiver p for occluder point o (p in o's penumbra,
// `inside` where p is in hard shadow). With `edge_model` on, the occluder's edge is the line
// through q along the silhouette's own direction at o, and the visible part is the light
// beyond it, away from the occluder — the same half-plane for the inner and the outer
// penumbra, and the same for every o along a straight edge, so it does not hang on which o
// flooding kept. The paper's line orthogonal to c→q is exact only for the o whose q is the
// foot of the perpendicular from c, which flooding finds only approximately; across an edge
// parallel to one of the light's colour boundaries it tilts the line and paints a hue the
// light cannot cast there. Off, or where the shadow map shows no silhouette around o, the
// paper's line (§3). `normal` is `silhouette_normal` at o, or (0, 0).
fn final_intensity(p: vec3<f32>, o: vec3<f32>, inside: bool, normal: vec2<f32>) -> vec4<f32> {
    let hit = light_hit(p, o);
    if hit.w == 0.0 {
        return vec4<f32>(0.0);
    }
    if params.edge_model == 1u {
        if dot(normal, normal) > 0.0 {
            return vec4<f32>(fraction_beyond(normal, dot(hit.xy, normal)), 1.0);
        }
    }
    let f = edge_fraction_at(hit.xy).rgb;
    return vec4<f32>(select(f, 1.0 - f, inside), 1.0);
}
