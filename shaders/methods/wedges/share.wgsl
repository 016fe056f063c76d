// Method `wedges` (Assarsson & Akenine-Möller 2003 §3): a wedge's share of the light at a
// receiver inside it — the light beyond the silhouette edge projected from the receiver onto
// the light, within the edge's angular sector from the centre: exact for the rectangle
// (Lambert's formula over the clipped polygon) and, for a coloured light, per channel from
// the sector table (`colored_share`). Imported by the penumbra passes with `rasterize.wgsl`.

// The share's polygons (up to 8 light-plane points) live in registers: every access to a
// vertex is at an index fixed when the shader is built — the clip's loop unrolled, a vertex at
// a lane-varying index picked by a chain of selects (`polygon_vertex`), one written by a
// select per slot (`put_vertex`). Indexed by lane-varying counts they lived in function
// memory, where on lavapipe each access is a gather or a scatter lane by lane.

// Vertex k of `poly`.
fn polygon_vertex(poly: ptr<function, array<vec2<f32>, 8>>, k: u32) -> vec2<f32> {
    var v = (*poly)[0];
    #unroll i in 1..8 {
        v = select(v, (*poly)[i], k == i);
    }
    return v;
}

// Writes v as vertex k of `poly` where `write`.
fn put_vertex(poly: ptr<function, array<vec2<f32>, 8>>, k: u32, v: vec2<f32>, write: bool) {
    #unroll i in 0..8 {
        (*poly)[i] = select((*poly)[i], v, write && k == i);
    }
}

// Clips the convex polygon `src` (count vertices) to the half-plane dot(normal, x) + offset ≥ 0,
// into `dst`; returns its vertex count. Each vertex is read once (an edge's end is the next
// edge's start), and the clips alternate between two arrays instead of copying the result.
fn clip(src: ptr<function, array<vec2<f32>, 8>>, dst: ptr<function, array<vec2<f32>, 8>>, count: u32, normal: vec2<f32>, offset: f32) -> u32 {
    var n = 0u;
    let first = (*src)[0];
    var a = first;
    var da = dot(normal, a) + offset;
    #unroll k in 0..8 {
        // The edge from vertex k to the next (the first, after the last).
        let b = select((*src)[min(k + 1u, 7u)], first, k + 1u >= count);
        let db = dot(normal, b) + offset;
        let edge = k < count;
        let keep = edge && da >= 0.0;
        put_vertex(dst, n, a, keep);
        n += select(0u, 1u, keep);
        let crosses = edge && (da >= 0.0) != (db >= 0.0) && n < 8u;
        put_vertex(dst, n, a + (b - a) * (da / (da - db)), crosses);
        n += select(0u, 1u, crosses);
        a = b;
        da = db;
    }
    return n;
}

// Irradiance (up to a constant) at p with normal `normal` from the polygon of light-plane
// points `poly` (light coordinates), by Lambert's formula ½ Σ Θₖ (n · Γₖ) — the weight the
// reference and E0 give each part of the light (cosines and distance), so shares of it are
// fractions of what p receives, not of the light's area.
// Each vertex's direction is normalised once: an edge's end is the next edge's start.
fn light_polygon_irradiance(poly: ptr<function, array<vec2<f32>, 8>>, count: u32, p: vec3<f32>, normal: vec3<f32>) -> f32 {
    let first = normalize(light_point((*poly)[0]) - p);
    var a = first;
    var sum = 0.0;
    for (var k = 0u; k < count; k++) {
        var b = first;
        if k + 1u < count {
            b = normalize(light_point(polygon_vertex(poly, k + 1u)) - p);
        }
        sum += dot(normal, edge_vector(a, b));
        a = b;
    }
    return 0.5 * abs(sum);
}

// The same for the whole light rectangle, its corners held in registers.
fn light_rectangle_irradiance(half: vec2<f32>, p: vec3<f32>, normal: vec3<f32>) -> f32 {
    let c0 = normalize(light_point(-half) - p);
    let c1 = normalize(light_point(vec2<f32>(half.x, -half.y)) - p);
    let c2 = normalize(light_point(half) - p);
    let c3 = normalize(light_point(vec2<f32>(-half.x, half.y)) - p);
    var sum = 0.0;
    sum += dot(normal, edge_vector(c0, c1));
    sum += dot(normal, edge_vector(c1, c2));
    sum += dot(normal, edge_vector(c2, c3));
    sum += dot(normal, edge_vector(c3, c0));
    return 0.5 * abs(sum);
}

fn light_point(x: vec2<f32>) -> vec3<f32> {
    return frame.light_center.xyz + x.x * frame.light_r.xyz + x.y * frame.light_u.xyz;
}

// The silhouette edge projected from p onto the light plane (light coordinates, c' at the
// origin), and `side` > 0 where c' lies on the left of a' → b'. `crosses` is false where the
// edge's share at p is certainly empty: no part of it lies between the light and p, the
// projected edge misses the rectangle's bounding box, or it passes through c' (an empty
// sector).
struct ProjectedEdge {
    a2: vec2<f32>,
    b2: vec2<f32>,
    side: f32,
    crosses: bool,
}

fn projected_edge(w: WedgeEdge, p: vec3<f32>) -> ProjectedEdge {
    var edge: ProjectedEdge;
    let c = frame.light_center.xyz;
    let n = frame.light_n.xyz;
    let hp = dot(p - c, n);
    var a = w.a.xyz;
    var b = w.b.xyz;
    var ha = dot(a - c, n);
    var hb = dot(b - c, n);
    // Only the part of the edge between the light and p can hide the light from p.
    let limit = hp * (1.0 - 1e-4);
    if (ha >= limit && hb >= limit) || min(ha, hb) <= 0.0 {
        return edge;
    }
    if ha >= limit {
        a = a + (b - a) * ((ha - limit) / (ha - hb));
        ha = limit;
    }
    if hb >= limit {
        b = b + (a - b) * ((hb - limit) / (hb - ha));
        hb = limit;
    }
    let qa = p + (a - p) * (hp / (hp - ha));
    let qb = p + (b - p) * (hp / (hp - hb));
    edge.a2 = vec2<f32>(dot(qa - c, frame.light_r.xyz), dot(qa - c, frame.light_u.xyz));
    edge.b2 = vec2<f32>(dot(qb - c, frame.light_r.xyz), dot(qb - c, frame.light_u.xyz));
    let a2 = edge.a2;
    let b2 = edge.b2;
    // The share hides no emission unless the projected edge meets the emitting octagon (which
    // is convex and holds c': the light beyond the edge lies on segments from c' across it);
    // a test along the octagon's four axes rejects most misses. Under a flame-shaped light
    // two in three wedge pixels on `terrain` hid only its black corners.
    let pa = vec4<f32>(a2, a2.x + a2.y, a2.x - a2.y);
    let pb = vec4<f32>(b2, b2.x + b2.y, b2.x - b2.y);
    if any(max(pa, pb) < params.emitting_lo) || any(min(pa, pb) > params.emitting_hi) {
        return edge;
    }
    let d = b2 - a2;
    edge.side = cross2(d, -a2);
    // The edge passes through c': its sector is empty.
    edge.crosses = abs(edge.side) > 1e-9 * (dot(d, d) + dot(a2, a2));
    return edge;
}

// The penumbra wedge's contribution at p (§3's light intensity, computed exactly for a
// rectangle): project the silhouette edge from p onto the light plane (c' at the origin); a
// light point x is hidden by one more layer than c' for each projected edge that the segment
// c'x crosses inwards, so the light beyond this edge inside its angular sector from c' —
// clipped to the rectangle — is this edge's share, added where c' is outside the projected
// occluder (outer penumbra) and removed where it is inside (inner). Returns that share as a
// signed fraction of the irradiance the whole light gives p, times the multiplicity; 0
// outside the wedge. Per channel (`colored_share`) for a coloured light, where `e0` is p's
// unshadowed irradiance.
fn wedge_share(w: WedgeEdge, p: vec3<f32>, normal: vec3<f32>, e0: vec3<f32>) -> vec3<f32> {
    let edge = projected_edge(w, p);
    if !edge.crosses {
        return vec3<f32>(0.0);
    }
    let half = 0.5 * vec2<f32>(frame.light_n.w, frame.light_u.w);
    let a2 = edge.a2;
    let b2 = edge.b2;
    let d = b2 - a2;
    let side = edge.side;
    var rect = array<vec2<f32>, 8>(-half, vec2<f32>(half.x, -half.y), half, vec2<f32>(-half.x, half.y), vec2<f32>(0.0), vec2<f32>(0.0), vec2<f32>(0.0), vec2<f32>(0.0));
    var poly: array<vec2<f32>, 8>;
    // Beyond the edge's line, on the side away from c'.
    let beyond = -sign(side) * vec2<f32>(-d.y, d.x);
    var count = clip(&rect, &poly, 4u, beyond, -dot(beyond, a2));
    // Inside the angular sector from c': on b's side of the line c'a', on a's side of c'b'.
    let s = sign(cross2(a2, b2));
    count = clip(&poly, &rect, count, s * vec2<f32>(-a2.y, a2.x), 0.0);
    count = clip(&rect, &poly, count, -s * vec2<f32>(-b2.y, b2.x), 0.0);
    if count < 3u {
        return vec3<f32>(0.0);
    }
    var whole = 0.0;
    let below_horizon = dot(light_point(-half) - p, normal) <= 0.0 || dot(light_point(vec2<f32>(half.x, -half.y)) - p, normal) <= 0.0
        || dot(light_point(half) - p, normal) <= 0.0 || dot(light_point(vec2<f32>(-half.x, half.y)) - p, normal) <= 0.0;
    var part = 0.0;
    if below_horizon {
        // Part of the light lies below p's horizon, where Lambert's formula would need
        // clipping: weigh by area instead (E0 carries the exact horizon).
        // Each vertex read once: an edge's end is the next edge's start.
        let first = poly[0];
        var a = first;
        for (var k = 1u; k <= count; k++) {
            let b = select(polygon_vertex(&poly, k), first, k == count);
            part += 0.5 * cross2(a, b);
            a = b;
        }
        part = abs(part);
        whole = 4.0 * half.x * half.y;
    } else {
        part = light_polygon_irradiance(&poly, count, p, normal);
        if CHANNELS == 1u {
            whole = light_rectangle_irradiance(half, p, normal);
        }
    }
    let weight = sign(side) * w.a.w;
    if CHANNELS == 1u {
        return vec3<f32>(weight * part / max(whole, 1e-30));
    }
    return weight * colored_share(&poly, count, a2, d, p, normal, part, below_horizon, e0);
}

// A coloured light's share of the region `poly` (light coordinates, c' at the origin, beyond
// the line through `a2` along `d`), per channel: the blocked irradiance over E0 (contract §1:
// V per channel). Lambert's formula gives the region's irradiance at unit radiance exactly
// (`part`); what the image adds is the region's mean radiance, weighed as p weighs it
// (cosines over squared distance). The region is bounded by rays from the centre, the edge's
// line and the rectangle, so it is the sector between its extreme directions minus what lies
// on c's side of the line. Its angular span is cut into steps (`color_angles` at most); in each, the
// line's distance is held at its value in the middle of the step and the sector table gives
// the emission and the area between it and the rectangle's edge (two look-ups: the table
// holds what lies beyond each distance) — the image's colour
// boundaries, whatever their direction, are integrated exactly, only the line's drift within
// a step is approximated — and the kernel at the step's middle weighs them. The mean comes
// from these pieces, so their error only bends the hue: a uniform light gets back exactly
// Lambert's share. Below the horizon (area weights, see `wedge_share`) the share is the
// region's emission over the whole light's.
fn colored_share(poly: ptr<function, array<vec2<f32>, 8>>, count: u32, a2: vec2<f32>, d: vec2<f32>, p: vec3<f32>, normal: vec3<f32>, part: f32, below_horizon: bool, e0: vec3<f32>) -> vec3<f32> {
    // The region's angular span seen from c' (< π: the region lies beyond a line that misses
    // c'), measured from the direction of its vertices' mean.
    var g = vec2<f32>(0.0);
    #unroll k in 0..8 {
        g += select(vec2<f32>(0.0), (*poly)[k], k < count);
    }
    g = normalize(g);
    var lo = 0.0;
    var hi = 0.0;
    for (var k = 0u; k < count; k++) {
        let v = polygon_vertex(poly, k);
        let rel = atan2(cross2(g, v), dot(g, v));
        lo = min(lo, rel);
        hi = max(hi, rel);
    }
    // The first direction within the table's first turn; the span then stays in its two.
    let start = fract((atan2(g.y, g.x) + lo) / TAU) * TAU;
    // `color_angles` steps across a region an eighth of a turn wide or wider; a narrower one
    // takes steps as wide as such a region's, but at least two. A short silhouette edge (a
    // landscape's) cuts a narrow region, where the line hardly drifts within a step (errors
    // within 2e-6 of a fixed count's).
    let steps = clamp(u32(ceil(4.0 * f32(COLOR_ANGLES) * (hi - lo) / PI)), min(2u, COLOR_ANGLES), COLOR_ANGLES);
    let width = (hi - lo) / f32(steps);
    let line_normal = vec2<f32>(-d.y, d.x);
    let line_offset = dot(line_normal, a2);
    let n_light = frame.light_n.xyz;
    var emitted = vec3<f32>(0.0);
    var area = 0.0;
    for (var j = 0u; j < steps; j++) {
        let phi_a = start + width * f32(j);
        let phi_b = phi_a + width;
        let mid = phi_a + 0.5 * width;
        let e = vec2<f32>(cos(mid), sin(mid));
        let reach = light_reach(e);
        // Where this step's middle ray crosses the edge's line into the region (never, if it
        // runs away from it).
        let along = dot(line_normal, e);
        var enter = reach;
        if along * line_offset > 0.0 {
            enter = clamp(line_offset / along, 0.0, reach);
        }
        let s = enter / reach;
        let piece = sector(phi_b, s) - sector(phi_a, s);
        var kernel = 1.0;
        if !below_horizon {
            let to_light = light_point(e * 0.5 * (enter + reach)) - p;
            let r2 = dot(to_light, to_light);
            kernel = max(dot(normal, to_light), 0.0) * max(-dot(n_light, to_light), 0.0) / (r2 * r2);
        }
        emitted += kernel * max(piece.rgb, vec3<f32>(0.0));
        area += kernel * max(piece.w, 0.0);
    }
    if area <= 0.0 {
        return vec3<f32>(0.0);
    }
    let mean_radiance = emitted / area; // the image's emission per m² of light
    if below_horizon {
        // `part` is the region's area here (`wedge_share`).
        let whole = sector(TAU, 0.0).rgb;
        return part * mean_radiance / max(whole, vec3<f32>(1e-30));
    }
    let blocked = part * frame.light_center.w * mean_radiance;
    return select(vec3<f32>(0.0), blocked / e0, e0 > vec3<f32>(0.0));
}

const TAU: f32 = 6.28318531;

// The sector table (`light::tables::sector_table`) at angle `phi` ∈ [0, 4π) and radial
// fraction `s`, linear between its rows and stations: rgb the emission beyond s, w the area.
fn sector(phi: f32, s: f32) -> vec4<f32> {
    let rows = 2u * params.sector_angles;
    let y = clamp(phi / TAU * f32(params.sector_angles), 0.0, f32(rows));
    let i = min(u32(y), rows - 1u);
    let x = clamp(s, 0.0, 1.0) * f32(params.sector_stations - 1u);
    let j = min(u32(x), params.sector_stations - 2u);
    let at = i * params.sector_stations + j;
    let below = mix(sectors[at], sectors[at + 1u], x - f32(j));
    let above = mix(sectors[at + params.sector_stations], sectors[at + params.sector_stations + 1u], x - f32(j));
    return mix(below, above, y - f32(i));
}

// §3: "if p is inside the wedge" — its plane equations, and not the wedge's own object.
fn inside_wedge(w: Wedge, receiver: vec4<f32>) -> bool {
    let p = vec4<f32>(receiver.xyz, 1.0);
    return w.edge.b.w != receiver.w && dot(w.front, p) >= 0.0 && dot(w.back, p) >= 0.0;
}

// The penumbra term at a receiver (pixel `at`) for a wedge.
fn penumbra_delta(w: Wedge, px: TilePixel) -> vec3<i32> {
    if !inside_wedge(w, px.receiver) {
        return vec3<i32>(0);
    }
    return penumbra_delta_inside(w.edge, px.at);
}

// `penumbra_delta` for a receiver known to lie inside the wedge (listed by `mark_inside`).
fn penumbra_delta_inside(w: WedgeEdge, at: u32) -> vec3<i32> {
    var e0 = vec3<f32>(1.0);
    if CHANNELS == 3u {
        e0 = e0_in[at].rgb;
    }
    let share = wedge_share(w, receivers[2u * at].xyz, receivers[2u * at + 1u].xyz, e0);
    return -vec3<i32>(round(f32(params.full) * share));
}
