//! The wedges method's geometry on the CPU (Assarsson & Akenine-Möller 2003 §2–3): the light
//! centre's shadow volume — a side quad per silhouette edge and, for z-fail, its caps — and a
//! penumbra wedge per edge with the two planes through the edge that touch the light.

use glam::{Vec3, Vec4};

use super::{PolygonGpu, WedgeGpu};
use crate::light::AreaLight;
use crate::scene::adjacency::{crosses, Casting, EdgeMesh, SilhouetteEdge};

/// The primitives the rasteriser runs over: volume polygons (side quads, then caps) with
/// their multiplicity and object, and one wedge per silhouette edge.
pub(super) struct Volume {
    pub polygons: Vec<[Vec3; 4]>,
    pub multiplicity: Vec<u32>,
    pub object: Vec<u32>,
    /// Cap polygons among `polygons` (z-fail only).
    pub caps: usize,
    pub wedges: Vec<WedgeGpu>,
}

impl Volume {
    /// The volume of the silhouette seen from the light centre, extruded to `reach`.
    pub fn build(mesh: &EdgeMesh, casting: &Casting, silhouette: &[SilhouetteEdge], light: &AreaLight, reach: f32, zfail: bool) -> Self {
        let c = light.center;
        // The light centre's shadow volume: a side quad per silhouette edge, and for z-fail its
        // caps — the triangles facing the light (top) and the same pushed out to `reach` (bottom).
        let extrude = |p: Vec3| c + (p - c) * (reach / (p - c).length().max(1e-6));
        let mut polygons: Vec<[Vec3; 4]> = Vec::new();
        let mut multiplicity: Vec<u32> = Vec::new();
        let mut object: Vec<u32> = Vec::new();
        for e in silhouette {
            // Always this order, never flipped per quad: (a − b) × (a' − b) is the outward
            // normal (a' the extruded a), and neighbouring quads run their shared extruded
            // edge in opposite directions, which the rasteriser's tie rule relies on; so do
            // the caps with the quads' near and far edges.
            polygons.push([e.b, e.a, extrude(e.a), extrude(e.b)]);
            multiplicity.push(e.multiplicity);
            object.push(e.object);
        }
        let mut caps = 0usize;
        if zfail {
            // Each casting triangle turned towards the centre (an open surface's back face
            // turned over), so that caps and side quads bound the same layers.
            for (t, [a, b, d]) in mesh.casting_triangles(casting) {
                polygons.push([a, b, d, d]);
                polygons.push([extrude(d), extrude(b), extrude(a), extrude(a)]);
                multiplicity.extend([1, 1]);
                object.extend([mesh.objects[t]; 2]);
                caps += 2;
            }
        }
        let wedges: Vec<WedgeGpu> = silhouette
            .iter()
            .map(|e| (e, tangent_planes(e, light)))
            .map(|(e, planes)| WedgeGpu {
                a: e.a.extend(e.multiplicity as f32).to_array(),
                b: e.b.extend(e.object as f32).to_array(),
                front: planes.first().copied().unwrap_or(Vec4::W).to_array(),
                back: planes.get(1).copied().unwrap_or(Vec4::W).to_array(),
            })
            .collect();

        Self { polygons, multiplicity, object, caps, wedges }
    }

    /// The volume polygons as the shaders read them (`VolumePolygon` in `common.wgsl`).
    pub fn polygons_gpu(&self) -> Vec<PolygonGpu> {
        self.polygons
            .iter()
            .zip(self.multiplicity.iter().zip(&self.object))
            .map(|(p, (&m, &o))| PolygonGpu {
                v0: p[0].extend(m as f32).to_array(),
                v1: p[1].extend(o as f32).to_array(),
                v2: p[2].extend(0.0).to_array(),
                v3: p[3].extend(0.0).to_array(),
            })
            .collect()
    }
}

/// Whether the eye lies in the light centre's hard shadow: the segment from the eye to the
/// centre passes through a casting triangle (then z-pass would count wrongly, §5).
pub(super) fn eye_in_shadow(mesh: &EdgeMesh, casting: &Casting, c: Vec3, eye: Vec3) -> bool {
    mesh.casting_triangles(casting).any(|(_, triangle)| crosses(eye, c - eye, triangle))
}

/// The light rectangle's corners.
pub(super) fn light_corners(light: &AreaLight) -> [Vec3; 4] {
    let (hw, hh) = (0.5 * light.size_m.x, 0.5 * light.size_m.y);
    [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(s, t)| light.center + light.r * (s * hw) + light.u * (t * hh))
}

/// The wedge's two planes through the edge's line that touch the light rectangle, as
/// world-space planes with the wedge on their positive side. Empty when the line passes
/// through the light (then every plane through it cuts the light, and only the bounding box
/// bounds the wedge).
pub(super) fn tangent_planes(e: &SilhouetteEdge, light: &AreaLight) -> Vec<Vec4> {
    let corners = light_corners(light);
    let dir = e.b - e.a;
    let scale = dir.length() * light.size_m.max_element();
    let mut planes = Vec::new();
    for &y in &corners {
        let n = dir.cross(y - e.a);
        if n.length() <= 1e-9 * scale {
            continue;
        }
        let sides: Vec<f32> = corners.iter().map(|&z| n.dot(z - e.a) / n.length()).collect();
        let tolerance = 1e-6 * light.size_m.max_element();
        let positive = sides.iter().all(|&s| s >= -tolerance);
        let negative = sides.iter().all(|&s| s <= tolerance);
        if positive == negative {
            continue; // cuts the light, or lies in its plane
        }
        // The light on the positive side: the wedge is on the negative side of both.
        let n = if positive { -n.normalize() } else { n.normalize() };
        let plane = n.extend(-n.dot(e.a));
        if planes.iter().all(|q: &Vec4| (q.truncate().dot(n) - 1.0).abs() > 1e-5) {
            planes.push(plane);
        }
    }
    if planes.len() == 2 {
        planes
    } else {
        Vec::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::AreaLight;
    use glam::Vec2;

    #[test]
    fn tangent_planes_touch_the_light_and_hold_the_wedge() {
        // A light of 2 × 1 m at y = 3 facing down; an edge along z at height 1.
        let light = AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
        let edge = SilhouetteEdge { a: Vec3::new(0.5, 1.0, -5.0), b: Vec3::new(0.5, 1.0, 5.0), multiplicity: 1, object: 0 };
        let planes = tangent_planes(&edge, &light);
        assert_eq!(planes.len(), 2);
        let side = |plane: &Vec4, p: Vec3| plane.truncate().dot(p) + plane.w;
        for plane in &planes {
            // Every corner of the light on the non-positive side, one on the plane.
            let values: Vec<f32> = light_corners(&light).iter().map(|&y| side(plane, y)).collect();
            assert!(values.iter().all(|&v| v <= 1e-4), "{values:?}");
            assert!(values.iter().any(|&v| v.abs() < 1e-4));
        }
        // Below the edge, on the floor straight under it: in the penumbra, inside both.
        assert!(planes.iter().all(|p| side(p, Vec3::new(0.5, 0.0, 0.0)) >= 0.0));
        // Far to the side on the floor: lit, outside one plane.
        assert!(planes.iter().any(|p| side(p, Vec3::new(4.0, 0.0, 0.0)) < 0.0));
        // An edge whose line passes through the light gives no planes.
        let through = SilhouetteEdge { a: Vec3::new(0.0, 1.0, 0.0), b: Vec3::new(0.0, 5.0, 0.0), multiplicity: 1, object: 0 };
        assert!(tangent_planes(&through, &light).is_empty());
    }
}
