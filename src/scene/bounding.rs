//! A scene's bounding triangles: large triangles with the whole scene on one side of their
//! plane — a floor, the walls of a room. From a light on that side such a triangle shadows
//! nothing, so the sample maps of `reference` and `filtered` leave it out (contract §1,
//! *Reference*): the floor is the largest fill of every map.
//!
//! Why it shadows nothing: every point of the scene is a convex combination of its vertices,
//! so it lies on the plane or on the scene's side. A segment from a point of the light,
//! strictly on that side, to such a point meets the plane at most at its far end, the
//! receiver itself, which the test's bias counts lit. A map without the triangle differs only
//! in the texels where it was nearest, where every receiver was lit anyway — but for a test
//! of a floor pixel against the floor's own depth that the bias did not cover (acne), now lit.

use std::ops::Range;

use glam::Vec3;

/// How many of the largest triangles are tried: each costs a pass over the vertices, and a
/// bounding triangle worth leaving out is a large one (its fill, not its set-up, is the cost).
const CANDIDATES: usize = 64;

/// A candidate is tried only if its area is at least this share of the largest triangle's: a
/// scene of equal small triangles (a terrain) has nothing worth the passes.
const LEAST_AREA_SHARE: f32 = 0.05;

/// Vertices this far behind a plane, as a share of the scene's bounding diagonal, still count
/// as on it (the floor's own vertices, rounded).
const TOLERANCE: f32 = 1e-5;

/// The most runs of kept triangles a light's casters may be cut into: each run is a draw call
/// of every map on the GPU. Beyond it, nothing is left out.
const MOST_RUNS: usize = 16;

/// The scene's bounding triangles, each with its plane turned so that the scene lies on the
/// positive side.
#[derive(Debug, Default)]
pub struct BoundingTriangles {
    planes: Vec<Bounding>,
    triangles: u32,
    tolerance: f32,
}

#[derive(Debug, Clone, Copy)]
struct Bounding {
    triangle: u32,
    normal: Vec3,
    offset: f32,
}

impl BoundingTriangles {
    /// Finds them among the largest triangles of `positions` / `indices` (three indices a
    /// triangle).
    pub fn find(positions: &[Vec3], indices: &[u32]) -> Self {
        let triangles = (indices.len() / 3) as u32;
        let corners = |t: usize| [0, 1, 2].map(|k| positions[indices[3 * t + k] as usize]);
        let mut by_area: Vec<(f32, u32)> = (0..triangles as usize)
            .filter_map(|t| {
                let [a, b, c] = corners(t);
                let area = 0.5 * (b - a).cross(c - a).length();
                (area.is_finite() && area > 0.0).then_some((area, t as u32))
            })
            .collect();
        let (lo, hi) = positions.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        let tolerance = TOLERANCE * (hi - lo).length().max(f32::MIN_POSITIVE);
        let mut found = Self { planes: Vec::new(), triangles, tolerance };
        if by_area.is_empty() {
            return found;
        }
        let take = CANDIDATES.min(by_area.len());
        by_area.select_nth_unstable_by(take - 1, |a, b| b.0.total_cmp(&a.0));
        by_area.truncate(take);
        let largest = by_area.iter().map(|&(area, _)| area).fold(0.0, f32::max);
        for &(area, t) in &by_area {
            if area < LEAST_AREA_SHARE * largest {
                continue;
            }
            let [a, b, c] = corners(t as usize);
            let normal = (b - a).cross(c - a).normalize();
            let offset = normal.dot(a);
            let (mut least, mut most) = (f32::MAX, f32::MIN);
            for p in positions {
                let d = normal.dot(*p) - offset;
                least = least.min(d);
                most = most.max(d);
            }
            if least >= -tolerance {
                found.planes.push(Bounding { triangle: t, normal, offset });
            } else if most <= tolerance {
                found.planes.push(Bounding { triangle: t, normal: -normal, offset: -offset });
            }
        }
        found.planes.sort_by_key(|b| b.triangle);
        found
    }

    /// How many were found.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.planes.len()
    }

    /// The runs of indices (three a triangle) of the triangles that can shadow some point of
    /// the scene from a light whose every point is a convex combination of `light`: all but the
    /// bounding triangles with every one of those points strictly on the scene's side of
    /// their plane. The whole index range where that leaves more than `MOST_RUNS` runs.
    pub fn casting_runs(&self, light: &[Vec3]) -> Vec<Range<u32>> {
        // A list of runs that holds one.
        #[allow(clippy::single_range_in_vec_init)]
        let all = vec![0..3 * self.triangles];
        let left_out: Vec<u32> =
            self.planes.iter().filter(|b| light.iter().all(|p| b.normal.dot(*p) - b.offset > self.tolerance)).map(|b| b.triangle).collect();
        if left_out.is_empty() {
            return all;
        }
        let mut runs = Vec::new();
        let mut from = 0;
        for &t in &left_out {
            if t > from {
                runs.push(3 * from..3 * t);
            }
            from = t + 1;
        }
        if from < self.triangles {
            runs.push(3 * from..3 * self.triangles);
        }
        if runs.len() > MOST_RUNS {
            return all;
        }
        runs
    }
}

// Lists of runs that hold one.
#[allow(clippy::single_range_in_vec_init)]
#[cfg(test)]
mod tests {
    use super::*;

    /// A floor (two triangles) under a box of twelve: the floor bounds the scene from below.
    /// The box's top bounds it from above, but is too small beside the floor to be tried.
    fn floor_and_box() -> (Vec<Vec3>, Vec<u32>) {
        let mut positions =
            vec![Vec3::new(-5.0, 0.0, -5.0), Vec3::new(-5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, -5.0)];
        let mut indices = vec![0, 1, 2, 0, 2, 3];
        for z in [0.5f32, 1.5] {
            for x in [-0.5f32, 0.5] {
                for y in [1.0f32, 2.0] {
                    positions.push(Vec3::new(x, y, z - 1.0));
                }
            }
        }
        // The box's six faces, as quads of its eight corners (index 4 + (z, x, y) bits).
        let quad = |a: u32, b: u32, c: u32, d: u32| [a + 4, b + 4, c + 4, a + 4, c + 4, d + 4];
        for q in [quad(0, 1, 3, 2), quad(4, 6, 7, 5), quad(0, 4, 5, 1), quad(2, 3, 7, 6), quad(0, 2, 6, 4), quad(1, 5, 7, 3)] {
            indices.extend(q);
        }
        (positions, indices)
    }

    #[test]
    fn a_floor_under_the_light_casts_nothing_and_the_rest_all_cast() {
        let (positions, indices) = floor_and_box();
        let bounding = BoundingTriangles::find(&positions, &indices);
        assert_eq!(bounding.len(), 2, "{bounding:?}");
        let above = [Vec3::new(-1.0, 6.0, -1.0), Vec3::new(1.0, 6.0, -1.0), Vec3::new(1.0, 6.0, 1.0), Vec3::new(-1.0, 6.0, 1.0)];
        assert_eq!(bounding.casting_runs(&above), vec![6..indices.len() as u32]);
    }

    #[test]
    fn a_light_below_or_through_the_floor_keeps_it() {
        let (positions, indices) = floor_and_box();
        let bounding = BoundingTriangles::find(&positions, &indices);
        let whole = vec![0..indices.len() as u32];
        let below = [Vec3::new(-1.0, -3.0, -1.0), Vec3::new(1.0, -3.0, 1.0)];
        assert_eq!(bounding.casting_runs(&below), whole);
        let through = [Vec3::new(-1.0, 3.0, -1.0), Vec3::new(1.0, -0.5, 1.0)];
        assert_eq!(bounding.casting_runs(&through), whole);
        // A corner on the plane itself: the floor could be met on the way to a receiver on it.
        let touching = [Vec3::new(-1.0, 3.0, -1.0), Vec3::new(1.0, 0.0, 1.0)];
        assert_eq!(bounding.casting_runs(&touching), whole);
    }

    #[test]
    fn a_vertex_below_the_floor_keeps_it() {
        let (mut positions, mut indices) = floor_and_box();
        positions.extend([Vec3::new(0.0, -0.2, 3.0), Vec3::new(0.5, 0.5, 3.0), Vec3::new(-0.5, 0.5, 3.0)]);
        let n = positions.len() as u32;
        indices.extend([n - 3, n - 2, n - 1]);
        let bounding = BoundingTriangles::find(&positions, &indices);
        let above = [Vec3::new(0.0, 6.0, 0.0)];
        assert_eq!(bounding.casting_runs(&above), vec![0..indices.len() as u32]);
    }

    #[test]
    fn the_walls_of_a_room_around_its_light_are_left_out() {
        // A room: the box alone, every face of which bounds it.
        let (positions, indices) = floor_and_box();
        let room: Vec<Vec3> = positions[4..].to_vec();
        let faces: Vec<u32> = indices[6..].iter().map(|i| i - 4).collect();
        let bounding = BoundingTriangles::find(&room, &faces);
        assert_eq!(bounding.len(), 12);
        assert_eq!(bounding.casting_runs(&[Vec3::new(0.0, 1.5, 0.0)]), Vec::<Range<u32>>::new());
        // A light above it, within its walls: the ceiling (y = 2) has the light outside and
        // stays; its floor and walls have the light on the scene's side and go.
        let runs = bounding.casting_runs(&[Vec3::new(0.1, 5.0, -0.2)]);
        let kept: u32 = runs.iter().map(|r| (r.end - r.start) / 3).sum();
        assert_eq!(kept, 2, "{runs:?}");
    }
}
