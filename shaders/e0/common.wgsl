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
#import e0/grid.wgsl

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

// pixels' normals lie (`BENT`), compared squared where a bound is (no square root).
fn normal_gap2(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return dot(a - b, a - b);
}

// Whether a block beside corner c may blend E0 where the light straddles a pixel's horizon,

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
