//! The exact unshadowed irradiance E0 every method shares (contract §1): the light cut into
//! uniform cells, and Lambert's closed form for a polygon clipped to the receiver's
//! hemisphere — the CPU twin of `shaders/common/light.wgsl` and `shaders/e0/`.

use glam::{DVec3, Vec3};

use super::{AreaLight, LightImage};

/// Most cells per side of the light grid E0 integrates over. Cells follow texel boundaries
/// and cells of equal colour are merged, so E0 is exact for images of up to this many texels
/// per side and for any image made of large uniform regions (`white`, `stripes`).
pub const E0_GRID: u32 = 8;

/// A uniform sub-rectangle of the light: corners in world space (counter-clockwise seen
/// from the lit side) and its radiance `intensity × rgb × alpha`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightCell {
    pub corners: [Vec3; 4],
    pub radiance: Vec3,
}

/// Splits the light into at most `E0_GRID`² texel-aligned cells with their mean radiance,
/// merges neighbours of identical radiance into larger rectangles and drops black ones.
/// The result integrates a piecewise-constant image exactly when every cell is uniform.
pub fn light_cells(light: &AreaLight, image: &LightImage) -> Vec<LightCell> {
    let gx = image.width.min(E0_GRID);
    let gy = image.height.min(E0_GRID);
    let col_edge = |k: u32| (k * image.width + gx / 2) / gx;
    let row_edge = |k: u32| (k * image.height + gy / 2) / gy;
    // Mean emission per grid cell.
    let mut grid = vec![Vec3::ZERO; (gx * gy) as usize];
    for cy in 0..gy {
        for cx in 0..gx {
            let (i0, i1, j0, j1) = (col_edge(cx), col_edge(cx + 1), row_edge(cy), row_edge(cy + 1));
            let mut sum = Vec3::ZERO;
            for j in j0..j1 {
                for i in i0..i1 {
                    sum += image.emission(i, j);
                }
            }
            grid[(cy * gx + cx) as usize] = sum / ((i1 - i0) * (j1 - j0)).max(1) as f32;
        }
    }
    // Runs of equal colour along each row, then runs of equal runs down the columns.
    let mut rects: Vec<(u32, u32, u32, u32, Vec3)> = Vec::new(); // (cx0, cx1, cy0, cy1, colour)
    for cy in 0..gy {
        let mut cx = 0;
        while cx < gx {
            let colour = grid[(cy * gx + cx) as usize];
            let mut end = cx + 1;
            while end < gx && grid[(cy * gx + end) as usize] == colour {
                end += 1;
            }
            match rects.iter_mut().find(|r| r.1 == end && r.0 == cx && r.3 == cy && r.4 == colour) {
                Some(rect) => rect.3 = cy + 1,
                None => rects.push((cx, end, cy, cy + 1, colour)),
            }
            cx = end;
        }
    }
    rects
        .into_iter()
        .filter(|r| r.4.max_element() > 0.0)
        .map(|(cx0, cx1, cy0, cy1, colour)| {
            let s0 = col_edge(cx0) as f32 / image.width as f32;
            let s1 = col_edge(cx1) as f32 / image.width as f32;
            let t0 = row_edge(cy0) as f32 / image.height as f32;
            let t1 = row_edge(cy1) as f32 / image.height as f32;
            // (s0,t1) bottom-left, (s1,t1) bottom-right, (s1,t0) top-right, (s0,t0) top-left:
            // counter-clockwise for a viewer on the lit side (right = +r, up = +u).
            LightCell {
                corners: [light.image_point(s0, t1), light.image_point(s1, t1), light.image_point(s1, t0), light.image_point(s0, t0)],
                radiance: colour * light.intensity,
            }
        })
        .collect()
}

/// The rectangle that bounds the light's cells, in the light's frame: its centre along `r`
/// and `u` from the light's centre and its half width and height, metres. A shaped light
/// (`flame`, `disk`) drops its black texels from the cells, so its cells can all lie on one
/// side of a receiver's horizon where the whole rectangle does not (`cells_horizon` in
/// `shaders/e0/`). The whole rectangle where there are no cells.
pub fn cells_bounds(light: &AreaLight, cells: &[LightCell]) -> [f32; 4] {
    let mut corners = cells.iter().flat_map(|c| c.corners).map(|p| light.plane_point(p));
    let Some(first) = corners.next() else {
        return [0.0, 0.0, 0.5 * light.size_m.x, 0.5 * light.size_m.y];
    };
    let (min, max) = corners.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
    let (centre, half) = (0.5 * (min + max), 0.5 * (max - min));
    [centre.x, centre.y, half.x, half.y]
}

/// Whether every segment within the light's rectangle subtends at most a right angle from
/// every point of the box `[min, max]` (`ACUTE_EDGES` in `shaders/common/light.wgsl`). A
/// segment subtends more only from inside the sphere on it as diameter (Thales), which lies
/// within half its length — at most half the light's diagonal — of the rectangle; the box's
/// distance to the rectangle is at least its distance to the centre less half the diagonal.
pub fn edges_acute_from(light: &AreaLight, min: Vec3, max: Vec3) -> bool {
    let half_diagonal = 0.5 * light.size_m.length();
    let nearest = light.center.clamp(min, max);
    // The margin keeps f32 rounding on the acute side of the bound.
    nearest.distance(light.center) > 2.0 * half_diagonal * (1.0 + 1e-3)
}

/// `∫ cosθx dω` over a polygon seen from `x` with normal `nx`, after clipping the polygon
/// to the hemisphere above x (Lambert's closed form for the vector irradiance: ½ Σ Θᵢ n·Γᵢ).
/// The CPU twin of `polygon_irradiance` in `shaders/common/light.wgsl`, clipped as it is
/// (`HORIZON_EPS` above the plane) but in f64 and with Θ from atan2: the yardstick the GPU's
/// f32 sums are measured against. In f32 its own rounding (`sin Θ` from the product of two
/// nearly parallel unit directions) would be as large as the error it is there to measure.
pub fn polygon_irradiance(x: DVec3, nx: DVec3, corners: &[DVec3; 4]) -> f64 {
    const HORIZON_EPS: f64 = 1e-6;
    let mut clipped: Vec<DVec3> = Vec::with_capacity(5);
    for k in 0..4 {
        let a = corners[k] - x;
        let b = corners[(k + 1) % 4] - x;
        let (da, db) = (a.dot(nx), b.dot(nx));
        if da > HORIZON_EPS {
            clipped.push(a);
        }
        if (da > HORIZON_EPS) != (db > HORIZON_EPS) {
            let t = (HORIZON_EPS - da) / (db - da);
            clipped.push(a + (b - a) * t);
        }
    }
    if clipped.len() < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    for k in 0..clipped.len() {
        let a = clipped[k].normalize();
        let b = clipped[(k + 1) % clipped.len()].normalize();
        let c = a.cross(b);
        let sin = c.length();
        if sin > 0.0 {
            sum += sin.atan2(a.dot(b)) * nx.dot(c / sin);
        }
    }
    0.5 * sum.abs()
}

/// The unshadowed irradiance E0 at x (contract §1), per channel: the sum over light cells,
/// each by `polygon_irradiance` (in f64).
pub fn unshadowed_irradiance(light: &AreaLight, cells: &[LightCell], x: DVec3, nx: DVec3) -> DVec3 {
    // One-sided emitter: only points on the lit side receive anything.
    if light.n.as_dvec3().dot(x - light.center.as_dvec3()) <= 0.0 {
        return DVec3::ZERO;
    }
    cells.iter().map(|c| c.radiance.as_dvec3() * polygon_irradiance(x, nx, &c.corners.map(|p| p.as_dvec3()))).sum()
}

#[cfg(test)]
mod tests {
    use glam::Vec2;
    use serde_json::Map;

    use super::*;

    fn overhead_light(size: f32) -> AreaLight {
        AreaLight::new(Vec3::new(0.0, 2.0, 0.0), -Vec3::Y, -Vec3::Z, Vec2::splat(size), 1.0).unwrap()
    }

    #[test]
    fn frame_follows_design() {
        let light = overhead_light(1.0);
        assert!((light.n - -Vec3::Y).length() < 1e-6);
        assert!((light.u - -Vec3::Z).length() < 1e-6);
        // r = cross(u, n) = cross(−z, −y) = −x.
        assert!((light.r - -Vec3::X).length() < 1e-6);
        // Column 0 (s = 0) is on the −r side, i.e. +x; row 0 (t = 0) on +u, i.e. −z.
        let top_left = light.image_point(0.0, 0.0);
        assert!((top_left - Vec3::new(0.5, 2.0, -0.5)).length() < 1e-6);
    }

    #[test]
    fn small_light_matches_point_source_law() {
        // A tiny square light straight above: E ≈ L·A·cosθx·cosθy / d².
        let light = overhead_light(0.01);
        let cells = light_cells(&light, &LightImage::builtin("white", &Map::new(), "f").unwrap());
        let e = unshadowed_irradiance(&light, &cells, DVec3::ZERO, DVec3::Y);
        let expected = 1e-4 / 4.0;
        assert!((e.x - expected).abs() / expected < 1e-3, "{e} vs {expected}");
    }

    #[test]
    fn large_light_tends_to_pi() {
        // An enormous light covers the whole hemisphere: ∫ cosθ dω = π.
        let light = overhead_light(1e4);
        let cells = light_cells(&light, &LightImage::builtin("white", &Map::new(), "f").unwrap());
        let e = unshadowed_irradiance(&light, &cells, DVec3::ZERO, DVec3::Y);
        assert!((e.x - std::f64::consts::PI).abs() < 1e-2, "{e}");
    }

    #[test]
    fn edges_are_acute_from_a_box_farther_than_the_lights_diagonal() {
        let light = AreaLight::new(Vec3::new(0.0, 2.0, 0.0), -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
        // Every segment between points of the rectangle, seen from every corner of the box and
        // from its point nearest the light: at most a right angle where the test says so.
        let widest = |min: Vec3, max: Vec3| {
            let mut points: Vec<Vec3> =
                (0..8).map(|k| Vec3::select(glam::BVec3::new(k & 1 != 0, k & 2 != 0, k & 4 != 0), max, min)).collect();
            points.push(light.center.clamp(min, max));
            let on_light: Vec<Vec3> = (0..=8)
                .flat_map(|i| (0..=8).map(move |j| (i as f32 / 8.0, j as f32 / 8.0)))
                .map(|(s, t)| light.image_point(s, t))
                .collect();
            let mut cos_min = 1.0f32;
            for x in &points {
                for a in &on_light {
                    for b in &on_light {
                        if a != b {
                            cos_min = cos_min.min((*a - *x).normalize().dot((*b - *x).normalize()));
                        }
                    }
                }
            }
            cos_min
        };
        let far = (Vec3::new(-5.0, -3.0, -5.0), Vec3::new(5.0, -0.3, 5.0));
        assert!(edges_acute_from(&light, far.0, far.1));
        assert!(widest(far.0, far.1) >= 0.0);
        // Just under the light: its long edges subtend obtuse angles, and the test says so.
        let near = (Vec3::new(-5.0, -3.0, -5.0), Vec3::new(5.0, 1.8, 5.0));
        assert!(!edges_acute_from(&light, near.0, near.1));
        assert!(widest(near.0, near.1) < 0.0);
    }

    #[test]
    fn horizon_clipping_agrees_with_quadrature() {
        // A receiver tilted so that the light straddles its horizon.
        let light = overhead_light(2.0);
        let cells = light_cells(&light, &LightImage::builtin("white", &Map::new(), "f").unwrap());
        let x = Vec3::new(0.3, 0.0, 0.1);
        let nx = Vec3::new(1.0, 0.3, 0.0).normalize();
        let analytic = unshadowed_irradiance(&light, &cells, x.as_dvec3(), nx.as_dvec3()).x as f32;
        // Midpoint quadrature of ∫ cosθx cosθy / d² dA.
        let n = 400;
        let mut sum = 0.0f64;
        for j in 0..n {
            for i in 0..n {
                let y = light.image_point((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                let d = y - x;
                let cx = nx.dot(d.normalize()).max(0.0);
                let cy = light.n.dot(-d.normalize()).max(0.0);
                sum += f64::from(cx * cy / d.length_squared());
            }
        }
        let numeric = sum as f32 * light.area_m2() / (n * n) as f32;
        assert!((analytic - numeric).abs() / numeric < 2e-3, "{analytic} vs {numeric}");
    }

    #[test]
    fn cells_merge_uniform_regions_and_drop_black() {
        let light = overhead_light(1.0);
        let none = Map::new();
        assert_eq!(light_cells(&light, &LightImage::builtin("white", &none, "f").unwrap()).len(), 1);
        assert_eq!(light_cells(&light, &LightImage::builtin("stripes", &none, "f").unwrap()).len(), 6);
        // `mosaic`: no two panes alike, so every cell of the grid stays: the most E0 sums.
        assert_eq!(light_cells(&light, &LightImage::builtin("mosaic", &none, "f").unwrap()).len(), (E0_GRID * E0_GRID) as usize);
        let disk = light_cells(&light, &LightImage::builtin("disk", &none, "f").unwrap());
        assert!(disk.len() < 64 && !disk.is_empty());
        // Total flux is preserved by merging: Σ radiance × area equals the image mean × area.
        let image = LightImage::builtin("flame", &none, "f").unwrap();
        let cells = light_cells(&light, &image);
        let flux: Vec3 =
            cells.iter().map(|c| c.radiance * (c.corners[1] - c.corners[0]).length() * (c.corners[3] - c.corners[0]).length()).sum();
        assert!((flux - image.mean_emission()).length() < 1e-4, "{flux} vs {}", image.mean_emission());
    }

    /// What E0's grid sums read of a light of `E0_GRID`² cells (`shaders/e0/grid.wgsl`): the
    /// cells row by row from the image's top, left to right, each sharing its right edge with
    /// the next and its bottom edge with the one below.
    #[test]
    fn a_full_grid_of_cells_comes_row_by_row_from_the_top() {
        let light = AreaLight::new(Vec3::new(1.0, 3.0, -2.0), Vec3::new(0.2, -1.0, 0.1), -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
        let cells = light_cells(&light, &LightImage::builtin("mosaic", &Map::new(), "f").unwrap());
        let side = E0_GRID as usize;
        assert_eq!(cells.len(), side * side);
        let cell = |row: usize, column: usize| cells[row * side + column].corners;
        // Corners: bottom-left, bottom-right, top-right, top-left; the image's top is +u.
        assert!(cell(0, 0)[3].distance(light.image_point(0.0, 0.0)) < 1e-6);
        assert!(cell(side - 1, side - 1)[1].distance(light.image_point(1.0, 1.0)) < 1e-6);
        for row in 0..side {
            for column in 0..side {
                let [bottom_left, bottom_right, top_right, _] = cell(row, column);
                if column + 1 < side {
                    assert_eq!([bottom_right, top_right], [cell(row, column + 1)[0], cell(row, column + 1)[3]], "({row}, {column})");
                }
                if row + 1 < side {
                    assert_eq!([bottom_left, bottom_right], [cell(row + 1, column)[3], cell(row + 1, column)[2]], "({row}, {column})");
                }
            }
        }
    }

    #[test]
    fn the_cells_bounds_hold_every_cell_and_no_more() {
        let light = AreaLight::new(Vec3::new(1.0, 3.0, -2.0), -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
        let none = Map::new();
        let bounds = |name: &str| cells_bounds(&light, &light_cells(&light, &LightImage::builtin(name, &none, "f").unwrap()));
        // A light with no black texels: its whole rectangle.
        for name in ["white", "stripes"] {
            let [cx, cy, hx, hy] = bounds(name);
            assert!(cx.abs() < 1e-5 && cy.abs() < 1e-5 && (hx - 1.0).abs() < 1e-5 && (hy - 0.5).abs() < 1e-5, "{name}");
        }
        // The flame: the outer columns of its cell grid (`E0_GRID`) are black, its tip and its
        // base are not: a quarter narrower than the light, as tall, centred.
        let cells = light_cells(&light, &LightImage::builtin("flame", &none, "f").unwrap());
        let [cx, cy, hx, hy] = cells_bounds(&light, &cells);
        assert!(cx.abs() < 1e-5 && cy.abs() < 1e-5 && (hx - 0.75).abs() < 1e-5 && (hy - 0.5).abs() < 1e-5, "{cx} {cy} {hx} {hy}");
        for cell in cells {
            for p in cell.corners {
                let q = p - light.center;
                assert!((q.dot(light.r) - cx).abs() <= hx + 1e-5 && (q.dot(light.u) - cy).abs() <= hy + 1e-5);
            }
        }
        // No cells (a black light): the whole rectangle.
        assert_eq!(cells_bounds(&light, &[]), [0.0, 0.0, 1.0, 0.5]);
    }

    #[test]
    fn stripes_are_red_on_the_minus_r_side() {
        // contract §1: column 0 along −r. The first stripe is red, so the receiver point
        // under the −r edge of the light gets more red than blue, and the +r edge the reverse.
        let light = overhead_light(1.0);
        let cells = light_cells(&light, &LightImage::builtin("stripes", &Map::new(), "f").unwrap());
        let under = |side: f32| unshadowed_irradiance(&light, &cells, (light.r * side * 0.8).as_dvec3(), DVec3::Y);
        let (under_minus_r, under_plus_r) = (under(-1.0), under(1.0));
        assert!(under_minus_r.x > under_minus_r.z);
        assert!(under_plus_r.z > under_plus_r.x);
    }

    #[test]
    fn degenerate_lights_name_the_field() {
        let err = AreaLight::new(Vec3::ZERO, Vec3::ZERO, Vec3::Y, Vec2::ONE, 1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.direction"));
        let err = AreaLight::new(Vec3::ZERO, Vec3::Y, Vec3::Y, Vec2::ONE, 1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.up"));
        let err = AreaLight::new(Vec3::ZERO, Vec3::Y, Vec3::X, Vec2::new(1.0, 0.0), 1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.size[1]"));
        let err = AreaLight::new(Vec3::ZERO, Vec3::Y, Vec3::X, Vec2::ONE, -1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.intensity"));
    }
}
