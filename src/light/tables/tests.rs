//! Unit tests of `tables`.

use super::*;
use glam::Vec3;

fn light(size: Vec2) -> AreaLight {
    AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, size, 1.0).unwrap()
}

fn sector(table: &[[f32; 4]], i: u32, j: u32) -> [f32; 4] {
    table[(i * SECTOR_STATIONS + j) as usize]
}

#[test]
fn sector_table_integrates_the_image() {
    // A full turn out to the edge holds the whole light: its emission per channel, and
    // its area.
    let light = light(Vec2::new(1.6, 0.9));
    let last = SECTOR_STATIONS - 1;
    for name in ["white", "stripes", "flame", "quadrants"] {
        let image = LightImage::builtin(name, &Default::default(), "f").unwrap();
        let table = sector_table(&light, &image);
        let turn = sector(&table, SECTOR_ANGLES, 0);
        let total = image.mean_emission() * light.area_m2();
        for k in 0..3 {
            assert!((turn[k] - total[k]).abs() <= 0.002 * total.max_element(), "{name} channel {k}: {} vs {}", turn[k], total[k]);
        }
        assert!((turn[3] - light.area_m2()).abs() < 0.002 * light.area_m2(), "{name}: area {}", turn[3]);
        // The second turn repeats the first.
        let twice = sector(&table, 2 * SECTOR_ANGLES, 0);
        // Nothing lies beyond the edge.
        assert!(sector(&table, SECTOR_ANGLES, last).iter().all(|&v| v.abs() < 1e-6), "{name}");
        assert!((twice[0] - 2.0 * turn[0]).abs() < 1e-3 * turn[0].max(1e-3));
    }
    // `quadrants`: the first quarter turn (x > 0, y > 0: right of the centre, towards the
    // image's top) is the top-right quadrant, green only; the second the red top-left.
    let image = LightImage::builtin("quadrants", &Default::default(), "f").unwrap();
    let table = sector_table(&light, &image);
    let quarter = light.area_m2() / 4.0;
    let first = sector(&table, SECTOR_ANGLES / 4, 0);
    assert!(first[0] < 1e-6 && (first[1] - quarter).abs() < 1e-3 && first[2] < 1e-6, "{first:?}");
    let second = sector(&table, SECTOR_ANGLES / 2, 0);
    assert!((second[0] - first[0] - quarter).abs() < 1e-3 && (second[1] - first[1]).abs() < 1e-6, "{second:?}");
    // Beyond halfway out, three quarters of the area: 1 − (1/2)² of the quarter.
    let outer = sector(&table, SECTOR_ANGLES / 4, last / 2);
    let s = (last / 2) as f32 / last as f32;
    assert!((outer[3] - (1.0 - s * s) * quarter).abs() < 1e-3, "{outer:?}");
}

#[test]
fn the_emitting_octagon_holds_every_emitting_texel_and_the_centre() {
    let light = light(Vec2::new(1.6, 0.9));
    let half = light.size_m * 0.5;
    let rectangle = ([-half.x, -half.y, -half.x - half.y, -half.x - half.y], [half.x, half.y, half.x + half.y, half.x + half.y]);
    let builtin = |name| LightImage::builtin(name, &Default::default(), "f").unwrap();
    // Lights that emit everywhere: the rectangle's own octagon.
    for name in ["white", "stripes", "quadrants"] {
        let (lo, hi) = emitting_octagon(&light, &builtin(name));
        for k in 0..4 {
            assert!((lo[k] - rectangle.0[k]).abs() < 1e-6 && (hi[k] - rectangle.1[k]).abs() < 1e-6, "{name} axis {k}: {lo:?} {hi:?}");
        }
    }
    // The flame's black corners are cut off, and every texel that emits stays inside.
    let flame = builtin("flame");
    let (lo, hi) = emitting_octagon(&light, &flame);
    assert!((0..4).all(|k| lo[k] < 0.0 && hi[k] > 0.0), "the centre: {lo:?} {hi:?}");
    assert!(hi[2] < 0.9 * rectangle.1[2] && lo[3] > 0.9 * rectangle.0[3], "corners kept: {lo:?} {hi:?}");
    for j in 0..flame.height {
        for i in 0..flame.width {
            if flame.emission(i, j).max_element() > 0.0 {
                let c = local(&light, (i as f32 + 0.5) / flame.width as f32, (j as f32 + 0.5) / flame.height as f32);
                let v = [c.x, c.y, c.x + c.y, c.x - c.y];
                assert!((0..4).all(|k| lo[k] <= v[k] && v[k] <= hi[k]), "texel ({i}, {j}) outside");
            }
        }
    }
    // Only a corner emits: the centre lies outside its octagon, so the rectangle's is kept
    // (a wedge's region is a sector from the centre: the test needs the centre inside).
    let corner = LightImage::from_fn(4, 4, |s, t| if s < 0.25 && t < 0.25 { [1.0; 4] } else { [0.0; 4] });
    assert_eq!(emitting_octagon(&light, &corner), rectangle);
}

#[test]
fn uniform_images_are_recognised() {
    let builtin = |name| LightImage::builtin(name, &Default::default(), "f").unwrap();
    assert!(builtin("white").is_uniform());
    for name in ["disk", "star", "stripes", "flame", "quadrants", "mosaic"] {
        assert!(!builtin(name).is_uniform(), "{name}");
    }
}

fn edge(table: &[[f32; 4]], i: u32, j: u32) -> [f32; 4] {
    table[(i * EDGE_STATIONS + j) as usize]
}

#[test]
fn edge_table_fractions_match_direct_summation() {
    // A uniform light: along +x (row 0) the centre's side of the line at x = s·w/2 holds
    // (1 + s)/2 of the light; along −x (row 128) the same, mirrored.
    let uniform = light(Vec2::new(2.0, 1.0));
    let white = edge_table(&uniform, &LightImage::builtin("white", &Default::default(), "f").unwrap());
    for j in [0, 10, 32, 63] {
        let s = j as f32 / (EDGE_STATIONS - 1) as f32;
        for i in [0, EDGE_ANGLES / 2] {
            let got = edge(&white, i, j);
            assert!((got[0] - (1.0 + s) / 2.0).abs() < 0.01 && (got[3] - got[0]).abs() < 1e-6, "row {i} station {j}: {got:?}");
        }
    }
    // `stripes`: along +x a line near the right edge cuts off a sliver of magenta only,
    // keeping all the green; along −x a line near the left edge cuts into the red band,
    // keeping all the blue. Red, direct: red, yellow and magenta emit it ([0, 2/6] and
    // [5/6, 1] of the width); the line at 60/63 of the way along −x leaves image s > s_line.
    let wide = light(Vec2::new(3.0, 1.0));
    let table = edge_table(&wide, &LightImage::builtin("stripes", &Default::default(), "f").unwrap());
    let right = edge(&table, 0, 60);
    let left = edge(&table, EDGE_ANGLES / 2, 60);
    assert!(right[1] > 0.999 && right[2] < 0.99, "green kept, magenta cut on the right: {right:?}");
    assert!(left[0] < 0.97 && left[2] > 0.999, "red cut, blue kept on the left: {left:?}");
    let s_line = 0.5 - 0.5 * 60.0 / 63.0; // image s of the line
    let red_total = 3.0 / 6.0;
    let red_visible = (2.0 / 6.0 - s_line) + 1.0 / 6.0;
    assert!((left[0] - red_visible / red_total).abs() < 0.01, "{} vs {}", left[0], red_visible / red_total);
}

#[test]
fn the_key_table_samples_the_edge_tables_luminance_on_a_grid() {
    let wide = light(Vec2::new(3.0, 1.0));
    let half = wide.size_m * 0.5;
    let image = LightImage::builtin("flame", &Default::default(), "f").unwrap();
    let table = edge_table(&wide, &image);
    let keys = key_table(&wide, &table);
    assert_eq!(keys.len() as u32, KEY_CELLS * KEY_CELLS);
    let polar = |q: Vec2| edge_lookup(&table, half, q).truncate().dot(LUMINANCE);
    // A grid point's key is the polar look-up there; the four corners of a cell are its
    // neighbours' shared corners.
    let point = |i: u32, j: u32| (Vec2::new(i as f32, j as f32) / KEY_CELLS as f32 - Vec2::splat(0.5)) * wide.size_m;
    for (i, j) in [(0, 0), (7, 30), (KEY_CELLS - 1, 12), (100, KEY_CELLS - 1), (64, 64)] {
        let cell = keys[(j * KEY_CELLS + i) as usize];
        assert_eq!(cell[0], polar(point(i, j)), "cell ({i}, {j})");
        assert_eq!(cell[3], polar(point(i + 1, j + 1)), "cell ({i}, {j})");
        if i + 1 < KEY_CELLS {
            assert_eq!(cell[1], keys[(j * KEY_CELLS + i + 1) as usize][0]);
        }
    }
    // Between grid points the bilinear blend stays close to the polar look-up (measured:
    // 1e-4 on average), except within a few cells of the centre, where the line's
    // direction turns with the point's.
    let blend = |q: Vec2| {
        let g = ((q / wide.size_m + Vec2::splat(0.5)) * KEY_CELLS as f32).clamp(Vec2::ZERO, Vec2::splat(KEY_CELLS as f32));
        let (i, j) = ((g.x as u32).min(KEY_CELLS - 1), (g.y as u32).min(KEY_CELLS - 1));
        let f = g - Vec2::new(i as f32, j as f32);
        let c = keys[(j * KEY_CELLS + i) as usize];
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        lerp(lerp(c[0], c[1], f.x), lerp(c[2], c[3], f.x), f.y)
    };
    let (mut worst, mut total, mut count) = (0.0f32, 0.0, 0);
    for j in 0..97 {
        for i in 0..97 {
            let q = (Vec2::new(i as f32 + 0.31, j as f32 + 0.77) / 97.0 - Vec2::splat(0.5)) * wide.size_m;
            let departure = (blend(q) - polar(q)).abs();
            total += departure;
            count += 1;
            if (q / wide.size_m * KEY_CELLS as f32).length() > 8.0 {
                worst = worst.max(departure);
            }
        }
    }
    assert!(total / (count as f32) < 5e-4, "mean departure {}", total / count as f32);
    assert!(worst < 0.01, "worst departure beyond 8 cells of the centre {worst}");
    // Rec. 709's weights sum to 1: under a white light the key is the fraction itself, and
    // the far side's luminance is 1 minus the near side's (what the keys rely on).
    assert!((LUMINANCE.element_sum() - 1.0).abs() < 1e-6);
    let white = LightImage::builtin("white", &Default::default(), "f").unwrap();
    let table = edge_table(&wide, &white);
    let q = Vec2::new(0.9, -0.2);
    assert!((edge_lookup(&table, half, q).truncate().dot(LUMINANCE) - edge_lookup(&table, half, q).x).abs() < 1e-6);
}

#[test]
fn edge_table_follows_the_image_orientation() {
    // `quadrants`: red top-left, green top-right, blue bottom-left, yellow bottom-right.
    // The line along +u (row 64, φ = π/2) close to the top edge keeps all the bottom half
    // (blue, yellow) and cuts off a sliver of the top (red, green).
    let light = light(Vec2::new(1.0, 1.0));
    let table = edge_table(&light, &LightImage::builtin("quadrants", &Default::default(), "f").unwrap());
    let up = edge(&table, EDGE_ANGLES / 4, 56);
    assert!(up[2] > 0.999, "blue lies below: {up:?}");
    // The white twin is the uniform square: the same share of it as of the red.
    assert!((up[3] - up[0]).abs() < 1e-6, "{up:?}");
    // Red: the top-left quadrant (all its red) plus the yellow bottom-right; the line keeps
    // the top quadrant's lower 56/63 and all the yellow: (56/63 + 1)/2.
    assert!((up[0] - (56.0 / 63.0 + 1.0) / 2.0).abs() < 0.01, "{up:?}");
    // Along +r near the right edge: green (top-right, and in the yellow) loses a sliver; blue none.
    let right = edge(&table, 0, 56);
    assert!(right[2] > 0.999 && right[1] < 0.95, "{right:?}");
}
