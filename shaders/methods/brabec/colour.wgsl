// Method `brabec`, past the paper: the colour of a penumbra pixel (contract §1). The search
// notes the occluder's edge as a line across the light (`edge_line`); the light's edge table
// gives each channel's share beyond it, and the paper's gray level takes that hue.

// The occluder's edge as a line across the light, seen from p: xy its unit normal pointing
// away from the occluder, z its signed distance from the centre along it. The occluder point
// next to the silhouette is the blocker found (outer penumbra), or the occluder texel next to
// the lit one found, one step back towards p's own (inner). The ray from p through it meets
// the light plane at q, on the edge's line; the line's direction is the silhouette's at that
// point (`silhouette_normal`), or else orthogonal to the direction the search found its texel
// in (`light_direction`). Where the ray fails (the point is not between p and the light), the
// penumbra coordinate f places the line: at f of the light's extent that way.
fn edge_line(p: vec3<f32>, w: Warped, found: vec2<i32>, f: f32) -> vec3<f32> {
    let toward = light_direction(p, w.depth, found);
    if dot(toward, toward) <= 0.0 {
        return vec3<f32>(0.0);
    }
    let e = normalize(toward);
    var texel = found;
    if w.hard {
        let back = w.texel - (vec2<f32>(found) + 0.5);
        let step = select(vec2<i32>(sign(back)), vec2<i32>(0), abs(back) < vec2<f32>(0.5 * max(abs(back.x), abs(back.y))));
        texel = clamp(found + step, vec2<i32>(0), vec2<i32>(i32(frame.sizes.z) - 1));
    }
    let occluder = shadow_point(texel).xyz;
    // The blocker lies towards e (outer), the lit surface towards e (inner): the occluder
    // faces away along −e, respectively +e.
    var normal = select(-e, e, w.hard);
    let silhouette = silhouette_normal(occluder, 2, SILHOUETTE_RELATIVE);
    if dot(silhouette, silhouette) > 0.0 {
        normal = silhouette;
    }
    let q = light_plane_hit(p, occluder);
    if q.z == 0.0 {
        return vec3<f32>(normal, select(-1.0, 1.0, w.hard) * f * light_reach(normal));
    }
    return vec3<f32>(normal, dot(q.xy, normal));
}

// The direction on the light plane, seen from receiver p (light depth `depth`), of what the
// shadow map holds at `texel`: its point's offset from the ray c→p at its own depth. A point
// beside that ray projects from p onto the light on the same side of c, so this is the side
// of the light the blocker hides (outer penumbra) or the lit surface sees (inner).
fn light_direction(p: vec3<f32>, depth: f32, texel: vec2<i32>) -> vec2<f32> {
    let c = frame.light_center.xyz;
    let point = shadow_point(texel).xyz;
    let on_ray = c + (p - c) * (dot(point - c, frame.light_n.xyz) / max(depth, 1e-6));
    let offset = point - on_ray;
    return vec2<f32>(dot(offset, frame.light_r.xyz), dot(offset, frame.light_u.xyz));
}

// Per-channel visibility of a pixel from its level v, penumbra coordinate t and the
// occluder edge's line its search found (`edge_line`). Brabec & Seidel's search finds how far
// the hard edge is, not which part of the light is hidden; the line says which (contract §1:
// V per channel): the edge table gives each channel's share of the light beyond it, away
// from the occluder. Only the hue is taken from it (`with_hue`): a uniform light keeps the
// paper's fall-off exactly.
fn colored_visibility(v: f32, t: f32, normal: vec2<f32>, edge: f32) -> vec3<f32> {
    if params.colored == 0u || dot(normal, normal) <= 0.0 || t <= 0.0 || t >= 1.0 {
        return vec3<f32>(v);
    }
    return with_hue(v, fraction_beyond(normalize(normal), edge));
}
