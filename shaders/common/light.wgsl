// The area light: uniform sub-rectangles (cells) with their radiance, and Lambert's closed
// form for the irradiance of a polygon, clipped to the receiver's hemisphere. The GPU twin of
// `light::polygon_irradiance` / `light::unshadowed_irradiance`.

struct LightCell {
    // Its rectangle in the light's frame, metres from the light's centre: x from its left to
    // its right edge along r, then y from its bottom to its top edge along u (`cell_corners`
    // makes the world corners). Four floats where the corners were twelve: on lavapipe each
    // float of a uniform costs ~20 instructions a SIMD group to load, at every cell of every
    // exact sum, and the corners' arithmetic less than a third of that.
    rect: vec4<f32>,
    radiance: vec4<f32>, // rgb: intensity × colour × alpha
}

// Θ Γ for the edge between unit directions a and b: the angle it subtends times the unit
// normal of the plane through x and the edge (Lambert's edge term; contract §1) — the cross
// product a × b (length sin Θ) times Θ / sin Θ. For an acute angle Θ / sin Θ is a smooth
// function of u = 1 − cos Θ (singular only at Θ = π, u = 2), held by `theta_over_sin`; an
// obtuse one is π − the acute Θ' with the same sine, so Θ / sin Θ = π / sin Θ − Θ' / sin Θ.
// No atan2 and no acos: as accurate as atan2 at every angle (1e-7 relative where f32 allows;
// acos loses the tiny angles of distant cells), and cheaper on lavapipe, the more so where
// no edge can be obtuse (`ACUTE_EDGES`).
fn edge_vector(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    let c = cross(a, b);
    return c * edge_scale(c, dot(a, b));
}

// n · `edge_vector(a, b)` with n × a given as `turned`: n · (a × b) = (n × a) · b. The signed
// angle about n from a to b where both lie in the plane normal to n (the horizon's circle,
// `horizon_angle` in shaders/e0/grid.wgsl). a × b itself is left to `edge_scale`, which reads
// it only where an edge may be obtuse.
fn edge_term_turned(turned: vec3<f32>, a: vec3<f32>, b: vec3<f32>) -> f32 {
    return dot(turned, b) * edge_scale(cross(a, b), dot(a, b));
}

// Θ / sin Θ for the edge whose a × b is c and a · b is cos Θ (`edge_vector`).
fn edge_scale(c: vec3<f32>, cos_theta: f32) -> f32 {
    let acute = theta_over_sin(1.0 - abs(cos_theta));
    if ACUTE_EDGES {
        return acute;
    }
    let sin2 = dot(c, c);
    let ratio = select(acute, PI * inverseSqrt(sin2) - acute, cos_theta < 0.0);
    // a = −b (the point on the edge's line between its ends): no plane, no term.
    return select(0.0, ratio, sin2 > 1e-24 || cos_theta >= 0.0);
}

const PI: f32 = 3.14159265;

// Set (a pipeline constant) where no receiver of the frame can see an edge of the light under
// more than a right angle (`light::edges_acute_from`: the scene's box lies farther from the
// light's centre than its diagonal): `edge_vector` then needs no obtuse branch, which a
// select would compute for every edge and a branch measured no cheaper on lavapipe.
override ACUTE_EDGES: bool = false;

// Θ / sin Θ for Θ ∈ [0, π/2] from u = 1 − cos Θ ∈ [0, 1]: a degree-9 polynomial fitted to
// acos(1 − u) / √(u(2 − u)) (Chebyshev, relative weights); at most 1.2e-7 relative in f32 by
// Horner's rule (1 + u/3 + 2u²/15 + … near 0, where cos Θ rounds but u's rounding barely moves it).
fn theta_over_sin(u: f32) -> f32 {
    return 1.0 + u * (0.33333632 + u * (0.13325340 + u * (0.058051180 + u * (0.020000827 + u * (0.030052582
        + u * (-0.032870978 + u * (0.049723420 + u * (-0.031646591 + u * 0.010896152))))))));
}

// The polygon clipped to the half-space above a receiver's plane, accumulated edge by edge:
// the clipped edges' Θ Γ, and where the boundary leaves (`exit`) and re-enters (`entry`)
// that half-space.
struct ClippedEdges {
    sum: vec3<f32>,
    exit: vec3<f32>,
    entry: vec3<f32>,
}

const HORIZON_EPS: f32 = 1e-6;

// Θ Γ for the part of an edge from s0 to s1 (fractions of the way along it), whose start
// there has unit direction `start` and whose end has inverse distance `inv_end` from x; `e`,
// the whole edge's vector, `cos_theta`, the part's a · b. The cross product of the part's
// two unit directions is (s1 − s0) (start × e) / |end| — exactly, since start × (its own
// point) = 0 — made without the two products near 1 that cancel to sin Θ when it is taken
// from the directions themselves: from metres away a cell of a few centimetres subtends
// ~0.01 rad, a × b of unit vectors keeps a few ulps of 1 of error (~10⁻⁵ of it), and a cell's
// four terms cancel again to its solid angle, so its sum lost ~10⁻³ (f64 against f32 at
// such receivers: 8.1·10⁻⁴ worst with the directions' product, 3.9·10⁻⁵ along the edge).
fn edge_part(start: vec3<f32>, e: vec3<f32>, s0: f32, s1: f32, inv_end: f32, cos_theta: f32) -> vec3<f32> {
    let c = cross(start, e) * ((s1 - s0) * inv_end);
    return c * edge_scale(c, cos_theta);
}

// The whole edge from unit direction a to b (`edge_part` from 0 to 1); `inv_b`, 1 / |b's
// point − x|.
fn edge_along(a: vec3<f32>, b: vec3<f32>, e: vec3<f32>, inv_b: f32) -> vec3<f32> {
    return edge_part(a, e, 0.0, 1.0, inv_b, dot(a, b));
}

// Adds edge a→b (a relative to x; unit directions ua, ub; b's inverse distance inv_b;
// heights da, db above the plane; `e` = b − a from the light's frame), clipped to the
// half-space. Straight-line code with selects rather than branches: lavapipe runs both sides
// of every branch that differs between neighbouring pixels, so the crossing point and one
// edge term, always computed, cost less than three guarded edge terms. The crossing's
// fraction t is meaningless (and may not be finite) where both ends lie on one side; no
// select then takes it.
fn clip_edge(edges: ptr<function, ClippedEdges>, a: vec3<f32>, e: vec3<f32>, ua: vec3<f32>, ub: vec3<f32>, inv_b: f32, da: f32, db: f32) {
    let above_a = da > HORIZON_EPS;
    let above_b = db > HORIZON_EPS;
    // The crossing, HORIZON_EPS above the plane: a + t e.
    let t = (HORIZON_EPS - da) / (db - da);
    let crossing = a + t * e;
    let inv_q = inverseSqrt(dot(crossing, crossing));
    let q = crossing * inv_q;
    let start = select(q, ua, above_a);
    let end = select(q, ub, above_b);
    let term = edge_part(start, e, select(t, 0.0, above_a), select(t, 1.0, above_b), select(inv_q, inv_b, above_b), dot(start, end));
    (*edges).sum += select(vec3<f32>(0.0), term, above_a || above_b);
    (*edges).exit = select((*edges).exit, q, above_a && !above_b);
    (*edges).entry = select((*edges).entry, q, above_b && !above_a);
}

// A quad's corners seen from x: their offsets from it, their unit directions and their inverse
// distances (what each edge term along its edge needs: `edge_along`, `clip_edge`).
struct SeenQuad {
    p0: vec3<f32>,
    p1: vec3<f32>,
    p2: vec3<f32>,
    p3: vec3<f32>,
    u0: vec3<f32>,
    u1: vec3<f32>,
    u2: vec3<f32>,
    u3: vec3<f32>,
    inv: vec4<f32>,
}

fn seen_quad(x: vec3<f32>, corners: array<vec4<f32>, 4>) -> SeenQuad {
    let p0 = corners[0].xyz - x;
    let p1 = corners[1].xyz - x;
    let p2 = corners[2].xyz - x;
    let p3 = corners[3].xyz - x;
    let inv = inverseSqrt(vec4<f32>(dot(p0, p0), dot(p1, p1), dot(p2, p2), dot(p3, p3)));
    return SeenQuad(p0, p1, p2, p3, p0 * inv.x, p1 * inv.y, p2 * inv.z, p3 * inv.w, inv);
}

// ∫ cosθx dω over the quad seen from x (normal nx), clipped to the hemisphere above x:
// ½ |Σ Θᵢ (nx · Γᵢ)| over the clipped polygon's edges. A convex quad cut by a plane leaves it
// at most once and re-enters at most once, so the clipped polygon is the clipped edges plus
// one edge along the horizon from the exit to the entry point; written without an array of
// clipped vertices (a dynamically indexed local array costs a memory round trip per lane on
// lavapipe). Five edge terms whatever the clipping.
// `edges`: the quad's edge vectors, corner i to corner i + 1 (`cell_edges`).
fn polygon_irradiance(x: vec3<f32>, nx: vec3<f32>, corners: array<vec4<f32>, 4>, edges: array<vec3<f32>, 4>) -> f32 {
    let q = seen_quad(x, corners);
    let d = vec4<f32>(dot(q.p0, nx), dot(q.p1, nx), dot(q.p2, nx), dot(q.p3, nx));
    var e = ClippedEdges(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    clip_edge(&e, q.p0, edges[0], q.u0, q.u1, q.inv.y, d.x, d.y);
    clip_edge(&e, q.p1, edges[1], q.u1, q.u2, q.inv.z, d.y, d.z);
    clip_edge(&e, q.p2, edges[2], q.u2, q.u3, q.inv.w, d.z, d.w);
    clip_edge(&e, q.p3, edges[3], q.u3, q.u0, q.inv.x, d.w, d.x);
    let crossed = any(d > vec4<f32>(HORIZON_EPS)) && any(d <= vec4<f32>(HORIZON_EPS));
    let sum = e.sum + select(vec3<f32>(0.0), edge_vector(e.exit, e.entry), crossed);
    return 0.5 * abs(dot(nx, sum));
}

// The vector irradiance of the whole quad seen from x, ½ Σ Θᵢ Γᵢ (its sign follows the
// corners' winding; independent of any normal): where the quad lies wholly above x's
// horizon, `polygon_irradiance` is |nx · it|. Each edge term along its edge (`edge_along`).
fn polygon_vector(x: vec3<f32>, corners: array<vec4<f32>, 4>, edges: array<vec3<f32>, 4>) -> vec3<f32> {
    let q = seen_quad(x, corners);
    return 0.5 * (edge_along(q.u0, q.u1, edges[0], q.inv.y) + edge_along(q.u1, q.u2, edges[1], q.inv.z)
        + edge_along(q.u2, q.u3, edges[2], q.inv.w) + edge_along(q.u3, q.u0, edges[3], q.inv.x));
}
