// E0's exact sums over a light of 64 cells — its whole 8 × 8 grid, none merged and none
// black, as a photograph's are (`light::irradiance::light_cells` lists them row by row from
// the image's top, left to right): a corner of the grid belongs to up to four cells and an
// edge to two, so walking the grid a row at a time, with the corners and edge terms of the
// line above the row carried from the row before, takes each of the 81 corners and 144 edges
// once where the cells' own sums (`polygon_vector`, `polygon_irradiance`) take 256 of each.
// The same terms as the cells' sums, in another order: equal up to f32 rounding. `GRID`, a
// pipeline constant, is set for such a light (`render::FrameSpec::full_grid`).
//
// A cell's boundary runs bottom, right, top, left (`cell_corners`): its bottom edge is the
// grid's edge along the line below it, left to right; its right edge the vertical between
// the two lines, upward; its top and left edges are its upper and left neighbours' bottom
// and right edges, reversed — the same Θ Γ negated (Θ is symmetric, Γ ∝ a × b is not).
// Only n · Θ Γ enters a receiver's sum, so an edge's term is carried as that one number,
// and made along its line of the grid (`GridPlanes`), not from its ends' unit directions.

#import common/frame_inputs.wgsl

override GRID: bool = false;

// Cells per side of the grid; mirrors `light::E0_GRID`.
const SIDE: u32 = 8u;

// The grid's vertical lines, metres along r from the light's centre: the columns' left
// edges, then the last column's right edge.
fn grid_columns() -> array<f32, 9> {
    var x: array<f32, 9>;
    #unroll i in 0..8 {
        x[i] = light_cells[i].rect.x;
    }
    x[SIDE] = light_cells[SIDE - 1u].rect.y;
    return x;
}

// The point of the grid on vertical line `column` and horizontal line `line` (metres along
// u), as `cell_corners` makes a cell's corner.
fn grid_point(column: f32, line: f32) -> vec3<f32> {
    return (frame.light_center.xyz + column * frame.light_r.xyz) + line * frame.light_u.xyz;
}

// One row of cells: its top and bottom lines, metres along u, and the cells' radiance.
struct GridRow {
    top: f32,
    bottom: f32,
    radiance: array<vec3<f32>, 8>,
}

fn grid_row(row: u32) -> GridRow {
    var r: GridRow;
    let first = light_cells[row * SIDE];
    r.top = first.rect.w;
    r.bottom = first.rect.z;
    #unroll i in 0..8 {
        r.radiance[i] = light_cells[row * SIDE + i].radiance.rgb;
    }
    return r;
}

// A point of the grid seen from x: its place along its line's axis, its unit direction and
// inverse distance.
struct SeenPoint {
    at: f32,
    dir: vec3<f32>,
    inv: f32,
}

fn seen_point(x: vec3<f32>, at: f32, point: vec3<f32>) -> SeenPoint {
    let p = point - x;
    let inv = inverseSqrt(dot(p, p));
    return SeenPoint(at, p * inv, inv);
}

// The corners of the horizontal line `line` (metres along u) seen from x: unit directions and
// inverse distances.
struct SeenLine {
    dir: array<vec3<f32>, 9>,
    inv: array<f32, 9>,
}

fn seen_line(x: vec3<f32>, columns: array<f32, 9>, line: f32) -> SeenLine {
    var l: SeenLine;
    #unroll i in 0..9 {
        let corner = seen_point(x, columns[i], grid_point(columns[i], line));
        l.dir[i] = corner.dir;
        l.inv[i] = corner.inv;
    }
    return l;
}

// Every edge of the grid lies on a line along r or u, and every point p of one line (relative
// to x) has the same p × r (a horizontal line) or p × u (a vertical one): (C − x) × r + y (u × r)
// for the line y metres along u, (C − x) × u + X (r × u) for the line X metres along r (C, the
// light's centre). So the cross product of the directions to two of its points a, b is that
// vector times the length from a to b over |a| |b| — exactly, and made without the two
// products near 1 that cancel to sin Θ when it is taken from the directions themselves: from
// metres away the grid's cells subtend a few hundredths of a radian, a × b of unit vectors
// keeps a few ulps of 1 of error, and a cell's four terms cancel again to its solid angle
// (the exact sum under `mosaic` was 1.9·10⁻³ off an f64 sum at receivers 5 m away; see
// `edge_part`, which takes a cell's own edges the same way).
struct GridPlanes {
    across: vec3<f32>, // (C − x) × r
    up: vec3<f32>,     // (C − x) × u
    slope: vec3<f32>,  // r × u: the horizontal lines' vector falls by it per metre along u, the vertical lines' rises per metre along r
}

fn grid_planes(x: vec3<f32>) -> GridPlanes {
    let c = frame.light_center.xyz - x;
    return GridPlanes(cross(c, frame.light_r.xyz), cross(c, frame.light_u.xyz), cross(frame.light_r.xyz, frame.light_u.xyz));
}

// n · the planes' vectors — a line's moment about x along n, n · (p × axis), the same for every
// point of the line — for the walks that need only a receiver's terms.
struct GridMoments {
    across: f32,
    up: f32,
    slope: f32,
}

fn grid_moments(x: vec3<f32>, nx: vec3<f32>) -> GridMoments {
    let p = grid_planes(x);
    return GridMoments(dot(nx, p.across), dot(nx, p.up), dot(nx, p.slope));
}

// The vector p × r of the horizontal line `line`, and p × u of the vertical line `column`.
fn across_plane(p: GridPlanes, line: f32) -> vec3<f32> {
    return p.across - line * p.slope;
}

fn up_plane(p: GridPlanes, column: f32) -> vec3<f32> {
    return p.up + column * p.slope;
}

// The moment n · (p × r) of the horizontal line `line`, and n · (p × u) of the vertical line
// `column` (`GridPlanes`; n · `across_plane`, `up_plane`).
fn across_moment(h: GridMoments, line: f32) -> f32 {
    return h.across - line * h.slope;
}

fn up_moment(h: GridMoments, column: f32) -> f32 {
    return h.up + column * h.slope;
}

// n · Θ Γ of the part of a grid line from a to b (unit directions ua, ub, inverse distances
// inv_a, inv_b; `length`, metres from a to b along the line's axis; `moment`, the line's n ·
// (p × axis)): n · (a × b) = moment × length / (|a| |b|), times Θ / sin Θ.
fn line_term(moment: f32, length: f32, inv_a: f32, inv_b: f32, ua: vec3<f32>, ub: vec3<f32>) -> f32 {
    return moment * (length * inv_a * inv_b) * edge_scale(cross(ua, ub), dot(ua, ub));
}

// Θ Γ itself, `plane` the line's p × axis.
fn line_vector(plane: vec3<f32>, length: f32, inv_a: f32, inv_b: f32, ua: vec3<f32>, ub: vec3<f32>) -> vec3<f32> {
    let c = plane * (length * inv_a * inv_b);
    return c * edge_scale(c, dot(ua, ub));
}

// --- Every cell above the horizon: |n · Φ| per cell (`exact_above`) ----------------------

// A pixel's walk down the grid: the line above the row (its corners seen from x) and the
// n · Θ Γ of its edges left to right, and the sum so far.
struct AboveWalk {
    line: SeenLine,
    edge: array<f32, 8>,
    moments: GridMoments,
    e0: vec3<f32>,
}

fn above_start(x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, line: f32) -> AboveWalk {
    var w: AboveWalk;
    w.line = seen_line(x, columns, line);
    w.moments = grid_moments(x, nx);
    let moment = across_moment(w.moments, line);
    #unroll i in 0..8 {
        w.edge[i] = line_term(moment, columns[i + 1u] - columns[i], w.line.inv[i], w.line.inv[i + 1u], w.line.dir[i], w.line.dir[i + 1u]);
    }
    w.e0 = vec3<f32>(0.0);
    return w;
}

// Adds a row's cells, each ½ |n · (bottom + right − top − left)| times its radiance.
fn above_row(w: ptr<function, AboveWalk>, x: vec3<f32>, columns: array<f32, 9>, row: GridRow) {
    let below = seen_line(x, columns, row.bottom);
    let across = across_moment((*w).moments, row.bottom);
    var up: array<f32, 9>;
    #unroll i in 0..9 {
        up[i] = line_term(up_moment((*w).moments, columns[i]), row.top - row.bottom, below.inv[i], (*w).line.inv[i], below.dir[i], (*w).line.dir[i]);
    }
    #unroll i in 0..8 {
        let bottom = line_term(across, columns[i + 1u] - columns[i], below.inv[i], below.inv[i + 1u], below.dir[i], below.dir[i + 1u]);
        (*w).e0 += row.radiance[i] * (0.5 * abs(bottom + up[i + 1u] - (*w).edge[i] - up[i]));
        (*w).edge[i] = bottom;
    }
    (*w).line = below;
}

// --- Φ, the light's vector irradiance (the block corners' and checks' `exact_terms`) -----

// A pixel's walk for Φ: the line above the row, its edges' Θ Γ left to right, and per
// channel Φ so far (columns) with the sum of |n · Φ| of each cell (E0 where every cell lies
// above the horizon).
struct PhiWalk {
    line: SeenLine,
    edge: array<vec3<f32>, 8>,
    phi: mat3x3<f32>,
    e0: vec3<f32>,
}

// Φ per channel (columns) and Σ radiance × |n · the cell's Φ| at x, over the grid.
fn grid_phi(x: vec3<f32>, nx: vec3<f32>) -> PhiWalk {
    let columns = grid_columns();
    let planes = grid_planes(x);
    var w: PhiWalk;
    let top = light_cells[0u].rect.w;
    w.line = seen_line(x, columns, top);
    let top_plane = across_plane(planes, top);
    #unroll i in 0..8 {
        w.edge[i] = line_vector(top_plane, columns[i + 1u] - columns[i], w.line.inv[i], w.line.inv[i + 1u], w.line.dir[i], w.line.dir[i + 1u]);
    }
    w.phi = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    w.e0 = vec3<f32>(0.0);
    for (var r = 0u; r < SIDE; r++) {
        let row = grid_row(r);
        let below = seen_line(x, columns, row.bottom);
        let across = across_plane(planes, row.bottom);
        var up: array<vec3<f32>, 9>;
        #unroll i in 0..9 {
            up[i] = line_vector(up_plane(planes, columns[i]), row.top - row.bottom, below.inv[i], w.line.inv[i], below.dir[i], w.line.dir[i]);
        }
        #unroll i in 0..8 {
            let bottom = line_vector(across, columns[i + 1u] - columns[i], below.inv[i], below.inv[i + 1u], below.dir[i], below.dir[i + 1u]);
            let cell = 0.5 * (bottom + up[i + 1u] - w.edge[i] - up[i]);
            let l = row.radiance[i];
            w.phi += mat3x3<f32>(cell * l.r, cell * l.g, cell * l.b);
            w.e0 += l * abs(dot(nx, cell));
            w.edge[i] = bottom;
        }
        w.line = below;
    }
    return w;
}

// --- Cells clipped to the hemisphere (`exact_clipped`, and every straddling corner) ----

// Where the horizon crosses the straight line of the grid from its end a to its end b (their
// places along the line's axis, metres; their heights above x's horizon): the place of the
// point at height HORIZON_EPS, as `clip_edge` finds it on a cell's edge. A line crosses the
// horizon's plane once at most, so the crossing of whichever of its edges crosses is the
// line's, found once for the line's eight edges (18 crossings a pixel instead of 152).
// Where the line's ends lie on one
// side, an edge of it that its corners' heights say crosses does so by rounding alone: the
// whole line then lies within rounding of the horizon, and a stands in for the crossing —
// moving a vertex of the clipped polygon along the horizon changes its projected solid angle
// by nothing.
fn line_crossing(a: f32, b: f32, da: f32, db: f32) -> f32 {
    let t = (HORIZON_EPS - da) / (db - da);
    return select(a, a + t * (b - a), (da > HORIZON_EPS) != (db > HORIZON_EPS));
}

// n · Θ Γ of the part of the grid line's edge a → b above x's horizon (heights da, db;
// `moment`, the line's: `line_term`), q its line's crossing (`line_crossing`), as `clip_edge`
// clips a cell's edge; with neither end above, 0 (q is no crossing there). Chosen among the
// points, not among the terms: an edge with both ends above then takes the arithmetic of
// `above_row`, term and sum alike, bit for bit (`exact_above` and `exact_clipped` agree where
// both apply).
fn clipped_term(moment: f32, q: SeenPoint, a: SeenPoint, b: SeenPoint, da: f32, db: f32) -> f32 {
    let above_a = da > HORIZON_EPS;
    let above_b = db > HORIZON_EPS;
    let start = pick(q, a, above_a);
    let end = pick(q, b, above_b);
    let length = select(0.0, end.at - start.at, above_a || above_b);
    return line_term(moment, length, start.inv, end.inv, start.dir, end.dir);
}

// `select` for a `SeenPoint`: `t` where `take`, else `f`.
fn pick(f: SeenPoint, t: SeenPoint, take: bool) -> SeenPoint {
    return SeenPoint(select(f.at, t.at, take), select(f.dir, t.dir, take), select(f.inv, t.inv, take));
}

// Every crossing of the horizon lies on one great circle of directions from x, the horizon's,
// and on the line where the horizon's plane meets the light's; the closing edge of a cell
// straddling the horizon runs along that circle, so its term n · Θ Γ is the signed angle
// about n from its exit to its entry: the difference of the two crossings' angles from one
// direction of the circle (`horizon_angle`). Each crossing's angle is made once, where the
// crossing is found (18 a pixel), instead of an edge term per cell (64).
struct HorizonCircle {
    origin: vec3<f32>,  // the direction to the point of the line nearest the light's centre
    quarter: vec3<f32>, // n × origin, a quarter turn on
}

// The origin is the direction to the point of the line nearest the light's centre: the line
// crosses the light, so that point lies within the light's circumscribed circle, and the
// crossings' angles from it are no wider than the light seen from x — a difference of two of
// them loses little to rounding — and within half a turn of it, as all of a line's points are
// (`edge_term_turned`, with `edge_scale`'s obtuse branch where the frame needs it, measures
// such an angle). The
// point: C + s e, e = n − (n · n_l) n_l the light plane's direction across the line, s making
// its height above x's horizon 0. Where the two planes are parallel no cell straddles and any
// direction in the horizon will do.
fn horizon_circle(x: vec3<f32>, nx: vec3<f32>) -> HorizonCircle {
    let n_light = frame.light_n.xyz;
    let across = nx - dot(nx, n_light) * n_light;
    let slope = dot(nx, across); // 1 − (n · n_l)², |n × n_l|²
    let centre = frame.light_center.xyz - x;
    let nearest = centre - across * (dot(nx, centre) / slope);
    let origin = normalize(select(cross(nx, frame.light_r.xyz), nearest, slope > 1e-12));
    return HorizonCircle(origin, cross(nx, origin));
}

// The signed angle about n from the circle's origin to q, a unit direction on the circle.
fn horizon_angle(c: HorizonCircle, q: vec3<f32>) -> f32 {
    return edge_term_turned(c.quarter, c.origin, q);
}

// The edge along the horizon that closes a straddling cell's clipped polygon, from where its
// boundary leaves the hemisphere to where it re-enters (`polygon_irradiance`): corners
// above it (bottom-left, bottom-right, top-right, top-left) and the angles of the crossings
// of the edges that start at each, in the boundary's order.
fn closing_term(above: vec4<bool>, bottom: f32, right: f32, top: f32, left: f32) -> f32 {
    let leaves = above & !above.yzwx;
    let enters = above.yzwx & !above;
    let exit = select(select(select(left, top, leaves.z), right, leaves.y), bottom, leaves.x);
    let entry = select(select(select(left, top, enters.z), right, enters.y), bottom, enters.x);
    return select(0.0, entry - exit, any(above) && !all(above));
}

// The corners of one horizontal line seen from x (`seen_line`) and their heights above x's
// horizon.
struct ClippedLine {
    seen: SeenLine,
    height: array<f32, 9>,
}

fn clipped_line(x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, line: f32) -> ClippedLine {
    var l: ClippedLine;
    l.seen = seen_line(x, columns, line);
    #unroll i in 0..9 {
        l.height[i] = dot(grid_point(columns[i], line) - x, nx);
    }
    return l;
}

// Corner i of a line as a `SeenPoint` along the line (`columns[i]` metres along r).
fn line_point(l: SeenLine, columns: array<f32, 9>, i: u32) -> SeenPoint {
    return SeenPoint(columns[i], l.dir[i], l.inv[i]);
}

// Where the horizon crosses the horizontal line `line` (metres along u) whose corners are `l`.
fn across_crossing(x: vec3<f32>, columns: array<f32, 9>, line: f32, l: ClippedLine) -> SeenPoint {
    let at = line_crossing(columns[0], columns[SIDE], l.height[0], l.height[SIDE]);
    return seen_point(x, at, grid_point(at, line));
}

// A pixel's walk down the grid: the line above the row (its corners seen from x, the clipped
// terms of its edges left to right, the angle of its crossing on the horizon's circle), where
// the horizon crosses each vertical line of the grid, and the sum so far.
struct ClippedWalk {
    line: SeenLine,
    edge: array<f32, 8>,
    crossing_angle: f32,
    // The crossings of the vertical lines, and their angles on the horizon's circle
    // (`closing_term`).
    vertical: array<SeenPoint, 9>,
    vertical_angle: array<f32, 9>,
    circle: HorizonCircle,
    moments: GridMoments,
    e0: vec3<f32>,
}

fn clipped_start(x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, top_line: f32, bottom_line: f32) -> ClippedWalk {
    let top = clipped_line(x, nx, columns, top_line);
    var w: ClippedWalk;
    w.circle = horizon_circle(x, nx);
    w.moments = grid_moments(x, nx);
    w.line = top.seen;
    let crossing = across_crossing(x, columns, top_line, top);
    w.crossing_angle = horizon_angle(w.circle, crossing.dir);
    let across = across_moment(w.moments, top_line);
    #unroll i in 0..8 {
        w.edge[i] = clipped_term(across, crossing, line_point(top.seen, columns, i), line_point(top.seen, columns, i + 1u), top.height[i], top.height[i + 1u]);
    }
    #unroll i in 0..9 {
        let bottom = dot(grid_point(columns[i], bottom_line) - x, nx);
        let at = line_crossing(top_line, bottom_line, top.height[i], bottom);
        w.vertical[i] = seen_point(x, at, grid_point(columns[i], at));
        w.vertical_angle[i] = horizon_angle(w.circle, w.vertical[i].dir);
    }
    w.e0 = vec3<f32>(0.0);
    return w;
}

// Adds a row's cells, each clipped: ½ |n · (its clipped edges + the closing edge)| times its
// radiance. The top line's heights are made again (a subtraction and a dot product each)
// rather than carried.
fn clipped_row(w: ptr<function, ClippedWalk>, x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, row: GridRow) {
    let below = clipped_line(x, nx, columns, row.bottom);
    let crossing = across_crossing(x, columns, row.bottom, below);
    let crossing_angle = horizon_angle((*w).circle, crossing.dir);
    var top_height: array<f32, 9>;
    var up: array<f32, 9>;
    #unroll i in 0..9 {
        top_height[i] = dot(grid_point(columns[i], row.top) - x, nx);
        let bottom = SeenPoint(row.bottom, below.seen.dir[i], below.seen.inv[i]);
        let top = SeenPoint(row.top, (*w).line.dir[i], (*w).line.inv[i]);
        up[i] = clipped_term(up_moment((*w).moments, columns[i]), (*w).vertical[i], bottom, top, below.height[i], top_height[i]);
    }
    let across = across_moment((*w).moments, row.bottom);
    #unroll i in 0..8 {
        let bottom = clipped_term(across, crossing, line_point(below.seen, columns, i), line_point(below.seen, columns, i + 1u), below.height[i], below.height[i + 1u]);
        let above = vec4<f32>(below.height[i], below.height[i + 1u], top_height[i + 1u], top_height[i]) > vec4<f32>(HORIZON_EPS);
        let closing = closing_term(above, crossing_angle, (*w).vertical_angle[i + 1u], (*w).crossing_angle, (*w).vertical_angle[i]);
        let sum = bottom + up[i + 1u] - (*w).edge[i] - up[i] + closing;
        (*w).e0 += row.radiance[i] * (0.5 * abs(sum));
        (*w).edge[i] = bottom;
    }
    (*w).line = below.seen;
    (*w).crossing_angle = crossing_angle;
}

// The clipped sum at one point (the corners' and the checks' `clipped_sum`, `exact_clipped`).
fn grid_clipped(x: vec3<f32>, nx: vec3<f32>) -> vec3<f32> {
    let columns = grid_columns();
    var w = clipped_start(x, nx, columns, light_cells[0u].rect.w, light_cells[SIDE * SIDE - 1u].rect.z);
    for (var row = 0u; row < SIDE; row++) {
        clipped_row(&w, x, nx, columns, grid_row(row));
    }
    return w.e0;
}
