//! Which triangles cast from a point: the surfaces facing it, less those hidden from it by
//! others (`FrontFaces`, a grid of the front faces seen from the point), and the ray-triangle
//! test they share.

use glam::Vec3;

use super::EdgeMesh;

/// How each triangle casts from one point: `Some(true)` in its own winding, `Some(false)`
/// turned over (an open surface's back face that nothing of it closes off), `None` not at all.
pub struct Casting {
    pub(super) by_triangle: Vec<Option<bool>>,
}

/// Front faces of open surfaces as seen from a point, in a grid over their projection, for
/// asking whether a segment from a surface's back face to the point crosses the same surface
/// first. The projection is the gnomonic one about the mean direction of the triangles'
/// corners, so a segment to the point is a point in it; triangles with a corner near or
/// behind the projection's plane are left out (they answer "not hidden": cast).
pub(super) struct FrontFaces {
    pub(super) point: Vec3,
    pub(super) axes: [Vec3; 3],
    pub(super) lo: glam::Vec2,
    pub(super) scale: glam::Vec2,
    pub(super) side: usize,
    pub(super) cells: Vec<Vec<u32>>,
    /// Triangles over more than `LARGE_CELLS` cells, tested by every query.
    pub(super) large: Vec<u32>,
}

/// A triangle over more cells than this is listed among `FrontFaces::large`.
pub(super) const LARGE_CELLS: usize = 64;

/// The most large triangles kept: every query tests them all.
pub(super) const MAX_LARGE: usize = 1024;

impl FrontFaces {
    pub(super) fn new(mesh: &EdgeMesh, point: Vec3, chosen: impl Fn(usize) -> bool) -> Self {
        let chosen: Vec<usize> = (0..mesh.triangles.len()).filter(|&t| chosen(t)).collect();
        let mean = chosen
            .iter()
            .flat_map(|&t| mesh.triangles[t].map(|i| (mesh.positions[i as usize] - point).normalize_or_zero()))
            .fold(Vec3::ZERO, |a, d| a + d);
        let forward = mean.try_normalize().unwrap_or(Vec3::NEG_Y);
        let right = forward.any_orthonormal_vector();
        let axes = [right, forward.cross(right), forward];
        let mut fronts =
            FrontFaces { point, axes, lo: glam::Vec2::ZERO, scale: glam::Vec2::ONE, side: 1, cells: vec![Vec::new()], large: Vec::new() };
        let projected: Vec<(usize, [glam::Vec2; 3])> = chosen
            .iter()
            .filter_map(|&t| {
                let [a, b, c] = mesh.triangles[t].map(|i| fronts.project(mesh.positions[i as usize]));
                Some((t, [a?, b?, c?]))
            })
            .collect();
        if projected.is_empty() {
            return fronts;
        }
        let (lo, hi) =
            projected.iter().flat_map(|(_, p)| *p).fold((glam::Vec2::MAX, glam::Vec2::MIN), |(lo, hi), p| (lo.min(p), hi.max(p)));
        fronts.side = ((projected.len() as f32).sqrt() as usize).clamp(1, 512);
        fronts.lo = lo;
        fronts.scale = fronts.side as f32 / (hi - lo).max(glam::Vec2::splat(1e-12));
        fronts.cells = vec![Vec::new(); fronts.side * fronts.side];
        for (t, p) in projected {
            let (a, b) = (fronts.cell(p[0].min(p[1]).min(p[2])), fronts.cell(p[0].max(p[1]).max(p[2])));
            // A triangle over many cells is listed once, among the ones every query tests, so
            // that a scene of large triangles costs lists, not cells; past `MAX_LARGE` of them
            // the rest are left out (their back faces then cast: the paper's count, not none).
            if (b.0 - a.0 + 1) * (b.1 - a.1 + 1) > LARGE_CELLS {
                if fronts.large.len() < MAX_LARGE {
                    fronts.large.push(t as u32);
                }
                continue;
            }
            for y in a.1..=b.1 {
                for x in a.0..=b.0 {
                    fronts.cells[y * fronts.side + x].push(t as u32);
                }
            }
        }
        fronts
    }

    /// `p` in the projection, if it lies well in front of the projection's plane.
    pub(super) fn project(&self, p: Vec3) -> Option<glam::Vec2> {
        let d = p - self.point;
        let z = d.dot(self.axes[2]);
        (z > 1e-3 * d.length()).then(|| glam::Vec2::new(d.dot(self.axes[0]), d.dot(self.axes[1])) / z)
    }

    pub(super) fn cell(&self, p: glam::Vec2) -> (usize, usize) {
        let c = ((p - self.lo) * self.scale).as_ivec2().clamp(glam::IVec2::ZERO, glam::IVec2::splat(self.side as i32 - 1));
        (c.x as usize, c.y as usize)
    }

    /// Whether the open segment from `from` to the point crosses a front face of `surface`.
    pub(super) fn hides(&self, mesh: &EdgeMesh, from: Vec3, surface: u32) -> bool {
        let Some(p) = self.project(from) else { return false };
        let (x, y) = self.cell(p);
        let dir = from - self.point;
        self.cells[y * self.side + x].iter().chain(&self.large).any(|&t| {
            mesh.surface[t as usize] == surface && {
                let [a, b, c] = mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]);
                crosses(self.point, dir, [a, b, c])
            }
        })
    }
}

/// Whether the open segment `origin + s·dir`, 0 < s < 1, crosses triangle `tri` (Möller–Trumbore).
pub fn crosses(origin: Vec3, dir: Vec3, [a, b, c]: [Vec3; 3]) -> bool {
    let (e1, e2) = (b - a, c - a);
    let h = dir.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return false;
    }
    let s = origin - a;
    let u = s.dot(h) / det;
    let q = s.cross(e1);
    let v = dir.dot(q) / det;
    let t = e2.dot(q) / det;
    u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 1e-6 && t < 1.0 - 1e-6
}
