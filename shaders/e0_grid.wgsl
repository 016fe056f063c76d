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
// Only n · Θ Γ enters a receiver's sum, so an edge's term is carried as that one number.

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

// The unit directions from x to the corners of the horizontal line `line` (metres along u).
fn grid_directions(x: vec3<f32>, columns: array<f32, 9>, line: f32) -> array<vec3<f32>, 9> {
    var dir: array<vec3<f32>, 9>;
    #unroll i in 0..9 {
        dir[i] = normalize(grid_point(columns[i], line) - x);
    }
    return dir;
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

// The corners of one horizontal line seen from x: unit directions, and their offsets from x
// (for the horizon's crossings) with heights above x's horizon.
struct GridLine {
    dir: array<vec3<f32>, 9>,
    offset: array<vec3<f32>, 9>,
    height: array<f32, 9>,
}

fn grid_line(x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, line: f32) -> GridLine {
    var l: GridLine;
    #unroll i in 0..9 {
        let p = grid_point(columns[i], line) - x;
        l.offset[i] = p;
        l.dir[i] = normalize(p);
        l.height[i] = dot(p, nx);
    }
    return l;
}

// --- Every cell above the horizon: |n · Φ| per cell (`exact_above`) ----------------------

// A pixel's walk down the grid: the line above the row (directions to its corners) and the
// n · Θ Γ of its edges left to right, and the sum so far.
struct AboveWalk {
    dir: array<vec3<f32>, 9>,
    edge: array<f32, 8>,
    e0: vec3<f32>,
}

fn above_start(x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, line: f32) -> AboveWalk {
    var w: AboveWalk;
    w.dir = grid_directions(x, columns, line);
    #unroll i in 0..8 {
        w.edge[i] = edge_term(nx, w.dir[i], w.dir[i + 1u]);
    }
    w.e0 = vec3<f32>(0.0);
    return w;
}

// Adds a row's cells, each ½ |n · (bottom + right − top − left)| times its radiance.
fn above_row(w: ptr<function, AboveWalk>, x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, row: GridRow) {
    let below = grid_directions(x, columns, row.bottom);
    var turned: array<vec3<f32>, 9>;
    var up: array<f32, 9>;
    #unroll i in 0..9 {
        turned[i] = cross(nx, below[i]);
        up[i] = edge_term_turned(turned[i], below[i], (*w).dir[i]);
    }
    #unroll i in 0..8 {
        let bottom = edge_term_turned(turned[i], below[i], below[i + 1u]);
        (*w).e0 += row.radiance[i] * (0.5 * abs(bottom + up[i + 1u] - (*w).edge[i] - up[i]));
        (*w).edge[i] = bottom;
    }
    (*w).dir = below;
}

// --- Φ, the light's vector irradiance (the block corners' and checks' `exact_terms`) -----

// A pixel's walk for Φ: the line above the row, its edges' Θ Γ left to right, and per
// channel Φ so far (columns) with the sum of |n · Φ| of each cell (E0 where every cell lies
// above the horizon).
struct PhiWalk {
    dir: array<vec3<f32>, 9>,
    edge: array<vec3<f32>, 8>,
    phi: mat3x3<f32>,
    e0: vec3<f32>,
}

// Φ per channel (columns) and Σ radiance × |n · the cell's Φ| at x, over the grid.
fn grid_phi(x: vec3<f32>, nx: vec3<f32>) -> PhiWalk {
    let columns = grid_columns();
    var w: PhiWalk;
    w.dir = grid_directions(x, columns, light_cells[0u].rect.w);
    #unroll i in 0..8 {
        w.edge[i] = edge_vector(w.dir[i], w.dir[i + 1u]);
    }
    w.phi = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    w.e0 = vec3<f32>(0.0);
    for (var r = 0u; r < SIDE; r++) {
        let row = grid_row(r);
        let below = grid_directions(x, columns, row.bottom);
        var up: array<vec3<f32>, 9>;
        #unroll i in 0..9 {
            up[i] = edge_vector(below[i], w.dir[i]);
        }
        #unroll i in 0..8 {
            let bottom = edge_vector(below[i], below[i + 1u]);
            let cell = 0.5 * (bottom + up[i + 1u] - w.edge[i] - up[i]);
            let l = row.radiance[i];
            w.phi += mat3x3<f32>(cell * l.r, cell * l.g, cell * l.b);
            w.e0 += l * abs(dot(nx, cell));
            w.edge[i] = bottom;
        }
        w.dir = below;
    }
    return w;
}

// --- Cells clipped to the hemisphere (`exact_clipped`, and every straddling corner) ----

// Where the horizon crosses the straight line of the grid from corner a to corner b (their
// offsets from x, a's direction, their heights above x's horizon): the point at height
// HORIZON_EPS, as `clip_edge` finds it on a cell's edge. A line crosses the horizon's plane
// once at most, so the crossing of whichever of its edges crosses is the line's, found once
// for the line's eight edges (for `exact_clipped` on `terrain` under `mosaic`, 18 crossings
// a pixel instead of 152: 70 → 57 ms). Where the line's ends lie on one side, an edge of it that
// its corners' heights say crosses does so by rounding alone: the whole line then lies within
// rounding of the horizon, and a's direction stands in for the crossing — moving a vertex of
// the clipped polygon along the horizon changes its projected solid angle by nothing.
fn line_crossing(a: vec3<f32>, b: vec3<f32>, ua: vec3<f32>, da: f32, db: f32) -> vec3<f32> {
    return select(ua, horizon_crossing(a, b, da, db), (da > HORIZON_EPS) != (db > HORIZON_EPS));
}

// n · Θ Γ of the part of edge ua → ub above x's horizon (heights da, db), q its line's
// crossing (`line_crossing`), as `clip_edge` clips a cell's edge. With neither end above,
// the edge from ua to itself, whose term is exactly 0 (q is no crossing there). Chosen among
// the directions, not among the terms: an edge with both ends above then takes the
// arithmetic of `above_row`, term and sum alike, bit for bit (`exact_above` and
// `exact_clipped` agree where both apply).
fn clipped_term(nx: vec3<f32>, q: vec3<f32>, ua: vec3<f32>, ub: vec3<f32>, da: f32, db: f32) -> f32 {
    let above_a = da > HORIZON_EPS;
    let above_b = db > HORIZON_EPS;
    let neither = !above_a && !above_b;
    return edge_term(nx, select(q, ua, above_a || neither), select(select(q, ub, above_b), ua, neither));
}

// Every crossing of the horizon lies on one great circle of directions from x, the horizon's,
// and on the line where the horizon's plane meets the light's; the closing edge of a cell
// straddling the horizon runs along that circle, so its term n · Θ Γ is the signed angle
// about n from its exit to its entry: the difference of the two crossings' angles from one
// direction of the circle (`horizon_angle`). Each crossing's angle is made once, where the
// crossing is found (18 a pixel), instead of an edge term per cell (64: `exact_clipped`
// ~62 → ~52 ms on `terrain` under `mosaic`, medians of six rounds in turn).
struct HorizonCircle {
    origin: vec3<f32>,  // the direction to the point of the line nearest the light's centre
    quarter: vec3<f32>, // n × origin, a quarter turn on
}

// The origin is the direction to the point of the line nearest the light's centre: the line
// crosses the light, so that point lies within the light's circumscribed circle, and the
// crossings' angles from it are no wider than the light seen from x — a difference of two of
// them loses little to rounding — and within half a turn of it, as all of a line's points are
// (`edge_term`, with its obtuse branch where the frame needs it, measures such an angle). The
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

// A pixel's walk down the grid: the line above the row (directions to its corners, the
// clipped terms of its edges left to right, where the horizon crosses it), where the
// horizon crosses each vertical line of the grid, and the sum so far.
struct ClippedWalk {
    dir: array<vec3<f32>, 9>,
    edge: array<f32, 8>,
    crossing: vec3<f32>,
    vertical: array<vec3<f32>, 9>,
    // The crossings' angles on the horizon's circle (`closing_term`).
    crossing_angle: f32,
    vertical_angle: array<f32, 9>,
    circle: HorizonCircle,
    e0: vec3<f32>,
}

fn clipped_start(x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, top_line: f32, bottom_line: f32) -> ClippedWalk {
    let top = grid_line(x, nx, columns, top_line);
    var w: ClippedWalk;
    w.circle = horizon_circle(x, nx);
    w.dir = top.dir;
    w.crossing = line_crossing(top.offset[0], top.offset[SIDE], top.dir[0], top.height[0], top.height[SIDE]);
    w.crossing_angle = horizon_angle(w.circle, w.crossing);
    #unroll i in 0..8 {
        w.edge[i] = clipped_term(nx, w.crossing, top.dir[i], top.dir[i + 1u], top.height[i], top.height[i + 1u]);
    }
    #unroll i in 0..9 {
        let bottom = grid_point(columns[i], bottom_line) - x;
        w.vertical[i] = line_crossing(top.offset[i], bottom, top.dir[i], top.height[i], dot(bottom, nx));
        w.vertical_angle[i] = horizon_angle(w.circle, w.vertical[i]);
    }
    w.e0 = vec3<f32>(0.0);
    return w;
}

// Adds a row's cells, each clipped: ½ |n · (its clipped edges + the closing edge)| times its
// radiance. The top line's heights are made again (a subtraction and a dot product each)
// rather than carried.
fn clipped_row(w: ptr<function, ClippedWalk>, x: vec3<f32>, nx: vec3<f32>, columns: array<f32, 9>, row: GridRow) {
    let below = grid_line(x, nx, columns, row.bottom);
    let crossing = line_crossing(below.offset[0], below.offset[SIDE], below.dir[0], below.height[0], below.height[SIDE]);
    let crossing_angle = horizon_angle((*w).circle, crossing);
    var top_height: array<f32, 9>;
    var up: array<f32, 9>;
    #unroll i in 0..9 {
        top_height[i] = dot(grid_point(columns[i], row.top) - x, nx);
        up[i] = clipped_term(nx, (*w).vertical[i], below.dir[i], (*w).dir[i], below.height[i], top_height[i]);
    }
    #unroll i in 0..8 {
        let bottom = clipped_term(nx, crossing, below.dir[i], below.dir[i + 1u], below.height[i], below.height[i + 1u]);
        let above = vec4<f32>(below.height[i], below.height[i + 1u], top_height[i + 1u], top_height[i]) > vec4<f32>(HORIZON_EPS);
        let closing = closing_term(above, crossing_angle, (*w).vertical_angle[i + 1u], (*w).crossing_angle, (*w).vertical_angle[i]);
        let sum = bottom + up[i + 1u] - (*w).edge[i] - up[i] + closing;
        (*w).e0 += row.radiance[i] * (0.5 * abs(sum));
        (*w).edge[i] = bottom;
    }
    (*w).dir = below.dir;
    (*w).crossing = crossing;
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
