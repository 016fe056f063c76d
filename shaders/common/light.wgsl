// The area light: uniform sub-rectangles (cells) with their radiance, and Lambert's closed
// form for the irradiance of a polygon, clipped to the receiver's hemisphere. The GPU twin of
// `light::polygon_irradiance` / `light::unshadowed_irradiance`.

struct LightCell {
    corners: array<vec4<f32>, 4>, // world space, counter-clockwise seen from the lit side
    radiance: vec4<f32>,          // rgb: intensity × colour × alpha
}

// ∫ cosθx dω over the polygon seen from x (normal nx), clipped to the upper hemisphere:
// ½ Σ Θᵢ (nx · Γᵢ), with Θᵢ the angle subtended by edge i and Γᵢ its unit edge-plane normal.
fn polygon_irradiance(x: vec3<f32>, nx: vec3<f32>, corners: array<vec4<f32>, 4>) -> f32 {
    let eps = 1e-6;
    var clipped: array<vec3<f32>, 5>;
    var count = 0u;
    for (var k = 0u; k < 4u; k++) {
        let a = corners[k].xyz - x;
        let b = corners[(k + 1u) % 4u].xyz - x;
        let da = dot(a, nx);
        let db = dot(b, nx);
        if da > eps {
            clipped[count] = a;
            count++;
        }
        if (da > eps) != (db > eps) {
            clipped[count] = a + (b - a) * ((eps - da) / (db - da));
            count++;
        }
    }
    if count < 3u {
        return 0.0;
    }
    var sum = 0.0;
    for (var k = 0u; k < count; k++) {
        let a = normalize(clipped[k]);
        let b = normalize(clipped[(k + 1u) % count]);
        let c = cross(a, b);
        let len = length(c);
        if len > 1e-12 {
            // atan2 rather than acos: accurate for the tiny angles of distant cells.
            sum += atan2(len, dot(a, b)) * dot(nx, c / len);
        }
    }
    return 0.5 * abs(sum);
}
