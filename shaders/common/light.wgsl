// The area light: uniform sub-rectangles (cells) with their radiance, and Lambert's closed
// form for the irradiance of a polygon, clipped to the receiver's hemisphere. The GPU twin of
// `light::polygon_irradiance` / `light::unshadowed_irradiance`.

struct LightCell {
    corners: array<vec4<f32>, 4>, // world space, counter-clockwise seen from the lit side
    radiance: vec4<f32>,          // rgb: intensity × colour × alpha
}

// Θ Γ for the edge between unit directions a and b: the angle it subtends times the unit
// normal of the plane through x and the edge (Lambert's edge term; contract §1).
fn edge_vector(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    let c = cross(a, b);
    let len = length(c);
    // atan2 rather than acos: accurate for the tiny angles of distant cells.
    return select(vec3<f32>(0.0), c * (atan2(len, dot(a, b)) / len), len > 1e-12);
}

// An edge a→b of the polygon (relative to x, heights da, db above the receiver's plane)
// clipped to the half-space above it; returns the clipped edge's Θ Γ. `cut` receives the
// crossing point where the edge leaves (xy… in `exit`) or enters (`entry`) that half-space.
struct ClippedEdge {
    sum: vec3<f32>,
    exit: vec3<f32>,
    entry: vec3<f32>,
}

const HORIZON_EPS: f32 = 1e-6;

fn clip_edge(e: ptr<function, ClippedEdge>, a: vec3<f32>, b: vec3<f32>, ua: vec3<f32>, ub: vec3<f32>, da: f32, db: f32) {
    let above_a = da > HORIZON_EPS;
    let above_b = db > HORIZON_EPS;
    if above_a && above_b {
        (*e).sum += edge_vector(ua, ub);
    } else if above_a != above_b {
        let q = normalize(a + (b - a) * ((HORIZON_EPS - da) / (db - da)));
        if above_a {
            (*e).sum += edge_vector(ua, q);
            (*e).exit = q;
        } else {
            (*e).sum += edge_vector(q, ub);
            (*e).entry = q;
        }
    }
}

// Lambert's closed form for one quad seen from x (normal nx): xyz = ½ Σ Θᵢ Γᵢ, the vector
// irradiance of the whole quad (independent of nx; its sign follows the corners' winding),
// and w = ∫ cosθx dω over the quad clipped to the hemisphere above x, ½ |Σ Θᵢ (nx · Γᵢ)|.
// Where the quad lies wholly above x's horizon, w = |nx · xyz|. Written edge by edge,
// without an array of clipped vertices: a convex quad cut by a plane leaves it at most once
// and re-enters at most once, so the clipped polygon is the clipped edges plus one edge
// along the horizon from the exit to the entry point. (A dynamically indexed local array
// costs a memory round trip per lane on lavapipe; this form is about half the time.)
fn polygon_terms(x: vec3<f32>, nx: vec3<f32>, corners: array<vec4<f32>, 4>) -> vec4<f32> {
    let p0 = corners[0].xyz - x;
    let p1 = corners[1].xyz - x;
    let p2 = corners[2].xyz - x;
    let p3 = corners[3].xyz - x;
    let u0 = normalize(p0);
    let u1 = normalize(p1);
    let u2 = normalize(p2);
    let u3 = normalize(p3);
    let whole = 0.5 * (edge_vector(u0, u1) + edge_vector(u1, u2) + edge_vector(u2, u3) + edge_vector(u3, u0));
    let d = vec4<f32>(dot(p0, nx), dot(p1, nx), dot(p2, nx), dot(p3, nx));
    if all(d > vec4<f32>(HORIZON_EPS)) {
        return vec4<f32>(whole, abs(dot(nx, whole)));
    }
    if all(d <= vec4<f32>(HORIZON_EPS)) {
        return vec4<f32>(whole, 0.0);
    }
    var e = ClippedEdge(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    clip_edge(&e, p0, p1, u0, u1, d.x, d.y);
    clip_edge(&e, p1, p2, u1, u2, d.y, d.z);
    clip_edge(&e, p2, p3, u2, u3, d.z, d.w);
    clip_edge(&e, p3, p0, u3, u0, d.w, d.x);
    let sum = e.sum + edge_vector(e.exit, e.entry);
    return vec4<f32>(whole, 0.5 * abs(dot(nx, sum)));
}

// ∫ cosθx dω over the quad seen from x (normal nx), clipped to the upper hemisphere.
fn polygon_irradiance(x: vec3<f32>, nx: vec3<f32>, corners: array<vec4<f32>, 4>) -> f32 {
    return polygon_terms(x, nx, corners).w;
}
