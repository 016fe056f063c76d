// Look-ups in a light's edge table (`light::tables::edge_table`): for a line across the light
// — a straight occluder edge projected onto it — the fraction of each channel's emission on
// the light centre's side. The including shader binds the table as `edge_table` and
// `frame` (common/frame_inputs.wgsl).

const EDGE_ANGLES: u32 = 256u;
const EDGE_STATIONS: u32 = 64u;

fn edge_entry(row: u32, x: f32) -> vec4<f32> {
    let i = min(u32(x), EDGE_STATIONS - 2u);
    let at = (row % EDGE_ANGLES) * EDGE_STATIONS + i;
    return mix(edge_table[at], edge_table[at + 1u], clamp(x - f32(i), 0.0, 1.0));
}

// The line orthogonal to unit direction `e` (light coordinates: x along r, y along u) at
// fraction `s` ∈ [0, 1] of the way from the centre to the rectangle's edge: rgb the fraction of
// each channel's emission on the centre's side, w the luminance-weighted fraction. Linear
// between neighbouring directions and distances.
fn edge_fraction(e: vec2<f32>, s: f32) -> vec4<f32> {
    let turns = fract(atan2(e.y, e.x) / 6.28318531 + 1.0);
    let y = turns * f32(EDGE_ANGLES);
    let row = u32(y);
    let x = clamp(s, 0.0, 1.0) * f32(EDGE_STATIONS - 1u);
    return mix(edge_entry(row, x), edge_entry(row + 1u, x), y - f32(row));
}

// Distance from the light's centre to its rectangle's edge along unit direction `e`.
fn light_reach(e: vec2<f32>) -> f32 {
    let half = 0.5 * vec2<f32>(frame.light_n.w, frame.light_u.w);
    return min(half.x / max(abs(e.x), 1e-9), half.y / max(abs(e.y), 1e-9));
}

// The same for the line through light point `q` (light coordinates) orthogonal to c→q: the
// intensity look-up of Rong & Tan 2006 §3.
fn edge_fraction_at(q: vec2<f32>) -> vec4<f32> {
    let length_q = length(q);
    if length_q <= 0.0 {
        return edge_fraction(vec2<f32>(1.0, 0.0), 0.0);
    }
    let e = q / length_q;
    return edge_fraction(e, length_q / light_reach(e));
}
