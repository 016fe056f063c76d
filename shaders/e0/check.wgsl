// Whether a block's interpolation of E0 may stand: what its centre pixel says, corrected
// along the view ray, and a bound on E0's own blend error where the light straddles a flat
// face's horizon (shaders/e0/interpolate.wgsl).

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
