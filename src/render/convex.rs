//! Convex solids as faces and planes: where a camera's view meets the scene's bounds, so that
//! a pass drawn from elsewhere (the reference's sample maps) can bound the texels a receiver
//! of the frame can fall in.

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::scene::box_corners;

/// A bounded convex solid: its faces, each a convex polygon, and the planes that bound it,
/// `plane · (p, 1) ≥ 0` inside. A solid with no faces is empty.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvexSolid {
    pub faces: Vec<Vec<Vec3>>,
    pub planes: Vec<Vec4>,
}

/// The six faces of a box whose corners are numbered as `box_corners` numbers them (bit 0:
/// x, bit 1: y, bit 2: z), each a loop of four corners.
const BOX_FACES: [[usize; 4]; 6] = [[0, 2, 6, 4], [1, 3, 7, 5], [0, 1, 5, 4], [2, 3, 7, 6], [0, 1, 3, 2], [4, 5, 7, 6]];

/// The faces of a hexahedron (a box, or a frustum: its image) from its corners, numbered as
/// `box_corners` numbers a box's.
fn hexahedron_faces(corners: [Vec3; 8]) -> Vec<Vec<Vec3>> {
    BOX_FACES.iter().map(|face| face.map(|k| corners[k]).to_vec()).collect()
}

impl ConvexSolid {
    /// The box [lo, hi].
    pub fn cuboid(lo: Vec3, hi: Vec3) -> Self {
        Self {
            faces: hexahedron_faces(box_corners(lo, hi)),
            planes: vec![
                Vec4::new(1.0, 0.0, 0.0, -lo.x),
                Vec4::new(-1.0, 0.0, 0.0, hi.x),
                Vec4::new(0.0, 1.0, 0.0, -lo.y),
                Vec4::new(0.0, -1.0, 0.0, hi.y),
                Vec4::new(0.0, 0.0, 1.0, -lo.z),
                Vec4::new(0.0, 0.0, -1.0, hi.z),
            ],
        }
    }

    /// The view volume of a projection with a far plane: the points whose clip coordinates
    /// satisfy −w ≤ x, y ≤ w and 0 ≤ z ≤ w (wgpu's clip volume).
    pub fn frustum(view_proj: Mat4) -> Self {
        let inverse = view_proj.inverse();
        let corners = box_corners(Vec3::new(-1.0, -1.0, 0.0), Vec3::ONE).map(|c| inverse.project_point3(c));
        let [r0, r1, r2, r3] = [0, 1, 2, 3].map(|i| view_proj.row(i));
        Self { faces: hexahedron_faces(corners), planes: vec![r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2] }
    }

    /// The part both solids share. Every face of it is a face of one of them clipped by the
    /// other's planes.
    pub fn intersect(&self, other: &Self) -> Self {
        let clipped = |faces: &[Vec<Vec3>], planes: &[Vec4]| -> Vec<Vec<Vec3>> {
            faces.iter().map(|face| clip_polygon(face, planes)).filter(|face| face.len() >= 3).collect()
        };
        let mut faces = clipped(&self.faces, &other.planes);
        faces.extend(clipped(&other.faces, &self.planes));
        Self { faces, planes: [self.planes.as_slice(), other.planes.as_slice()].concat() }
    }

    /// Whether `p` lies inside every plane, within `tolerance` (in the planes' units).
    pub fn contains(&self, p: Vec3, tolerance: f32) -> bool {
        self.planes.iter().all(|plane| plane.dot(p.extend(1.0)) >= -tolerance)
    }
}

/// The bounds, in texels (x right, y down from the top-left corner of a `resolution`² map
/// drawn with `view_proj`, an infinite reversed-Z perspective), of where the points of `solid`
/// in front of the map's near plane project: the vertices of the solid clipped by the map's
/// four sides and near plane, and the near plane's corners where the solid holds them.
/// `None` where no point of the solid falls in the map.
pub fn map_bounds(solid: &ConvexSolid, view_proj: Mat4, resolution: u32) -> Option<(Vec2, Vec2)> {
    let [r0, r1, r2, r3] = [0, 1, 2, 3].map(|i| view_proj.row(i));
    // Inside the map: −w ≤ x, y ≤ w; in front of the near plane: z ≤ w (z is the near
    // distance itself under an infinite reversed-Z projection).
    let sides = [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 - r2];
    let mut points: Vec<Vec3> = solid.faces.iter().flat_map(|face| clip_polygon(face, &sides)).collect();
    let inverse = view_proj.inverse();
    let scale = solid.faces.iter().flatten().fold(1.0f32, |m, p| m.max(p.abs().max_element()));
    for corner in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let p = inverse.project_point3(Vec3::new(corner.0, corner.1, 1.0));
        if solid.contains(p, 1e-5 * scale) {
            points.push(p);
        }
    }
    let side = resolution as f32;
    let mut bounds: Option<(Vec2, Vec2)> = None;
    for p in points {
        let clip = view_proj * p.extend(1.0);
        let texel = Vec2::new(clip.x / clip.w + 1.0, 1.0 - clip.y / clip.w) * (0.5 * side);
        if !texel.is_finite() {
            return Some((Vec2::ZERO, Vec2::splat(side)));
        }
        bounds = Some(bounds.map_or((texel, texel), |(lo, hi)| (lo.min(texel), hi.max(texel))));
    }
    bounds
}

/// The part of a convex polygon on the inner side of every plane (Sutherland–Hodgman).
fn clip_polygon(polygon: &[Vec3], planes: &[Vec4]) -> Vec<Vec3> {
    planes.iter().fold(polygon.to_vec(), |polygon, plane| {
        let side = |p: Vec3| plane.dot(p.extend(1.0));
        let mut kept = Vec::with_capacity(polygon.len() + 1);
        for (i, &a) in polygon.iter().enumerate() {
            let b = polygon[(i + 1) % polygon.len()];
            let (da, db) = (side(a), side(b));
            if da >= 0.0 {
                kept.push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                kept.push(a + (b - a) * (da / (da - db)));
            }
        }
        kept
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` points spread over the box [lo, hi] (a fixed low-discrepancy sequence).
    fn points_in(lo: Vec3, hi: Vec3, n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let t = i as f32 + 0.5;
                let u = Vec3::new((t * 0.618_034).fract(), (t * 0.754_877_7).fract(), (t * 0.569_840_3).fract());
                lo + (hi - lo) * u
            })
            .collect()
    }

    fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
        points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    #[test]
    fn a_camera_sees_the_part_of_a_box_its_frustum_holds() {
        // Looking at one corner of the box from outside it: a strict part of it is in view.
        let view_proj = Mat4::perspective_rh(40f32.to_radians(), 1.5, 0.5, 30.0)
            * Mat4::look_at_rh(Vec3::new(7.0, 4.0, 9.0), Vec3::new(3.0, 0.0, 2.0), Vec3::Y);
        let (lo, hi) = (Vec3::new(-5.0, 0.0, -5.0), Vec3::new(5.0, 2.0, 5.0));
        let solid = ConvexSolid::frustum(view_proj).intersect(&ConvexSolid::cuboid(lo, hi));
        let vertices: Vec<Vec3> = solid.faces.iter().flatten().copied().collect();
        let (vlo, vhi) = bounds(&vertices);
        let in_view = |p: Vec3| {
            let c = view_proj * p.extend(1.0);
            c.x.abs() <= c.w && c.y.abs() <= c.w && c.z >= 0.0 && c.z <= c.w
        };
        let all = points_in(lo, hi, 40_000);
        let seen: Vec<Vec3> = all.iter().copied().filter(|p| in_view(*p)).collect();
        assert!(seen.len() > 2_000 && seen.len() < 38_000, "a strict part of the box: {} of {}", seen.len(), all.len());
        // Every point seen lies inside the solid and within its vertices' bounds...
        for p in &seen {
            assert!(solid.contains(*p, 1e-4), "{p}");
            assert!(p.cmpge(vlo - 1e-4).all() && p.cmple(vhi + 1e-4).all(), "{p} outside {vlo}..{vhi}");
        }
        // ...every vertex lies in the box and the view, and the bounds are tight.
        for v in &vertices {
            assert!(solid.contains(*v, 1e-3), "{v}");
        }
        let (slo, shi) = bounds(&seen);
        assert!((slo - vlo).abs().max_element() < 0.3 && (shi - vhi).abs().max_element() < 0.3, "{slo}..{shi} against {vlo}..{vhi}");
        // Looking away from the box: nothing of it in view.
        let away = Mat4::perspective_rh(40f32.to_radians(), 1.5, 0.5, 30.0)
            * Mat4::look_at_rh(Vec3::new(7.0, 4.0, 9.0), Vec3::new(9.0, 5.0, 20.0), Vec3::Y);
        assert!(ConvexSolid::frustum(away).intersect(&ConvexSolid::cuboid(lo, hi)).faces.is_empty());
    }

    #[test]
    fn map_bounds_hold_every_point_in_the_map_and_nothing_behind_it() {
        let (lo, hi) = (Vec3::new(-4.0, 0.0, -3.0), Vec3::new(2.0, 1.5, 3.0));
        let resolution = 1024;
        // A map looking down from above one side of the box, its frustum narrower than it.
        let eye = Vec3::new(3.0, 6.0, 0.5);
        let view_proj = Mat4::perspective_infinite_reverse_rh(70f32.to_radians(), 1.0, 0.2) * Mat4::look_to_rh(eye, -Vec3::Y, -Vec3::Z);
        let (blo, bhi) = map_bounds(&ConvexSolid::cuboid(lo, hi), view_proj, resolution).unwrap();
        let mut texels = Vec::new();
        for p in points_in(lo, hi, 40_000) {
            let c = view_proj * p.extend(1.0);
            if c.x.abs() <= c.w && c.y.abs() <= c.w && c.z <= c.w {
                let texel = Vec2::new(c.x / c.w + 1.0, 1.0 - c.y / c.w) * (0.5 * resolution as f32);
                assert!(texel.cmpge(blo - 1e-2).all() && texel.cmple(bhi + 1e-2).all(), "{texel} outside {blo}..{bhi}");
                texels.push(texel);
            }
        }
        let (tlo, thi) = texels.iter().fold((Vec2::INFINITY, Vec2::NEG_INFINITY), |(a, b), t| (a.min(*t), b.max(*t)));
        assert!((tlo - blo).abs().max_element() < 40.0 && (thi - bhi).abs().max_element() < 40.0, "{tlo}..{thi} against {blo}..{bhi}");
        assert!(bhi.x - blo.x < 0.9 * resolution as f32, "the box covers part of the map: {blo}..{bhi}");
        // Behind the map (above its eye, looking down): nothing falls in it.
        let above = ConvexSolid::cuboid(Vec3::new(-4.0, 7.0, -3.0), Vec3::new(2.0, 9.0, 3.0));
        assert_eq!(map_bounds(&above, view_proj, resolution), None);
        // Around its eye: the near plane's corners are in the box, so the whole map.
        let around = ConvexSolid::cuboid(Vec3::new(-10.0, 0.0, -10.0), Vec3::new(10.0, 10.0, 10.0));
        let (alo, ahi) = map_bounds(&around, view_proj, resolution).unwrap();
        assert!(alo.abs().max_element() < 1e-2 && (ahi - resolution as f32).abs().max_element() < 1e-2, "{alo}..{ahi}");
    }
}
