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
// acos loses the tiny angles of distant cells), and on lavapipe E0 under a 26-cell light
// over a 100k-triangle landscape took 162 ms instead of 190, 148 ms where no edge can be
// obtuse (`ACUTE_EDGES`).
fn edge_vector(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    let c = cross(a, b);
    return c * edge_scale(c, dot(a, b));
}

// n · `edge_vector(a, b)`, the edge's term in a receiver's sum: the scale applied to the one
// number rather than to the vector (E0's grid sums, shaders/e0_grid.wgsl: `exact_above` −9 %).
fn edge_term(nx: vec3<f32>, a: vec3<f32>, b: vec3<f32>) -> f32 {
    return edge_term_turned(cross(nx, a), a, b);
}

// `edge_term` with n × a given: n · (a × b) = (n × a) · b, so a corner's n × a serves every
// edge that starts at it (E0's grid walk starts two at each corner: `exact_above` 32 → 29 ms
// on `terrain` under `mosaic`). a × b itself is left to `edge_scale`, which reads it only
// where an edge may be obtuse.
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

// The unit direction from x to where edge a→b (relative to x, heights da, db above x's
// plane) crosses the horizon, HORIZON_EPS above the plane: a + (b − a)(ε − da)/(db − da),
// scaled by db − da (no division) — its direction is all `edge_vector` needs, so the scale
// only has to keep its sign. Meaningless where both ends lie on one side.
fn horizon_crossing(a: vec3<f32>, b: vec3<f32>, da: f32, db: f32) -> vec3<f32> {
    return normalize((a * (db - HORIZON_EPS) + b * (HORIZON_EPS - da)) * sign(db - da));
}

// Adds edge a→b (relative to x, unit directions ua, ub, heights da, db above the plane),
// clipped to the half-space. Straight-line code with selects rather than branches: lavapipe
// runs both sides of every branch that differs between neighbouring pixels, so the crossing
// point and one edge term, always computed, cost less than three guarded edge terms.
fn clip_edge(e: ptr<function, ClippedEdges>, a: vec3<f32>, b: vec3<f32>, ua: vec3<f32>, ub: vec3<f32>, da: f32, db: f32) {
    let above_a = da > HORIZON_EPS;
    let above_b = db > HORIZON_EPS;
    let q = horizon_crossing(a, b, da, db);
    let term = edge_vector(select(q, ua, above_a), select(q, ub, above_b));
    (*e).sum += select(vec3<f32>(0.0), term, above_a || above_b);
    (*e).exit = select((*e).exit, q, above_a && !above_b);
    (*e).entry = select((*e).entry, q, above_b && !above_a);
}

// ∫ cosθx dω over the quad seen from x (normal nx), clipped to the hemisphere above x:
// ½ |Σ Θᵢ (nx · Γᵢ)| over the clipped polygon's edges. A convex quad cut by a plane leaves it
// at most once and re-enters at most once, so the clipped polygon is the clipped edges plus
// one edge along the horizon from the exit to the entry point; written without an array of
// clipped vertices (a dynamically indexed local array costs a memory round trip per lane on
// lavapipe). Five edge terms whatever the clipping.
fn polygon_irradiance(x: vec3<f32>, nx: vec3<f32>, corners: array<vec4<f32>, 4>) -> f32 {
    let p0 = corners[0].xyz - x;
    let p1 = corners[1].xyz - x;
    let p2 = corners[2].xyz - x;
    let p3 = corners[3].xyz - x;
    let u0 = normalize(p0);
    let u1 = normalize(p1);
    let u2 = normalize(p2);
    let u3 = normalize(p3);
    let d = vec4<f32>(dot(p0, nx), dot(p1, nx), dot(p2, nx), dot(p3, nx));
    var e = ClippedEdges(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    clip_edge(&e, p0, p1, u0, u1, d.x, d.y);
    clip_edge(&e, p1, p2, u1, u2, d.y, d.z);
    clip_edge(&e, p2, p3, u2, u3, d.z, d.w);
    clip_edge(&e, p3, p0, u3, u0, d.w, d.x);
    let crossed = any(d > vec4<f32>(HORIZON_EPS)) && any(d <= vec4<f32>(HORIZON_EPS));
    let sum = e.sum + select(vec3<f32>(0.0), edge_vector(e.exit, e.entry), crossed);
    return 0.5 * abs(dot(nx, sum));
}

// The vector irradiance of the whole quad seen from x, ½ Σ Θᵢ Γᵢ (its sign follows the
// corners' winding; independent of any normal): where the quad lies wholly above x's
// horizon, `polygon_irradiance` is |nx · it|.
fn polygon_vector(x: vec3<f32>, corners: array<vec4<f32>, 4>) -> vec3<f32> {
    let u0 = normalize(corners[0].xyz - x);
    let u1 = normalize(corners[1].xyz - x);
    let u2 = normalize(corners[2].xyz - x);
    let u3 = normalize(corners[3].xyz - x);
    return 0.5 * (edge_vector(u0, u1) + edge_vector(u1, u2) + edge_vector(u2, u3) + edge_vector(u3, u0));
}
