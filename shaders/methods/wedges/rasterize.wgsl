// Method `wedges` (Assarsson & Akenine-Möller 2003 §3–§6): rasterise the work list — each
// workgroup takes one (primitive, tile) pair that survived culling and runs over the tile's
// pixels, reading the pixel's surface point once (the "depth read") and adding to the LI
// buffer (an "LI write") where the primitive touches it:
// - a shadow-volume polygon of the light centre's hard shadow (`rasterizeUmbra`): ∓full for a
//   crossing of the eye ray in front of the point (z-pass) or, with the signs reversed, beyond
//   it (z-fail, §5 — with the volume's caps, correct with the eye inside a shadow);
// - a penumbra wedge (`rasterizePenumbra`): where the silhouette edge, projected from the
//   point onto the light, cuts the light rectangle, the light's share beyond it.
// The single-pass variant (§6.2) gives one item both halves of an edge.

#import methods/wedges/common.wgsl

fn cross2(a: vec2<f32>, b: vec2<f32>) -> f32 {
    return a.x * b.y - a.y * b.x;
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
    // A point on the volume's boundary (a lit cap is the caster's own surface) counts as
    // outside: z-pass ignores crossings at p, z-fail counts them.
    let near_p = 1.0 - 1e-4;
    if (params.zfail == 0u && (t <= 0.0 || t >= near_p)) || (params.zfail == 1u && t < near_p) {
        return 0;
    }
    let x = eye + t * ray;
    let v = array<vec3<f32>, 4>(poly.v0.xyz, poly.v1.xyz, poly.v2.xyz, poly.v3.xyz);
    for (var k = 0u; k < 4u; k++) {
        if dot(cross(v[(k + 1u) % 4u] - v[k], x - v[k]), n) < 0.0 {
            return 0;
        }
    }
    let entering = facing < 0.0;
    let m = i32(poly.v0.w);
    return select(m, -m, entering == (params.zfail == 1u));
}

// Clips the convex polygon `poly` (count vertices) to the half-plane dot(normal, x) + offset ≥ 0.
fn clip(poly: ptr<function, array<vec2<f32>, 8>>, count: u32, normal: vec2<f32>, offset: f32) -> u32 {
    var out: array<vec2<f32>, 8>;
    var n = 0u;
    for (var k = 0u; k < count; k++) {
        let a = (*poly)[k];
        let b = (*poly)[(k + 1u) % count];
        let da = dot(normal, a) + offset;
        let db = dot(normal, b) + offset;
        if da >= 0.0 {
            out[n] = a;
            n++;
        }
        if (da >= 0.0) != (db >= 0.0) && n < 8u {
            out[n] = a + (b - a) * (da / (da - db));
            n++;
        }
    }
    *poly = out;
    return n;
}

// The penumbra wedge's contribution at p (§3's light intensity, computed exactly for a
// rectangle): project the silhouette edge from p onto the light plane (c' at the origin); a
// light point x is hidden by one more layer than c' for each projected edge that the segment
// c'x crosses inwards, so the light beyond this edge inside its angular sector from c' —
// clipped to the rectangle — is this edge's share, added where c' is outside the projected
// occluder (outer penumbra) and removed where it is inside (inner). Returns that share as a
// signed fraction of the light, times the multiplicity; 0 outside the wedge.
fn wedge_share(w: Wedge, p: vec3<f32>) -> f32 {
    let c = frame.light_center.xyz;
    let n = frame.light_n.xyz;
    let half = 0.5 * vec2<f32>(frame.light_n.w, frame.light_u.w);
    let hp = dot(p - c, n);
    var a = w.a.xyz;
    var b = w.b.xyz;
    var ha = dot(a - c, n);
    var hb = dot(b - c, n);
    // Only the part of the edge between the light and p can hide the light from p.
    let limit = hp * (1.0 - 1e-4);
    if (ha >= limit && hb >= limit) || min(ha, hb) <= 0.0 {
        return 0.0;
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
    let a2 = vec2<f32>(dot(qa - c, frame.light_r.xyz), dot(qa - c, frame.light_u.xyz));
    let b2 = vec2<f32>(dot(qb - c, frame.light_r.xyz), dot(qb - c, frame.light_u.xyz));
    // The share is empty unless the projected edge meets the rectangle (which is convex and
    // holds c'); a bounding-box test rejects most misses.
    if max(a2.x, b2.x) < -half.x || min(a2.x, b2.x) > half.x || max(a2.y, b2.y) < -half.y || min(a2.y, b2.y) > half.y {
        return 0.0;
    }
    let d = b2 - a2;
    let side = cross2(d, -a2); // > 0: c' on the left of a' → b'
    if abs(side) <= 1e-9 * (dot(d, d) + dot(a2, a2)) {
        return 0.0; // the edge passes through c': its sector is empty
    }
    var poly = array<vec2<f32>, 8>(-half, vec2<f32>(half.x, -half.y), half, vec2<f32>(-half.x, half.y), vec2<f32>(0.0), vec2<f32>(0.0), vec2<f32>(0.0), vec2<f32>(0.0));
    var count = 4u;
    // Beyond the edge's line, on the side away from c'.
    let beyond = -sign(side) * vec2<f32>(-d.y, d.x);
    count = clip(&poly, count, beyond, -dot(beyond, a2));
    // Inside the angular sector from c': on b's side of the line c'a', on a's side of c'b'.
    let s = sign(cross2(a2, b2));
    count = clip(&poly, count, s * vec2<f32>(-a2.y, a2.x), 0.0);
    count = clip(&poly, count, -s * vec2<f32>(-b2.y, b2.x), 0.0);
    var area = 0.0;
    for (var k = 0u; k < count; k++) {
        area += cross2(poly[k], poly[(k + 1u) % count]);
    }
    return sign(side) * w.a.w * 0.5 * abs(area) / (4.0 * half.x * half.y);
}

var<workgroup> item: WorkItem;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let index = group.y * 65535u + group.x;
    if index >= arrayLength(&work) {
        return;
    }
    let job = work[index];
    let tiles = tile_grid();
    let origin = vec2<u32>(job.tile % tiles.x, job.tile / tiles.x) * params.tile;
    let eye = frame.eye.xyz;
    let full = f32(params.full);
    for (var k = local; k < params.tile * params.tile; k += 64u) {
        let pixel = origin + vec2<u32>(k % params.tile, k / params.tile);
        if any(pixel >= frame.sizes.xy) {
            continue;
        }
        atomicAdd(&counters[0], 1u);
        if !covered(pixel) {
            continue;
        }
        let p = textureLoad(gbuf_position, pixel, 0).xyz;
        var delta = 0;
        if job.primitive < params.polygon_count {
            delta -= params.full * volume_crossing(polygons[job.primitive], eye, p);
        }
        let wedge = select(job.both, job.primitive - params.polygon_count + 1u, job.primitive >= params.polygon_count);
        if wedge > 0u {
            delta -= i32(round(full * wedge_share(wedges[wedge - 1u], p)));
        }
        if delta != 0 {
            atomicAdd(&li[pixel.y * frame.sizes.x + pixel.x], delta);
            atomicAdd(&counters[1], 1u);
        }
    }
}
