//! What the light's centre sees of a scene's occluders, measured on the CPU so that a method
//! can say where its paper's model of a shadow does not hold (contract §2: detect it and say
//! so in the job's warnings):
//! - `overlap`: how much of the band within half a penumbra of the shadows' outline lies
//!   behind two occluding layers or more. `wedges` adds what each silhouette hides (the LI
//!   buffer, Assarsson & Akenine-Möller 2003 §2–3), so where layers overlap there its
//!   penumbra comes out darker and harder than the light that really gets through.
//! - `thin`: the share of the occluders' outline narrower than their penumbra. `brabec` and
//!   the `jfa` methods shade a point by its distance to the one nearest edge of the hard shadow
//!   (Brabec & Seidel 2002 §3; Rong & Tan 2006 §3), as if the occluder went on behind that edge;
//!   a part thinner than its penumbra (a spider's leg, a rod, a mane) lets light past both its
//!   sides, and they draw it dark with an umbra it does not have.
//!
//! The casting triangles (as `wedges` counts them: `scene::adjacency`) are drawn from the
//! light's centre into a grid of `GRID`² cells over their projection, counting layers. The
//! deepest layer of a cell is what the others shadow (a floor, a wall behind), so a cell is an
//! occluder where it holds two layers and an overlap where it holds three. The penumbra's
//! width there is the light's size carried from the cell's nearest layer to its deepest.
//! A part is thin where the occluder region, opened by a disc as wide as the penumbra (eroded,
//! then grown back), is gone: no point of it is a whole penumbra away from its outline.

use glam::{Vec2, Vec3};

use crate::light::AreaLight;
use crate::scene::adjacency::{Casting, EdgeMesh};

/// Cells along the longer side of the grid.
const GRID: usize = 256;

/// The most cells all triangles together may visit: past it (a hostile scene of millions of
/// screen-filling triangles) the measure gives up and says nothing, rather than take the job's
/// time. A real scene visits a few cells a triangle.
const CELL_BUDGET: u64 = 1 << 26;

/// Beyond these shares a method warns (chosen on the real-model suite: docs/methods.md).
pub const OVERLAP_WARNING: f64 = 0.2;
pub const THIN_WARNING: f64 = 0.25;

/// The measures of `LightView` (module doc), each a share in [0, 1].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LightView {
    pub overlap: f64,
    pub thin: f64,
}

impl LightView {
    /// Measures the scene `mesh` casting as `casting` says, from `light`'s centre.
    pub fn measure(mesh: &EdgeMesh, casting: &Casting, light: &AreaLight) -> Self {
        let project = |p: Vec3| {
            let d = p - light.center;
            let depth = d.dot(light.n);
            (depth > 1e-6 * light.size_m.max_element()).then(|| (Vec2::new(d.dot(light.r), d.dot(light.u)) / depth, depth))
        };
        let triangles: Vec<[(Vec2, f32); 3]> = mesh
            .casting_triangles(casting)
            .filter_map(|(_, corners)| Some([project(corners[0])?, project(corners[1])?, project(corners[2])?]))
            .collect();
        let (lo, hi) = triangles.iter().flatten().fold((Vec2::MAX, Vec2::MIN), |(lo, hi), (p, _)| (lo.min(*p), hi.max(*p)));
        if triangles.is_empty() || !(hi - lo).is_finite() {
            return Self::default();
        }
        let cell = (hi - lo).max_element().max(1e-12) / GRID as f32;
        let (w, h) = ((((hi.x - lo.x) / cell) as usize + 1).min(GRID), (((hi.y - lo.y) / cell) as usize + 1).min(GRID));
        let Some(Layers { layers, nearest, deepest }) = Layers::draw(&triangles, lo, cell, (w, h)) else { return Self::default() };
        let occluder: Vec<bool> = layers.iter().map(|&l| l >= 2).collect();
        let occluders = occluder.iter().filter(|o| **o).count();
        if occluders == 0 {
            return Self::default();
        }
        // The penumbra's half width per cell in the projection (tangents from the centre): the
        // light's size carried from the occluder to its receiver, L·(d_r − d_o)/(d_o·d_r).
        let light_size = (light.size_m.x * light.size_m.y).sqrt();
        let radius: Vec<f32> = (0..w * h)
            .map(|i| if occluder[i] { 0.5 * light_size * (deepest[i] - nearest[i]) / (nearest[i] * deepest[i]) / cell } else { 0.0 })
            .collect();
        let inside = distance_to(&occluder.iter().map(|o| !o).collect::<Vec<_>>(), w, h);
        let band: Vec<usize> = (0..w * h).filter(|&i| occluder[i] && inside[i] < radius[i]).collect();
        let overlap = if band.is_empty() { 0.0 } else { band.iter().filter(|&&i| layers[i] >= 3).count() as f64 / band.len() as f64 };
        let core: Vec<bool> = (0..w * h).map(|i| occluder[i] && inside[i] >= radius[i]).collect();
        let to_core = distance_to(&core, w, h);
        let thin = (0..w * h).filter(|&i| occluder[i] && to_core[i] > radius[i]).count() as f64 / occluders as f64;
        Self { overlap, thin }
    }
}

/// The casting triangles drawn into the grid: per cell, its layers, and the nearest and the
/// deepest surface along its ray.
struct Layers {
    layers: Vec<u16>,
    nearest: Vec<f32>,
    deepest: Vec<f32>,
}

impl Layers {
    /// Draws `triangles` (projected corners and their depths) into a `w × h` grid of cells of
    /// side `cell` from `lo`; `None` past `CELL_BUDGET`.
    fn draw(triangles: &[[(Vec2, f32); 3]], lo: Vec2, cell: f32, (w, h): (usize, usize)) -> Option<Self> {
        let mut out = Layers { layers: vec![0; w * h], nearest: vec![f32::INFINITY; w * h], deepest: vec![0.0; w * h] };
        let mut visits = 0u64;
        for t in triangles {
            let mut p = t.map(|(p, _)| (p - lo) / cell);
            let mut inverse = t.map(|(_, d)| 1.0 / d);
            let (min, max) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
            if area == 0.0 {
                continue;
            }
            if area < 0.0 {
                p.swap(1, 2);
                inverse.swap(1, 2);
            }
            // A cell centre on an edge counts for one of the two triangles sharing it: the one
            // that runs the edge upwards (or rightwards, level), as a rasteriser's fill rule.
            let owns = |e: Vec2| e.y > 0.0 || (e.y == 0.0 && e.x > 0.0);
            let (xs, ys) = (
                (min.x.floor().max(0.0) as usize)..(max.x.ceil() as usize).min(w),
                (min.y.floor().max(0.0) as usize)..(max.y.ceil() as usize).min(h),
            );
            visits += (xs.len() * ys.len()) as u64;
            if visits > CELL_BUDGET {
                return None;
            }
            for y in ys {
                for x in xs.clone() {
                    let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let sides = [0, 1, 2].map(|k| (p[(k + 1) % 3] - p[k]).perp_dot(c - p[k]));
                    if (0..3).all(|k| sides[k] > 0.0 || (sides[k] == 0.0 && owns(p[(k + 1) % 3] - p[k]))) {
                        // 1/depth is affine across a triangle seen from the centre; side k is
                        // opposite corner k + 2.
                        let depth = area.abs() / (0..3).map(|k| sides[k] * inverse[(k + 2) % 3]).sum::<f32>();
                        let i = y * w + x;
                        out.layers[i] = out.layers[i].saturating_add(1);
                        out.nearest[i] = out.nearest[i].min(depth);
                        out.deepest[i] = out.deepest[i].max(depth);
                    }
                }
            }
        }
        Some(out)
    }
}

/// The share of the frame's occluders thinner than their penumbra (`LightView::thin`), for a
/// method that shades from the one nearest edge of the hard shadow, with a warning for the
/// job beyond `THIN_WARNING` naming `method` and the section of its paper (`model`) that makes
/// it so.
pub fn thin_occluders(ctx: &mut super::MethodContext<'_>, method: &str, model: &str) -> f64 {
    let light = &ctx.spec.light;
    let mesh = ctx.scene.edge_mesh();
    let thin = LightView::measure(&mesh, &ctx.scene.casting_from(light.center), light).thin;
    if thin > THIN_WARNING {
        ctx.warnings.push(format!(
            "{method}: {:.0} % of the occluders, seen from the light, are narrower than their penumbra; {method} shades a point \
             by its distance to the one nearest edge of the hard shadow ({model}), as if the occluder went on behind it, so \
             these parts shadow darker than they do, with an umbra they do not have (pcss and reference do not assume it)",
            100.0 * thin
        ));
    }
    thin
}

/// Per cell of a `w × h` grid, its distance in cells to the nearest cell where `target` holds
/// (two-pass chamfer, 3-4 weights: within 8 % of the Euclidean distance); infinite if none.
fn distance_to(target: &[bool], w: usize, h: usize) -> Vec<f32> {
    const FAR: u32 = u32::MAX / 2;
    let mut d: Vec<u32> = target.iter().map(|&t| if t { 0 } else { FAR }).collect();
    fn relax(d: &mut [u32], i: usize, j: Option<usize>, cost: u32) {
        if let Some(j) = j {
            d[i] = d[i].min(d[j].saturating_add(cost));
        }
    }
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            relax(&mut d, i, (x > 0).then(|| i - 1), 3);
            relax(&mut d, i, (y > 0).then(|| i - w), 3);
            relax(&mut d, i, (x > 0 && y > 0).then(|| i - w - 1), 4);
            relax(&mut d, i, (x + 1 < w && y > 0).then(|| i - w + 1), 4);
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            relax(&mut d, i, (x + 1 < w).then(|| i + 1), 3);
            relax(&mut d, i, (y + 1 < h).then(|| i + w), 3);
            relax(&mut d, i, (x + 1 < w && y + 1 < h).then(|| i + w + 1), 4);
            relax(&mut d, i, (x > 0 && y + 1 < h).then(|| i + w - 1), 4);
        }
    }
    d.iter().map(|&v| if v >= FAR { f32::INFINITY } else { v as f32 / 3.0 }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    /// A horizontal quad (two triangles) at height `y`, `(x0, z0)`–`(x1, z1)`, facing up.
    fn quad(positions: &mut Vec<Vec3>, indices: &mut Vec<u32>, y: f32, (x0, z0): (f32, f32), (x1, z1): (f32, f32)) {
        let base = positions.len() as u32;
        positions.extend([Vec3::new(x0, y, z0), Vec3::new(x0, y, z1), Vec3::new(x1, y, z1), Vec3::new(x1, y, z0)]);
        indices.extend([0, 1, 2, 0, 2, 3].map(|k| base + k));
    }

    /// A level rectangle: two opposite corners (x, z) and its height.
    type Occluder = ((f32, f32), (f32, f32), f32);

    fn measure(occluders: &[Occluder]) -> LightView {
        let (mut positions, mut indices) = (Vec::new(), Vec::new());
        quad(&mut positions, &mut indices, 0.0, (-20.0, -20.0), (20.0, 20.0)); // the floor
        for &(a, b, y) in occluders {
            quad(&mut positions, &mut indices, y, a, b);
        }
        let mesh = EdgeMesh::build(&positions, &indices, &[]);
        let light = AreaLight::new(Vec3::Y * 10.0, -Vec3::Y, -Vec3::Z, Vec2::splat(2.0), 1.0).unwrap();
        LightView::measure(&mesh, &mesh.casting(light.center), &light)
    }

    #[test]
    fn a_wide_plate_is_neither_thin_nor_overlapped() {
        // Penumbra on the floor: 2 m × (10 − 5)/5 = 2 m; the plate is 8 m wide.
        let view = measure(&[((-4.0, -4.0), (4.0, 4.0), 5.0)]);
        assert_eq!(view.overlap, 0.0);
        assert!(view.thin < 0.05, "{view:?}");
    }

    #[test]
    fn a_rod_narrower_than_its_penumbra_is_thin() {
        // 0.4 m wide against a 2 m penumbra; beside a wide plate, it alone is thin.
        let view = measure(&[((-4.0, -4.0), (4.0, 4.0), 5.0), ((6.0, -4.0), (6.4, 4.0), 5.0)]);
        assert!(view.thin > 0.03 && view.thin < 0.15, "{view:?}");
        assert!(measure(&[((6.0, -4.0), (6.4, 4.0), 5.0)]).thin > 0.9);
    }

    #[test]
    fn stacked_plates_overlap_along_their_outline() {
        let view = measure(&[((-4.0, -4.0), (4.0, 4.0), 5.0), ((-3.0, -3.0), (4.5, 4.5), 6.0)]);
        assert!(view.overlap > 0.2, "{view:?}");
        assert_eq!(measure(&[((-4.0, -4.0), (-1.0, 4.0), 5.0), ((1.0, -4.0), (4.0, 4.0), 5.0)]).overlap, 0.0, "side by side");
    }

    /// A hostile scene: thousands of plates each covering the whole grid. The measure gives up
    /// within its cell budget and says nothing rather than take the job's time.
    #[test]
    fn a_scene_of_huge_overlapping_plates_stays_within_the_cell_budget() {
        let plates: Vec<_> = (0..3000).map(|k| ((-19.0, -19.0), (19.0, 19.0), 1.0 + 8.0 * k as f32 / 3000.0)).collect();
        assert_eq!(measure(&plates), LightView::default());
    }

    #[test]
    fn the_chamfer_distance_is_close_to_euclid() {
        let (w, h) = (40, 30);
        let mut target = vec![false; w * h];
        target[15 * w + 20] = true;
        let d = distance_to(&target, w, h);
        for (x, y) in [(30usize, 15usize), (20, 5), (28, 21), (0, 0)] {
            let exact = ((x as f32 - 20.0).powi(2) + (y as f32 - 15.0).powi(2)).sqrt();
            assert!((d[y * w + x] - exact).abs() <= 0.08 * exact + 1e-6, "({x}, {y}): {} against {exact}", d[y * w + x]);
        }
        assert!(distance_to(&[false; 4], 2, 2).iter().all(|d| d.is_infinite()));
    }
}
