// Look-ups in a light's edge table (`light::tables::edge_table`): for a line across the light
// — a straight occluder edge projected onto it — the fraction of each channel's emission on
// the light centre's side. The including shader binds the table as `edge_table` and
// `frame` (common/frame_inputs.wgsl).

const EDGE_ANGLES: u32 = 256u;
const EDGE_STATIONS: u32 = 64u;

// Where station coordinate `x` of row `row` falls among the table's entries: the entry at or
// below it (the next one lies at `at` + 1) and the fraction of the way to the next.
struct EdgeCell {
    at: u32,
    along: f32,
}

fn edge_cell(row: u32, x: f32) -> EdgeCell {
    let i = min(u32(x), EDGE_STATIONS - 2u);
    return EdgeCell((row % EDGE_ANGLES) * EDGE_STATIONS + i, clamp(x - f32(i), 0.0, 1.0));
}

fn edge_entry(row: u32, x: f32) -> vec4<f32> {
    let cell = edge_cell(row, x);
    return mix(edge_table[cell.at], edge_table[cell.at + 1u], cell.along);
}

// Where the line orthogonal to unit direction `e` (light coordinates: x along r, y along u)
// at fraction `s` ∈ [0, 1] of the way from the centre to the rectangle's edge falls in the
// table: the row below its direction, the fraction of the way to the next row, and its
// station coordinate. Look-ups are linear between neighbouring directions and distances.
struct EdgeSpot {
    row: u32,
    toward_next: f32,
    x: f32,
}

fn edge_spot(e: vec2<f32>, s: f32) -> EdgeSpot {
    let turns = fract(atan2(e.y, e.x) / 6.28318531 + 1.0);
    let y = turns * f32(EDGE_ANGLES);
    let row = u32(y);
    return EdgeSpot(row, y - f32(row), clamp(s, 0.0, 1.0) * f32(EDGE_STATIONS - 1u));
}

// The same for the line through light point `q` (light coordinates) orthogonal to c→q: the
// intensity look-up of Rong & Tan 2006 §3.
fn edge_spot_at(q: vec2<f32>) -> EdgeSpot {
    let length_q = length(q);
    if length_q <= 0.0 {
        return edge_spot(vec2<f32>(1.0, 0.0), 0.0);
    }
    let e = q / length_q;
    return edge_spot(e, length_q / light_reach(e));
}

// rgb: the fraction of each channel's emission on the centre's side of the line at `spot`;
// w: the same fraction of the light's white twin (its shape alone).
fn edge_fraction_of(spot: EdgeSpot) -> vec4<f32> {
    return mix(edge_entry(spot.row, spot.x), edge_entry(spot.row + 1u, spot.x), spot.toward_next);
}

fn edge_fraction(e: vec2<f32>, s: f32) -> vec4<f32> {
    return edge_fraction_of(edge_spot(e, s));
}

fn edge_fraction_at(q: vec2<f32>) -> vec4<f32> {
    return edge_fraction_of(edge_spot_at(q));
}

// The fraction of each channel's emission (w: of the white twin's) on the side {y : y·n < λ}
// of a line with unit normal n at signed distance λ from the centre.
fn fraction_within(n: vec2<f32>, lambda: f32) -> vec4<f32> {
    if lambda >= 0.0 {
        return edge_fraction(n, lambda / light_reach(n));
    }
    // {y·n < λ < 0} is the complement of the centre's side of the line along −n at −λ.
    return vec4<f32>(1.0) - edge_fraction(-n, -lambda / light_reach(-n));
}

// The other side: {y : y·n > λ}.
fn fraction_beyond(n: vec2<f32>, lambda: f32) -> vec4<f32> {
    return vec4<f32>(1.0) - fraction_within(n, lambda);
}

// Per-channel visibility with the hue of `visible` (a model's fraction of each channel's
// emission, w the white twin's fraction) and the level `v` a method computed for the light's
// shape by its own means: each channel is v times the channel's share over the shape's, so a
// uniform light keeps v exactly.
fn with_hue(v: f32, visible: vec4<f32>) -> vec3<f32> {
    if visible.w <= 1e-4 {
        return vec3<f32>(v);
    }
    return clamp(v * visible.rgb / visible.w, vec3<f32>(0.0), vec3<f32>(1.0));
}
