// Method `wedges` (Assarsson & Akenine-Möller 2003 §3–§6): rasterising the work list — each
// workgroup takes one (primitive, tile) pair that survived culling and runs over the tile's
// pixels, reading the pixel's surface point once (the "depth read") and adding to the LI
// buffer (an "LI write") where the primitive touches it. The entry points
// (`rasterize_umbra.wgsl`, `rasterize_penumbra.wgsl`, `rasterize_both.wgsl`) each hold only
// the code their items need: on a CPU rasteriser (lavapipe) the wedge code alone, even never
// taken, makes the umbra loop many times slower. The two contributions:
// - a shadow-volume polygon of the light centre's hard shadow (`rasterizeUmbra`): ∓full for a
//   crossing of the eye ray in front of the point (z-pass) or, with the signs reversed, beyond
//   it (z-fail, §5 — with the volume's caps, correct with the eye inside a shadow);
// - a penumbra wedge (`rasterizePenumbra`): where the silhouette edge, projected from the
//   point onto the light, cuts the light rectangle, the light's share beyond it — per channel
//   of the light image's emission for a coloured light (`colored_share`).
// The single-pass variant (§6.2) gives one item both halves of an edge.

#import methods/wedges/common.wgsl

// `CHANNELS` and `COLOR_ANGLES` as pipeline constants (`methods::wedges` makes a
// pipeline per value): on lavapipe a branch no lane takes still runs its code, so a uniform
// light's passes hold no colour code at all, and the colour loop runs a fixed count.
override CHANNELS: u32 = 1u;
override COLOR_ANGLES: u32 = 8u;
// The tile's side in pixels (`params.tile`) as a pipeline constant: a pixel's place in its
// tile is then a shift and a mask, where a division by a uniform was a scalar division per
// lane on lavapipe, twice per pixel.
override TILE: u32 = 8u;
// Invocations per work item, each taking every LANES-th pixel of the tile. lavapipe runs a
// workgroup as a loop over SIMD groups of 8 lanes, each paying again for what every lane of
// the item shares (its work item, its primitive), so there 8 lanes each take 8 of an 8×8
// tile's pixels (`methods::wedges` sets it). A GPU keeps 64, two warps.
override LANES: u32 = 64u;

fn cross2(a: vec2<f32>, b: vec2<f32>) -> f32 {
    return a.x * b.y - a.y * b.x;
}

// A fixed order of points: lexicographic in x, y, z.
fn before(u: vec3<f32>, w: vec3<f32>) -> bool {
    if u.x != w.x {
        return u.x < w.x;
    }
    if u.y != w.y {
        return u.y < w.y;
    }
    return u.z < w.z;
}

// Which side of the edge u → w the ray from `eye` along `ray` passes: the sign of
// ray · ((u − eye) × (w − eye)), with a fixed owner for an exact 0.
fn edge_side(ray: vec3<f32>, eye: vec3<f32>, u: vec3<f32>, w: vec3<f32>) -> f32 {
    let s = dot(ray, cross(u - eye, w - eye));
    if s == 0.0 {
        // The ray meets the edge's line exactly (a symmetric view does, along whole rows):
        // the edge's owner is the polygon running it in the canonical direction.
        return select(-1.0, 1.0, before(u, w));
    }
    return s;
}

// The signed number of times the eye ray to p crosses `poly` where it counts: in front of p
// (z-pass: entering +, leaving −) or beyond it (z-fail: the reverse), times the multiplicity.
fn volume_crossing(poly: VolumePolygon, eye: vec3<f32>, p: vec3<f32>) -> i32 {
    let ray = p - eye;
    let n = cross(poly.v1.xyz - poly.v0.xyz, poly.v2.xyz - poly.v0.xyz);
    let facing = dot(n, ray);
    if abs(facing) <= 1e-12 * length(n) * length(ray) {
        return 0; // the ray runs along the polygon's plane
    }
    let t = dot(n, poly.v0.xyz - eye) / facing;
    // Where p lies on the polygon, it counts as outside. That only needs a tolerance for caps:
    // a top cap is the caster's own lit surface, which z-fail must count at p (the ray enters
    // there and leaves through the bottom cap). A side quad is compared with p exactly: a ray
    // grazing a caster can leave its volume through a quad just in front of p, and a
    // tolerance would drop that exit and shadow a lit point.
    let cap = all(poly.v3.xyz == poly.v2.xyz);
    let at_p = select(1.0, 1.0 - 1e-4, cap);
    if (params.zfail == 0u && (t <= 0.0 || t >= at_p)) || (params.zfail == 1u && t < at_p) {
        return 0;
    }
    // Whether the ray passes through the polygon: on the same side of every edge, by the sign
    // of ray · ((u − eye) × (v − eye)). Two polygons sharing an edge run it in opposite
    // directions, which negates that product exactly, so a ray through a shared edge (the
    // corner ray of a volume) is counted by exactly one of them — testing the hit point
    // against each polygon's own edges would count it by both or neither.
    let s0 = edge_side(ray, eye, poly.v0.xyz, poly.v1.xyz);
    let s1 = edge_side(ray, eye, poly.v1.xyz, poly.v2.xyz);
    let s2 = edge_side(ray, eye, poly.v2.xyz, poly.v3.xyz);
    let s3 = edge_side(ray, eye, poly.v3.xyz, poly.v0.xyz);
    let sides = vec4<f32>(s0, s1, s2, s3);
    // A triangle's repeated vertex makes a null edge, on both sides at once.
    let null_edge = vec4<bool>(false, false, cap, false);
    let positive = all((sides > vec4<f32>(0.0)) | null_edge);
    let negative = all((sides < vec4<f32>(0.0)) | null_edge);
    if !(positive || negative) {
        return 0;
    }
    let entering = facing < 0.0;
    let m = i32(poly.v0.w);
    return select(m, -m, entering == (params.zfail == 1u));
}

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


// The item this workgroup runs, and the first pixel of its tile; counts the tile's on-screen
// pixels as depth reads once per item (an atomic per pixel would cost more than the test).
struct TileItem {
    job: WorkItem,
    origin: vec2<u32>,
    valid: bool,
}

// The work item of a workgroup: items go in rows of `groups.x` workgroups, as even as the
// grid allows (`item_grid` in `wedges/mod.rs`), so that few workgroups past the list's end are
// launched — on lavapipe one that returns at once still pays for most of its code.
fn item_index(group: vec3<u32>, groups: vec3<u32>) -> u32 {
    return group.y * groups.x + group.x;
}

// A work item's tile's first pixel, from its packed `origin`.
fn tile_origin(origin: u32) -> vec2<u32> {
    return vec2<u32>(origin & 0xffffu, origin >> 16u);
}

fn tile_item(group: vec3<u32>, groups: vec3<u32>, local: u32) -> TileItem {
    var item: TileItem;
    let index = item_index(group, groups);
    item.valid = index < arrayLength(&work);
    if !item.valid {
        return item;
    }
    item.job = work[index];
    item.origin = tile_origin(item.job.origin);
    if local == 0u {
        let span = min(item.origin + TILE, frame.sizes.xy) - item.origin;
        atomicAdd(&counters[0], span.x * span.y);
    }
    return item;
}

// The k-th pixel of a tile: its index into per-pixel buffers and its receiver record (the
// surface point; w, the object it ignores), loaded once for every test of the pixel. Not
// valid off screen or on the background.
struct TilePixel {
    at: u32,
    receiver: vec4<f32>,
    valid: bool,
}

fn tile_pixel(origin: vec2<u32>, k: u32) -> TilePixel {
    let pixel = tile_pixel_at(origin, k);
    var px: TilePixel;
    if any(pixel >= frame.sizes.xy) {
        return px;
    }
    px.at = pixel_index(pixel);
    px.receiver = receivers[2u * px.at];
    px.valid = px.receiver.w != NOT_COVERED;
    return px;
}

// The k-th pixel of the tile whose first pixel is `origin`.
fn tile_pixel_at(origin: vec2<u32>, k: u32) -> vec2<u32> {
    return origin + vec2<u32>(k % TILE, k / TILE);
}

fn add_light(at: u32, delta: vec3<i32>) {
    if any(delta != vec3<i32>(0)) {
        for (var k = 0u; k < CHANNELS; k++) {
            atomicAdd(&li[at * CHANNELS + k], delta[k]);
        }
        atomicAdd(&counters[1], 1u);
    }
}

// The primitives are loaded once per work item, before the loop over its tile's pixels, and
// passed by value: on lavapipe a storage load inside the loop is a gather, lane by lane, on
// every pass through it, though every lane reads the same primitive.

// The umbra term at a receiver for a volume polygon.
fn umbra_delta(poly: VolumePolygon, receiver: vec4<f32>) -> i32 {
    if poly.v1.w == receiver.w {
        return 0; // its own object, facing away from the light centre
    }
    return -params.full * volume_crossing(poly, frame.eye.xyz, receiver.xyz);
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
