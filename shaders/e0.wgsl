// The unshadowed irradiance E0 (contract §1), identical for every method: Lambert's closed
// form over each uniform cell of the light image, times the cell's radiance, summed —
// evaluated exactly at the corners and the centre of 8×8-pixel blocks and interpolated
// inside a block wherever the error measured at its centre, and bounds for what the centre
// cannot see, keep it within E0_TOLERANCE of the exact sum; every other lit pixel is listed
// and summed exactly by a compacted pass of its own (contract §1, "E0") — one for pixels that
// see every cell of the light above their horizon, whose cells need no clipping, one for the
// rest; a pixel that sees every cell below its horizon takes 0, the exact sum, and no pass.
//
// What is interpolated: below its horizon-free region, E0 = |n · Φ(x)| per channel, where
// Φ = Σ radiance × ½ Σ Θᵢ Γᵢ is the light's vector irradiance — a smooth function of the
// position alone, so it interpolates across the normal's discontinuities (box edges, facets).
// The blend is corrected along the pixel's view ray (`ray_offset`), where a bumpy surface
// leaves the corners' blend. Where the light straddles the receiver's horizon E0 depends on
// the normal through the clipping; on a flat face (the four corners' normal equal to the
// pixel's) E0 itself is a smooth function of position and is interpolated instead, judged by
// a bound on its own error over the block (`e0_blend_error`).

#import common/frame_inputs.wgsl
#import common/pixel_list.wgsl
#import e0_grid.wgsl

@group(1) @binding(0) var<storage, read_write> e0_out: array<vec4<f32>>;
@group(1) @binding(1) var<storage, read_write> corners: array<Corner>;
// The pixels the interpolation refuses, summed exactly by a pass of their own over each list
// (common/pixel_list.wgsl says why): those that see every cell above their horizon,
// whose cells need no clipping, and the others.
@group(1) @binding(2) var<storage, read_write> above: PixelList;
@group(1) @binding(3) var<storage, read_write> above_groups: array<u32, 3>; // indirect dispatch
@group(1) @binding(4) var<storage, read_write> clipped: PixelList;
@group(1) @binding(5) var<storage, read_write> clipped_groups: array<u32, 3>;

// Pixels per block side; mirrors `render::passes::E0_BLOCK`.
const BLOCK: u32 = 8u;
// The largest estimated relative error accepted for an interpolated pixel: the estimate is
// the error measured at the block's centre (with a margin) plus a bound for positions off
// the corners' surface; `penumbra bench` measures the actual error against the exact sum.
const E0_TOLERANCE: f32 = 6e-4;
// Where a quantity varies quadratically across a block, bilinear interpolation's error is
// largest at the centre; the margin covers higher orders.
const ERROR_MARGIN: f32 = 1.25;
// |∇Φ| ≤ GRADIENT·|Φ|/dist, dist the distance to the light (a point light's Φ ∝ 1/r² has
// |∇Φ| = 2|Φ|/r; the margin covers the area light's edges): the error per unit of
// |t − t_centre|/dist in a block whose centre found it flat, which corrects nothing.
const GRADIENT: f32 = 4.0;
// A block is flat where its centre lies within FLAT × the distance to the light of the
// corners' blend (f32 rounding leaves ~1e-7 on a plane).
const FLAT: f32 = 1e-5;
// The view-ray derivative's forward difference: its step over the distance to the light.
const RAY_STEP: f32 = 1e-2;
// The derivative's relative error — the difference's truncation, ~1.5 RAY_STEP, and its
// change across the block, up to ~5 % on a curved receiver (the torus at 960×540) — times
// |∂Φ/∂t| ≤ 2|Φ|/dist (a point light's Φ ∝ 1/r²), with a margin of 2: the error per unit of
// |t − t_centre|/dist the centre's check does not see.
const RAY_FIRST: f32 = 0.2;
// Φ's second derivative along a ray, ≤ 6|Φ|/dist² for a point light, halved (Taylor) and
// doubled (margin): the error per unit of (t/dist)².
const RAY_SECOND: f32 = 6.0;
// A block whose centre could not be checked.
const UNCHECKED: f32 = 1e30;
// Where the light straddles a pixel's horizon, its E0 is blended only in a block whose
// corners' normals lie within BENT of its first corner's (`agrees`). A pixel of any
// other block has a bend of at least BENT / 2 (the triangle inequality), and accepting its
// blend would take an E0 at least BENT / (2 E0_TOLERANCE) ≈ 8 × |Φ|, which E0 (at most |Φ|
// over the cosine of the light's angular radius) reaches only on a receiver touching the
// light: so such a block's check skips the clipped sums its E0 derivative would need — the
// dearest part of the check on a landscape, whose facets' normals all differ.
const BENT: f32 = 1e-2;

struct Corner {
    phi_r: vec4<f32>,    // xyz: Φ of the red channel; w: exact E0 (red) with the corner's own normal
    phi_g: vec4<f32>,
    phi_b: vec4<f32>,
    position: vec4<f32>, // xyz: world position; w: 1 where the corner is a lit surface
    normal: vec4<f32>,   // xyz: the G-buffer normal; w: view depth
}

// Distance from x to the light's rectangle.
fn light_distance(x: vec3<f32>) -> f32 {
    let q = x - frame.light_center.xyz;
    let half = 0.5 * vec2<f32>(frame.light_n.w, frame.light_u.w);
    let along = vec2<f32>(dot(q, frame.light_r.xyz), dot(q, frame.light_u.xyz));
    let outside = abs(along) - min(abs(along), half);
    return length(vec3<f32>(outside, dot(q, frame.light_n.xyz)));
}

// One-sided emitter: only the lit side of the light plane receives light.
fn lit_side(x: vec3<f32>) -> bool {
    return dot(x - frame.light_center.xyz, frame.light_n.xyz) > 0.0;
}

fn corner_count() -> vec2<u32> {
    return (frame.sizes.xy - 1u) / BLOCK + 2u;
}

fn corner_pixel(c: vec2<u32>) -> vec2<u32> {
    return min(c * BLOCK, frame.sizes.xy - 1u);
}

// Φ per channel (columns) and the exact E0 with x's own normal (w of each column's vec4).
// `clip`: whether E0 is wanted where the light straddles the horizon (else it is −1 there,
// no sum — E0 is never negative — which `face_corner` tells from one).
fn exact_terms(x: vec3<f32>, nx: vec3<f32>, depth: f32, clip: bool) -> Corner {
    var phi = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    // With every cell above the horizon a cell's irradiance is |nx · its Φ| (`exact_above`).
    var e0_above = vec3<f32>(0.0);
    if GRID {
        let walk = grid_phi(x, nx);
        phi = walk.phi;
        e0_above = walk.e0;
    } else {
        for (var k = 0u; k < frame.sizes.w; k++) {
            let cell = light_cells[k];
            let corners = cell_corners(cell);
            let phi_cell = polygon_vector(x, corners, cell_edges(cell));
            phi += mat3x3<f32>(phi_cell * cell.radiance.r, phi_cell * cell.radiance.g, phi_cell * cell.radiance.b);
            e0_above += cell.radiance.rgb * abs(dot(nx, phi_cell));
        }
    }
    let horizon = cells_horizon(x, nx);
    let straddles = !horizon.above && !horizon.below;
    let clipped = select(clipped_sum(x, nx, clip && straddles), vec3<f32>(-1.0), straddles && !clip);
    let e0 = select(clipped, e0_above, horizon.above);
    return Corner(vec4<f32>(phi[0], e0.r), vec4<f32>(phi[1], e0.g), vec4<f32>(phi[2], e0.b), vec4<f32>(x, 1.0), vec4<f32>(nx, depth));
}

// The clipped sum where `straddles`, else 0 (every cell below the horizon, or a value the
// caller does not take) by a loop of no iterations: lavapipe runs an `if`'s body for every
// lane of its SIMD group, taken or not, but a loop's body only until no lane goes on — once,
// masked, where none straddles, instead of once per cell (`e0_corners` −30 % on `crowd`
// under `flame`, whose corners mostly see every cell above their horizon).
fn clipped_sum(x: vec3<f32>, nx: vec3<f32>, straddles: bool) -> vec3<f32> {
    var e0 = vec3<f32>(0.0);
    if GRID {
        for (var once = 0u; once < select(0u, 1u, straddles); once++) {
            e0 = grid_clipped(x, nx);
        }
        return e0;
    }
    for (var k = 0u; k < select(0u, frame.sizes.w, straddles); k++) {
        let cell = light_cells[k];
        let corners = cell_corners(cell);
        e0 += cell.radiance.rgb * polygon_irradiance(x, nx, corners, cell_edges(cell));
    }
    return e0;
}

fn no_corner() -> Corner {
    return Corner(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
}

// The exact terms at a pixel, or an invalid record where it holds no lit surface
// (`clip`: `exact_terms`).
fn pixel_terms(pixel: vec2<u32>, clip: bool) -> Corner {
    return surface_terms(pixel, textureLoad(gbuf_shading, pixel, 0), clip);
}

// `pixel_terms` at a pixel whose normal texel the caller has read (corners and centres lie
// on the screen): the texel once, for the coverage and the normal (`covers`).
fn surface_terms(pixel: vec2<u32>, normal: vec4<f32>, clip: bool) -> Corner {
    if covers(normal) {
        let x = textureLoad(gbuf_position, pixel, 0);
        if lit_side(x.xyz) {
            return exact_terms(x.xyz, normal.xyz, x.w, clip);
        }
    }
    return no_corner();
}

// Pass 1: Φ per channel and the exact E0 at every block corner — where the light straddles
// the corner's horizon, only where a block beside it may blend E0 (`beside_agreeing`).
@compute @workgroup_size(8, 8)
fn block_corners(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let count = corner_count();
    if any(id.xy >= count) {
        return;
    }
    let pixel = corner_pixel(id.xy);
    let normal = textureLoad(gbuf_shading, pixel, 0);
    corners[id.y * count.x + id.x] = surface_terms(pixel, normal, beside_agreeing(id.xy, count, normal.xyz));
}

// |a − b|², the squared distance between two unit normals: how far apart the corners' and
// pixels' normals lie (`BENT`), compared squared where a bound is (no square root).
fn normal_gap2(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return dot(a - b, a - b);
}

// Whether a block beside corner c may blend E0 where the light straddles a pixel's horizon,
// the one use of a corner's clipped sum: such a block's corners lie within BENT of its first
// (`agrees`), so within 2 BENT of each other, and it holds c and one of c's two
// neighbours along the row. Where neither neighbour's normal lies that near c's (2.5 BENT:
// room for rounding), no block takes c's clipped sum, and it is not made (a corner at the
// row's end counts as its own neighbour, and always makes it).
// `n`: c's own normal.
fn beside_agreeing(c: vec2<u32>, count: vec2<u32>, n: vec3<f32>) -> bool {
    let left = textureLoad(gbuf_shading, corner_pixel(vec2<u32>(max(c.x, 1u) - 1u, c.y)), 0).xyz;
    let right = textureLoad(gbuf_shading, corner_pixel(vec2<u32>(min(c.x + 1u, count.x - 1u), c.y)), 0).xyz;
    let limit = (2.5 * BENT) * (2.5 * BENT);
    return normal_gap2(left, n) <= limit || normal_gap2(right, n) <= limit;
}

// A block's four corner records.
struct Block {
    c00: Corner,
    c10: Corner,
    c01: Corner,
    c11: Corner,
}

fn load_block(block: vec2<u32>) -> Block {
    let row = block.y * corner_count().x + block.x;
    let below = row + corner_count().x;
    return Block(corners[row], corners[row + 1u], corners[below], corners[below + 1u]);
}

// The blend of a block's corners at a pixel is perspective-correct (bilinear over view
// depth): on a plane it puts the blend of the corners' positions on the pixel's own position
// up to second order, where plain screen-space weights would be off by the projection's
// curvature. It is Σ bᵢ cᵢ/dᵢ over Σ bᵢ/dᵢ, bᵢ the bilinear weights and dᵢ the corners' view
// depths, and both sums are linear along a row of the block: so a row holds them at its two
// ends (`RowBlend`), and a pixel takes a linear step and one division instead of four
// weights and four divisions.
struct RowBlend {
    left_r: vec4<f32>,
    left_g: vec4<f32>,
    left_b: vec4<f32>,
    left_position: vec4<f32>,
    right_r: vec4<f32>,
    right_g: vec4<f32>,
    right_b: vec4<f32>,
    right_position: vec4<f32>,
    weight: vec2<f32>, // Σ bᵢ/dᵢ at the left and right ends
}

// Row `fy` (0 at the block's top corners, 1 at its bottom ones).
fn row_blend(b: Block, fy: f32) -> RowBlend {
    let inv = 1.0 / max(vec4<f32>(b.c00.normal.w, b.c10.normal.w, b.c01.normal.w, b.c11.normal.w), vec4<f32>(1e-20));
    let w = vec4<f32>(inv.x * (1.0 - fy), inv.y * (1.0 - fy), inv.z * fy, inv.w * fy);
    return RowBlend(
        w.x * b.c00.phi_r + w.z * b.c01.phi_r,
        w.x * b.c00.phi_g + w.z * b.c01.phi_g,
        w.x * b.c00.phi_b + w.z * b.c01.phi_b,
        w.x * b.c00.position + w.z * b.c01.position,
        w.y * b.c10.phi_r + w.w * b.c11.phi_r,
        w.y * b.c10.phi_g + w.w * b.c11.phi_g,
        w.y * b.c10.phi_b + w.w * b.c11.phi_b,
        w.y * b.c10.position + w.w * b.c11.position,
        vec2<f32>(w.x + w.z, w.y + w.w),
    );
}

// The blend of the corners' records at fraction `fx` along the row.
fn blend_in_row(row: RowBlend, fx: f32) -> Corner {
    let scale = 1.0 / mix(row.weight.x, row.weight.y, fx);
    return Corner(
        mix(row.left_r, row.right_r, fx) * scale,
        mix(row.left_g, row.right_g, fx) * scale,
        mix(row.left_b, row.right_b, fx) * scale,
        mix(row.left_position, row.right_position, fx) * scale,
        vec4<f32>(0.0),
    );
}

// The fraction of the way between a block's corners that one pixel is, across and down
// (a block at the frame's edge spans fewer pixels).
fn pixel_step(block: vec2<u32>) -> vec2<f32> {
    return 1.0 / vec2<f32>(max(corner_pixel(block + 1u) - corner_pixel(block), vec2<u32>(1u)));
}

// The blend at the pixel `offset` from the block's first (`step`: `pixel_step`).
fn blend_at(b: Block, offset: vec2<u32>, step: vec2<f32>) -> Corner {
    return blend_in_row(row_blend(b, f32(offset.y) * step.y), f32(offset.x) * step.x);
}

fn all_valid(b: Block) -> bool {
    return b.c00.position.w * b.c10.position.w * b.c01.position.w * b.c11.position.w > 0.0;
}

// Largest distance of the corners' normals from nx: 0 on a flat face. One square root of the
// largest square (the same value: the root is monotonic and correctly rounded).
fn bend(b: Block, nx: vec3<f32>) -> f32 {
    let squares = vec4<f32>(
        normal_gap2(b.c00.normal.xyz, nx),
        normal_gap2(b.c10.normal.xyz, nx),
        normal_gap2(b.c01.normal.xyz, nx),
        normal_gap2(b.c11.normal.xyz, nx),
    );
    return sqrt(max(max(squares.x, squares.y), max(squares.z, squares.w)));
}

// Whether the corners' normals lie within BENT of the first corner's.
fn agrees(b: Block) -> bool {
    return bend(b, b.c00.normal.xyz) <= BENT;
}

fn phi_size(c: Corner) -> vec3<f32> {
    return vec3<f32>(length(c.phi_r.xyz), length(c.phi_g.xyz), length(c.phi_b.xyz));
}

fn e0_of(c: Corner) -> vec3<f32> {
    return vec3<f32>(c.phi_r.w, c.phi_g.w, c.phi_b.w);
}

fn max3(v: vec3<f32>) -> f32 {
    return max(v.x, max(v.y, v.z));
}

// What a block's centre pixel says about its interpolation: the derivatives of Φ and of the
// E0 blend along the view ray (`ray_offset`), and the error left at the centre once they
// are applied, relative to |Φ|.
struct Check {
    error: f32,           // UNCHECKED where the centre or a corner holds no lit surface
    ray: f32,             // the centre's offset along its view ray from the corners' blend, m
    first: f32,           // the error per unit of |t − ray|/dist the centre does not see
    d_phi: mat3x3<f32>,   // ∂Φ/∂t per channel (columns)
    d_e0: vec3<f32>,      // ∂E0/∂t with the centre's normal; taken only where the block blends E0
    // A bound on |E0's corrected blend − its exact sum| over the block, per channel
    // (`e0_blend_error`), by which a pixel the light straddles the horizon of is judged;
    // UNCHECKED where the block does not blend E0 — its corners' normals disagree (`agrees`)
    // — or its centre sees every cell on one side of its horizon (its pixels' E0 is then
    // |n · Φ| or 0, or summed exactly).
    e0_error: vec3<f32>,
}

fn unchecked() -> Check {
    return Check(UNCHECKED, 0.0, 0.0, mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0)), vec3<f32>(0.0), vec3<f32>(UNCHECKED));
}

fn phi_of(c: Corner) -> mat3x3<f32> {
    return mat3x3<f32>(c.phi_r.xyz, c.phi_g.xyz, c.phi_b.xyz);
}

// Unit direction from the eye through x.
fn view_ray(x: vec3<f32>) -> vec3<f32> {
    return normalize(x - frame.eye.xyz);
}

// The pixel's signed distance along its view ray from the corners' blended position.
// Perspective-correct weights put the blend on the pixel's own view ray (the weights are the
// screen-space bilinear ones over depth, so the blend projects to the pixel), so on a surface
// that bends or bumps inside the block the blend misses x only along that ray: by t, and Φ
// there is the blend's plus t ∂Φ/∂t to first order — the correction that lets a bumpy
// surface (a landscape) be interpolated at all, where the plain blend is off by |∇Φ| t.
fn ray_offset(x: vec3<f32>, mixed: Corner) -> f32 {
    let view = x - frame.eye.xyz;
    return dot(x - mixed.position.xyz, view) * inverseSqrt(dot(view, view));
}

// Measures the block at its centre pixel: the error of the corrected interpolation there
// and, where the centre leaves the corners' blend along its ray at all (the block is not
// flat), Φ's and the E0 blend's derivatives along the view ray, by a forward difference of
// RAY_STEP × the distance to the light (truncation ~1.5 RAY_STEP of the derivative; Φ's
// rounding, atan2-based, stays far below it). A flat block skips the difference (one exact
// sum fewer: on lavapipe the SIMD groups of a flat floor or box face take no lane through
// it) and bounds what its pixels' offsets add by Φ's gradient instead.
fn block_check(block: vec2<u32>, b: Block) -> Check {
    let centre = min(block * BLOCK + BLOCK / 2u, frame.sizes.xy - 1u);
    let blends_e0 = agrees(b);
    let exact = pixel_terms(centre, blends_e0);
    if !all_valid(b) || exact.position.w <= 0.0 {
        return unchecked();
    }
    let x = exact.position.xyz;
    // The same blend as the block's pixels take (`interpolate_blocks`).
    let mixed = blend_at(b, centre - block * BLOCK, pixel_step(block));
    let t = ray_offset(x, mixed);
    var check = Check(0.0, t, GRADIENT, mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0)), vec3<f32>(0.0), vec3<f32>(UNCHECKED));
    let distance_to_light = light_distance(x);
    if abs(t) > FLAT * distance_to_light {
        let step = RAY_STEP * distance_to_light;
        let beyond = x + step * view_ray(x);
        if !lit_side(beyond) {
            return unchecked();
        }
        let ahead = exact_terms(beyond, exact.normal.xyz, exact.normal.w, blends_e0);
        check.first = RAY_FIRST;
        check.d_phi = (phi_of(ahead) - phi_of(exact)) * (1.0 / step);
        check.d_e0 = (e0_of(ahead) - e0_of(exact)) / step;
    }
    let phi = phi_of(mixed) + check.d_phi * t;
    let size = max(phi_size(exact), vec3<f32>(1e-30));
    let phi_error = vec3<f32>(
        distance(phi[0], exact.phi_r.xyz),
        distance(phi[1], exact.phi_g.xyz),
        distance(phi[2], exact.phi_b.xyz),
    );
    check.error = max3(phi_error / size);
    // Where E0 itself is blended (the light straddles the horizon, on a flat face): a bound
    // on its own error over the block (`e0_blend_error`).
    let horizon = cells_horizon(x, exact.normal.xyz);
    if blends_e0 && !horizon.above && !horizon.below {
        check.e0_error = e0_blend_error(block, b, e0_of(mixed) + check.d_e0 * t - e0_of(exact));
    }
    return check;
}

// Corner c's exact E0 (xyz) and view depth (w) where it lies on the grid, on a lit surface
// and on the face whose normal is n (within BENT), and its E0 was summed; w = 0 otherwise.
fn face_corner(c: vec2<i32>, n: vec3<f32>) -> vec4<f32> {
    let count = vec2<i32>(corner_count());
    let i = u32(clamp(c.y, 0, count.y - 1) * count.x + clamp(c.x, 0, count.x - 1));
    // A corner with no lit surface has a zero normal (`no_corner`), which fails the test; one
    // whose clipped sum was not made (`beside_agreeing`) holds −1 (`exact_terms`).
    let normal = corners[i].normal;
    let usable = all(c >= vec2<i32>(0)) && all(c < count) && normal_gap2(normal.xyz, n) <= BENT * BENT
        && corners[i].phi_r.w >= 0.0;
    return select(vec4<f32>(0.0), vec4<f32>(corners[i].phi_r.w, corners[i].phi_g.w, corners[i].phi_b.w, normal.w), usable);
}

// The error of the blend between corners `before` and `after` (E0 and view depth, as
// `face_corner` gives them), two blocks apart, at the corner `middle` between them, the
// fraction `f` of the way (½ but next to the frame's last row or column, whose block is
// narrower): the blend the block's pixels take (perspective-correct), over twice the block's
// width. Per channel; w = 0 where an end does not lie on the face.
fn wide_blend_error(before: vec4<f32>, middle: Corner, after: vec4<f32>, f: f32) -> vec4<f32> {
    let w = vec2<f32>((1.0 - f) / max(before.w, 1e-20), f / max(after.w, 1e-20));
    let blend = (before.xyz * w.x + after.xyz * w.y) / (w.x + w.y);
    return select(vec4<f32>(0.0), vec4<f32>(abs(blend - e0_of(middle)), 1.0), before.w > 0.0 && after.w > 0.0);
}

// A bound on the error of E0's blend over the block, per channel; `centre`, its signed
// error at the block's centre. A bilinear blend reproduces a quadratic's cross term, so its
// error at (u, v) in the block is ½ (u(1−u) a + v(1−v) b), a and b the second differences
// along the block's sides: (a + b)/8 at the centre and at most (|a| + |b|)/8 anywhere. The
// centre alone does not bound it: where a ≈ −b (a saddle, as E0 under a light standing on
// the receiver's plane) it reads ~0 while the middle of an edge is off by |a|/8 — judged by
// Φ's error at the centre instead, such pixels departed from the exact sum by up to
// 1.04·10⁻³ (a steep `stripes` light over `occluder`'s floor). So a and b are measured too,
// with no exact sum more: the same blend between the corners two blocks apart misses the
// corner halfway between them by |a|/2 (along a row; |b|/2 down a column), read at each of
// the block's four corners from its neighbour beyond it on the same face (the largest, per
// direction: a and b may differ between the block's two rows or columns). UNCHECKED where a
// direction has none: a block along the face's edge or the frame's.
fn e0_blend_error(block: vec2<u32>, b: Block, centre: vec3<f32>) -> vec3<f32> {
    let n = b.c00.normal.xyz;
    let c = vec2<i32>(block);
    let left0 = face_corner(c + vec2<i32>(-1, 0), n);
    let left1 = face_corner(c + vec2<i32>(-1, 1), n);
    let right0 = face_corner(c + vec2<i32>(2, 0), n);
    let right1 = face_corner(c + vec2<i32>(2, 1), n);
    let up0 = face_corner(c + vec2<i32>(0, -1), n);
    let up1 = face_corner(c + vec2<i32>(1, -1), n);
    let down0 = face_corner(c + vec2<i32>(0, 2), n);
    let down1 = face_corner(c + vec2<i32>(1, 2), n);
    let c00 = vec4<f32>(e0_of(b.c00), b.c00.normal.w);
    let c10 = vec4<f32>(e0_of(b.c10), b.c10.normal.w);
    let c01 = vec4<f32>(e0_of(b.c01), b.c01.normal.w);
    let c11 = vec4<f32>(e0_of(b.c11), b.c11.normal.w);
    // Where the block's first and second corners lie between their neighbours, per axis
    // (corner_pixel's spacing: BLOCK, but the last one's).
    let p0 = vec2<f32>(corner_pixel(block));
    let p1 = vec2<f32>(corner_pixel(block + 1u));
    let first = f32(BLOCK) / (p1 - p0 + f32(BLOCK));
    let second = (p1 - p0) / (vec2<f32>(corner_pixel(block + 2u)) - p0);
    let across = max(
        max(wide_blend_error(left0, b.c00, c10, first.x), wide_blend_error(c00, b.c10, right0, second.x)),
        max(wide_blend_error(left1, b.c01, c11, first.x), wide_blend_error(c01, b.c11, right1, second.x)),
    );
    let down = max(
        max(wide_blend_error(up0, b.c00, c01, first.y), wide_blend_error(c00, b.c01, down0, second.y)),
        max(wide_blend_error(up1, b.c10, c11, first.y), wide_blend_error(c10, b.c11, down1, second.y)),
    );
    // |a|/8 = |across| / 4, |b|/8 = |down| / 4.
    let sides = (across.xyz + down.xyz) * 0.25;
    return select(vec3<f32>(UNCHECKED), max(abs(centre), sides), across.w > 0.0 && down.w > 0.0);
}

// Where the light's cells lie against the horizon of x (the plane through it with normal
// nx), judged over the rectangle that bounds them (`frame.cells_bounds`), not over the whole
// light — a shaped light's black texels are no part of its sum, and under a low light a
// landscape's slopes see all of a flame's cells above their horizon, or none, where the
// rectangle straddles it. Neither above nor below: the light straddles the horizon and its
// cells are clipped.
struct Horizon {
    // The least height above HORIZON_EPS: every cell lies above, and its clipped irradiance
    // is its unclipped |nx · Φ| (the same edge terms in the same order).
    above: bool,
    // The greatest at most 0 (HORIZON_EPS below the clip's threshold, for rounding): every
    // cell lies below, no clipped edge survives and E0 is exactly 0.
    below: bool,
}

fn cells_horizon(x: vec3<f32>, nx: vec3<f32>) -> Horizon {
    let bounds = frame.cells_bounds;
    let centre = frame.light_center.xyz + bounds.x * frame.light_r.xyz + bounds.y * frame.light_u.xyz;
    let c = dot(centre - x, nx);
    let reach = bounds.z * abs(dot(frame.light_r.xyz, nx)) + bounds.w * abs(dot(frame.light_u.xyz, nx));
    return Horizon(c - reach > HORIZON_EPS, c + reach <= 0.0);
}

// E0 at one pixel interpolated from its block's corners, corrected along the view ray
// (`ray_offset`): xyz, and w = 1 where the estimate accepts it (or the pixel receives no
// light); where it must be summed exactly, w = 0 if every cell lies above its horizon
// (`exact_above`), else −1 (`exact_clipped`). `normal` is the pixel's G-buffer normal texel
// (w: coverage); `mixed`, the blend of the block's corners at the pixel (`blend_in_row`).
fn interpolated_e0(x: vec3<f32>, normal: vec4<f32>, b: Block, mixed: Corner, check: Check) -> vec4<f32> {
    let nx = normal.xyz;
    if !covers(normal) || !lit_side(x) {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    let t = ray_offset(x, mixed);
    // The centre's error with a margin; what the derivative's error adds where the pixel lies
    // farther along its ray than the centre did; and the second order in t.
    let dist = light_distance(x);
    let reach = t / dist;
    let beyond = abs(t - check.ray) / dist;
    let first_order = check.first * beyond;
    let second_order = RAY_SECOND * reach * reach;
    let relative = ERROR_MARGIN * check.error + first_order + second_order;
    let phi = phi_of(mixed) + check.d_phi * t;
    // Both cases in straight-line code (lavapipe runs both sides of a branch its SIMD group
    // splits on, and a landscape splits most groups): with every cell above the horizon
    // E0 is |nx · Φ|; where the light straddles it, on a flat face (the corners' normal the
    // pixel's) E0 is still smooth in the position and is blended itself; with every cell
    // below it E0 is 0, exactly the sum (`cells_horizon`).
    let horizon = cells_horizon(x, nx);
    let above = horizon.above;
    let below = horizon.below;
    let e0 = select(select(e0_of(mixed) + check.d_e0 * t, abs(nx * phi), above), vec3<f32>(0.0), below);
    let size2 = vec3<f32>(dot(phi[0], phi[0]), dot(phi[1], phi[1]), dot(phi[2], phi[2]));
    let bound = E0_TOLERANCE * e0;
    // Every cell above: relative × |Φ| ≤ E0_TOLERANCE × E0, compared squared (no square root
    // per channel); both sides' signs kept (relative ≥ 0, E0 may not be).
    let fits_above = all(relative * relative * size2 <= bound * abs(bound));
    // Straddled, on a flat face: E0's own error over the block with the margin, plus what
    // lies off the centre in units of |Φ| — the ray terms and the pixel's bend from the
    // corners' normals (E0 moves by up to |Φ| per unit of normal) — at most E0_TOLERANCE × E0:
    // what the first leaves, squared, against the second's square (no square root either).
    // UNCHECKED fails it.
    let off_centre = first_order + second_order + bend(b, nx);
    let room = bound - ERROR_MARGIN * check.e0_error;
    let fits_straddled = all(room >= vec3<f32>(0.0)) && all(off_centre * off_centre * size2 <= room * room);
    let done = (select(fits_straddled, fits_above, above) && check.error < UNCHECKED) || below;
    return vec4<f32>(e0, select(select(-1.0, 0.0, above), 1.0, done));
}

// Appends the pixels of a block whose bits are set in `mask` — bit 8r + x: column x of row
// `first_row` + r — to `above` or to `clipped`, with one atomic for the lot. (WGSL passes no
// pointer to a storage buffer into a function, so the list is chosen by a flag.)
fn append_rows(to_above: bool, origin: vec2<u32>, first_row: u32, mask: u32) {
    if mask == 0u {
        return;
    }
    var at: u32;
    if to_above {
        at = atomicAdd(&above.count, countOneBits(mask));
    } else {
        at = atomicAdd(&clipped.count, countOneBits(mask));
    }
    var rest = mask;
    while rest != 0u {
        let bit = firstTrailingBit(rest);
        let entry = pixel_index(origin + vec2<u32>(bit % BLOCK, first_row + bit / BLOCK));
        if to_above {
            above.pixels[at] = entry;
        } else {
            clipped.pixels[at] = entry;
        }
        at++;
        rest &= rest - 1u;
    }
}

// Pass 2, one invocation per block (a row of blocks per workgroup row): the centre checks
// the interpolation, then each of the block's pixels is interpolated where the estimate
// allows and listed otherwise for the exact sum — in `above` where every cell lies above
// its horizon, else in `clipped` — four rows at a time (an atomic append per pixel is a loop
// over the lanes on lavapipe). One invocation loads the block's 20
// corner vectors for its 64 pixels: on lavapipe a storage load is a gather lane by lane
// whatever the lanes read, so loading them per pixel cost more than the interpolation itself.
@compute @workgroup_size(64)
fn interpolate_blocks(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let block = id.xy;
    if any(block >= corner_count() - 1u) {
        return;
    }
    let b = load_block(block);
    let check = block_check(block, b);
    let origin = block * BLOCK;
    let step = pixel_step(block);
    // The pixels to list, four rows at a time: 4 × BLOCK (8) bits.
    var to_above = 0u;
    var to_clip = 0u;
    for (var y = 0u; y < BLOCK; y++) {
        let row = row_blend(b, f32(y) * step.y);
        for (var x = 0u; x < BLOCK; x++) {
            let bit = 1u << ((y % 4u) * BLOCK + x);
            let pixel = origin + vec2<u32>(x, y);
            if all(pixel < frame.sizes.xy) {
                // Loaded once here: lavapipe runs the listing branch's code for every pixel.
                let position = textureLoad(gbuf_position, pixel, 0).xyz;
                let normal = textureLoad(gbuf_shading, pixel, 0);
                let e0 = interpolated_e0(position, normal, b, blend_in_row(row, f32(x) * step.x), check);
                // Stored whether or not the estimate holds: a refused pixel's value is
                // overwritten by its exact pass, and lavapipe stores a whole SIMD group for
                // less than it stores a masked part of one (the pass −7 % on `terrain`).
                e0_out[pixel_index(pixel)] = vec4<f32>(e0.xyz, 1.0);
                if e0.w == 0.0 {
                    // Every cell above the horizon: summed without clipping.
                    to_above |= bit;
                } else if e0.w < 0.0 {
                    to_clip |= bit;
                }
            }
        }
        if y % 4u == 3u {
            append_rows(true, origin, y - 3u, to_above);
            append_rows(false, origin, y - 3u, to_clip);
            to_above = 0u;
            to_clip = 0u;
        }
    }
}

// Every pixel summed exactly, in one pass: lights of a cell or two, where the corners and
// the check cost more than they save (and listing the lit pixels costs more than the cells'
// sums: an atomic append per lane), and `E0Mode::Exact`, the yardstick the interpolation is
// measured against.
@compute @workgroup_size(8, 8)
fn exact(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let origin = 2u * id.xy;
    if any(origin >= frame.sizes.xy) {
        return;
    }
    let last = frame.sizes.xy - 1u;
    let p = array<vec2<u32>, 4>(origin, min(origin + vec2<u32>(1u, 0u), last), min(origin + vec2<u32>(0u, 1u), last), min(origin + 1u, last));
    let q = Quad(screen_surface(p[0]), screen_surface(p[1]), screen_surface(p[2]), screen_surface(p[3]));
    store_quad(q, clipped_quad(q));
}

// A pixel's surface, its normal zero where it receives no light (E0 = 0 then).
fn screen_surface(pixel: vec2<u32>) -> Surface {
    let x = textureLoad(gbuf_position, pixel, 0).xyz;
    let normal = textureLoad(gbuf_shading, pixel, 0);
    let lit = covers(normal) && lit_side(x);
    return Surface(pixel_index(pixel), x, select(vec3<f32>(0.0), normal.xyz, lit));
}

// The sizes of the two exact passes' dispatches.
@compute @workgroup_size(1)
fn exact_sizes() {
    frame = frame_uniform;
    above_groups = list_dispatch((atomicLoad(&above.count) + QUAD - 1u) / QUAD);
    clipped_groups = list_dispatch((atomicLoad(&clipped.count) + QUAD - 1u) / QUAD);
}

// A listed pixel's surface: its element of the screen-space images, position and normal.
struct Surface {
    at: u32,
    x: vec3<f32>,
    nx: vec3<f32>,
}

fn listed_surface(entry: u32) -> Surface {
    let pixel = listed_pixel(entry);
    return Surface(entry, textureLoad(gbuf_position, pixel, 0).xyz, textureLoad(gbuf_shading, pixel, 0).xyz);
}

// Listed pixels per invocation of the exact passes. On lavapipe a uniform-buffer load indexed
// by the loop over cells is a gather, lane by lane, and loading a cell cost more than summing
// it for one pixel: four pixels per invocation load each cell once for all four.
const QUAD: u32 = 4u;

// The four listed pixels of one invocation.
struct Quad {
    a: Surface,
    b: Surface,
    c: Surface,
    d: Surface,
}

fn listed_quad(pixels: vec4<u32>) -> Quad {
    return Quad(listed_surface(pixels.x), listed_surface(pixels.y), listed_surface(pixels.z), listed_surface(pixels.w));
}

fn store_quad(q: Quad, e0: mat4x3<f32>) {
    e0_out[q.a.at] = vec4<f32>(e0[0], 1.0);
    e0_out[q.b.at] = vec4<f32>(e0[1], 1.0);
    e0_out[q.c.at] = vec4<f32>(e0[2], 1.0);
    e0_out[q.d.at] = vec4<f32>(e0[3], 1.0);
}

// The list positions of an invocation's quad, clamped to the list: where it ends, the last
// pixel is summed again and written twice with the same value.
fn quad_positions(group: vec3<u32>, lane: u32, count: u32) -> vec4<u32> {
    let first = QUAD * list_position(group, lane);
    return min(vec4<u32>(first) + vec4<u32>(0u, 1u, 2u, 3u), vec4<u32>(count - 1u));
}

// The pixels of `above`, summed exactly without clipping: where the whole light lies above
// x's horizon, |nx · Φ| of each cell (`polygon_vector`, its own four edges) is the value
// `polygon_irradiance` computes there, in the same order, at about half the cost.
@compute @workgroup_size(64)
fn exact_above(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    let count = atomicLoad(&above.count);
    if QUAD * list_position(group, lane) >= count {
        return;
    }
    let at = quad_positions(group, lane, count);
    let q = listed_quad(vec4<u32>(above.pixels[at.x], above.pixels[at.y], above.pixels[at.z], above.pixels[at.w]));
    if GRID {
        store_quad(q, grid_above_quad(q));
        return;
    }
    var e0 = mat4x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var k = 0u; k < frame.sizes.w; k++) {
        let cell = light_cells[k];
        let corners = cell_corners(cell);
        let edges = cell_edges(cell);
        e0[0] += cell.radiance.rgb * abs(dot(q.a.nx, polygon_vector(q.a.x, corners, edges)));
        e0[1] += cell.radiance.rgb * abs(dot(q.b.nx, polygon_vector(q.b.x, corners, edges)));
        e0[2] += cell.radiance.rgb * abs(dot(q.c.nx, polygon_vector(q.c.x, corners, edges)));
        e0[3] += cell.radiance.rgb * abs(dot(q.d.nx, polygon_vector(q.d.x, corners, edges)));
    }
    store_quad(q, e0);
}

// The exact sum at each of a quad's pixels (columns), every cell clipped to its hemisphere.
fn clipped_quad(q: Quad) -> mat4x3<f32> {
    if GRID {
        // Pixel by pixel: the walk's carried state is twice the unclipped one's, and four
        // walks side by side (the row's cells loaded once for all) spill more than they save.
        return mat4x3<f32>(grid_clipped(q.a.x, q.a.nx), grid_clipped(q.b.x, q.b.nx), grid_clipped(q.c.x, q.c.nx), grid_clipped(q.d.x, q.d.nx));
    }
    var e0 = mat4x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var k = 0u; k < frame.sizes.w; k++) {
        let cell = light_cells[k];
        let corners = cell_corners(cell);
        let edges = cell_edges(cell);
        e0[0] += cell.radiance.rgb * polygon_irradiance(q.a.x, q.a.nx, corners, edges);
        e0[1] += cell.radiance.rgb * polygon_irradiance(q.b.x, q.b.nx, corners, edges);
        e0[2] += cell.radiance.rgb * polygon_irradiance(q.c.x, q.c.nx, corners, edges);
        e0[3] += cell.radiance.rgb * polygon_irradiance(q.d.x, q.d.nx, corners, edges);
    }
    return e0;
}

// The pixels of `clipped`, summed exactly with each cell clipped to the hemisphere.
@compute @workgroup_size(64)
fn exact_clipped(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    let count = atomicLoad(&clipped.count);
    if QUAD * list_position(group, lane) >= count {
        return;
    }
    let at = quad_positions(group, lane, count);
    let q = listed_quad(vec4<u32>(clipped.pixels[at.x], clipped.pixels[at.y], clipped.pixels[at.z], clipped.pixels[at.w]));
    store_quad(q, clipped_quad(q));
}

// The unclipped sums of a quad's pixels over the grid (`GRID`), a row of cells at a time for
// all four: the row's cells are loaded once for the quad (`QUAD`), cheaper than a pixel at
// a time.
fn grid_above_quad(q: Quad) -> mat4x3<f32> {
    let columns = grid_columns();
    let top = light_cells[0u].rect.w;
    var a = above_start(q.a.x, q.a.nx, columns, top);
    var b = above_start(q.b.x, q.b.nx, columns, top);
    var c = above_start(q.c.x, q.c.nx, columns, top);
    var d = above_start(q.d.x, q.d.nx, columns, top);
    for (var r = 0u; r < SIDE; r++) {
        let row = grid_row(r);
        above_row(&a, q.a.x, columns, row);
        above_row(&b, q.b.x, columns, row);
        above_row(&c, q.c.x, columns, row);
        above_row(&d, q.d.x, columns, row);
    }
    return mat4x3<f32>(a.e0, b.e0, c.e0, d.e0);
}
