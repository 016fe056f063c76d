//! The regions a primitive of `wedges` can change (§4, made exact): for a volume polygon the
//! receivers whose eye ray crosses it where the count looks, for a wedge the points from which
//! its edge hides some of the light; and each one's part no deeper than any receiver lies.

use glam::{Vec3, Vec4};

use crate::light::AreaLight;
use crate::methods::wedges::geometry::light_corners;
use crate::scene::adjacency::SilhouetteEdge;

/// The planes (world space, inside ≥ 0) of the receivers whose eye ray crosses the volume
/// polygon where the count looks (`volume_crossing` in `rasterize.wgsl`): the polygon's cone
/// from the eye — a plane through the eye and each edge — beyond the polygon's plane (z-pass:
/// the crossing lies in front of the receiver) or on the eye's side of it (z-fail: beyond the
/// receiver). Empty where the eye lies in the polygon's plane (the ray runs along it).
pub(super) fn crossing_region(polygon: &[Vec3; 4], eye: Vec3, zfail: bool) -> Vec<Vec4> {
    let n = (polygon[1] - polygon[0]).cross(polygon[2] - polygon[0]);
    let eye_side = n.dot(eye - polygon[0]);
    let scale = polygon.iter().map(|v| (*v - eye).length()).fold(0.0f32, f32::max);
    if n.length() <= 1e-12 * scale * scale || eye_side.abs() <= 1e-6 * n.length() * scale {
        return Vec::new();
    }
    let centroid = polygon.iter().copied().sum::<Vec3>() / 4.0;
    let mut planes = Vec::with_capacity(5);
    for k in 0..4 {
        let (u, w) = (polygon[k], polygon[(k + 1) % 4]);
        let m = (u - eye).cross(w - eye);
        if u == w || m.length() <= 1e-12 * scale * scale {
            continue; // a cap triangle's repeated vertex, or an edge in line with the eye
        }
        let m = if m.dot(centroid - eye) >= 0.0 { m } else { -m };
        planes.push(m.extend(-m.dot(eye)));
    }
    // z-pass: the receiver on the far side of the plane from the eye; z-fail: on the eye's.
    let toward_receiver = if (eye_side > 0.0) == zfail { n } else { -n };
    planes.push(toward_receiver.extend(-toward_receiver.dot(polygon[0])));
    planes
}

/// The part of a volume polygon where an eye ray can cross it where the count looks. For
/// z-pass the crossing lies on the segment from the eye to a receiver, so no deeper below the
/// light's plane than the deeper of the two — the eye, or at most `deepest`, the scene's
/// deepest point: the polygon is cut there (Sutherland–Hodgman against one plane; empty where
/// all of it lies deeper). For z-fail the crossing lies beyond the receiver: the whole polygon.
pub(super) fn crossing_part(polygon: &[Vec3; 4], light: &AreaLight, eye: Vec3, deepest: f32, zfail: bool) -> Vec<Vec3> {
    if zfail {
        return polygon.to_vec();
    }
    let limit = deepest.max(light.depth(eye));
    let mut part = Vec::with_capacity(5);
    for k in 0..4 {
        let (p, q) = (polygon[k], polygon[(k + 1) % 4]);
        let (dp, dq) = (limit - light.depth(p), limit - light.depth(q));
        if dp >= 0.0 {
            part.push(p);
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            part.push(p + (q - p) * (dp / (dp - dq)));
        }
    }
    part
}

/// Where a silhouette edge's wedge can change a receiver: the points from which some point of
/// the edge a → b hides some point of the light, `p = e + s(e − y)` with `s ≥ 0`. That set lies
/// in `conv{a, b} + cone{a − y, b − y}` over the light's corners y (`y` is a mean of corners, `e`
/// of a and b); its planes are those spanned by two of the generators (the edge and the
/// eight directions) that hold every direction and both ends. Returns points whose hull holds
/// the region out to `reach` from the edge and no deeper below the light's plane than
/// `deepest` (the scene's deepest point: every receiver lies above it), for the screen
/// bounding box, and the planes, or
/// None when the edge never hides the light from anything below it (it does not reach below
/// the light's plane: `wedge_share` returns 0).
pub(super) fn wedge_region(e: &SilhouetteEdge, light: &AreaLight, reach: f32, deepest: f32) -> Option<(Vec<Vec3>, Vec<Vec4>)> {
    let corners = light_corners(light);
    let lowest = light.depth(e.a).min(light.depth(e.b));
    // `wedge_share` gives 0 unless both ends lie below the light (min(ha, hb) > 0); the margin
    // keeps an edge whose GPU rounding could disagree.
    if lowest < -1e-5 * reach {
        return None;
    }
    let directions: Vec<Vec3> = [e.a, e.b].iter().flat_map(|&p| corners.map(|y| p - y)).collect();
    // Points e + s(e − y) with |p − e| ≤ reach have s ≤ reach / |e − y| ≤ reach / lowest; and
    // a receiver lies no deeper below the light's plane than `deepest`, where p's depth is
    // h(e)(1 + s) (y lies on the plane), so s ≤ deepest / h(e) − 1 ≤ deepest / lowest − 1 too:
    // the hull of the ends and of each end pushed the lesser along each direction holds them.
    // On `terrain` the second is the tighter by far: an edge on a ridge, the landscape's
    // lowest point a little below it.
    let lowest = lowest.max(1e-6 * reach);
    let far = (reach / lowest).min((deepest / lowest - 1.0).max(0.0));
    let mut hull = vec![e.a, e.b];
    hull.extend(directions.iter().zip([e.a, e.a, e.a, e.a, e.b, e.b, e.b, e.b]).map(|(d, p)| p + *d * far));
    let unit: Vec<Vec3> = directions.iter().map(|d| d.normalize_or_zero()).collect();
    let mut generators = unit.clone();
    generators.push((e.b - e.a).normalize_or_zero());
    let mut planes: Vec<Vec4> = Vec::new();
    for (i, g) in generators.iter().enumerate() {
        for h in &generators[i + 1..] {
            let normal = g.cross(*h);
            if normal.length() <= 1e-4 {
                continue;
            }
            let normal = normal.normalize();
            for m in [normal, -normal] {
                if unit.iter().any(|d| m.dot(*d) < -1e-6) {
                    continue;
                }
                // Through the lower of the two ends, widened by what the directions' slack
                // could let a receiver within reach fall outside.
                let offset = -m.dot(e.a).min(m.dot(e.b)) + 1e-5 * reach;
                if planes.iter().all(|q| q.truncate().dot(m) < 1.0 - 1e-6 || (q.w - offset).abs() > 1e-5 * reach) {
                    planes.push(m.extend(offset));
                }
            }
        }
    }
    Some((hull, planes))
}
