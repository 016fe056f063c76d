//! Unit tests of `cpu`.

use glam::Vec4;

use super::raster::{clip_near, round_to_i64, SUBTEXEL};
use super::*;

/// A map of `size`² texels with nothing drawn.
fn blank(size: u32) -> Map {
    Map::with_depths(UVec2::splat(size), vec![0.0; (size * size) as usize])
}

/// One triangle of `positions` (its first three) as a map's geometry.
fn one_triangle(positions: &[Vec3]) -> Geometry<'_> {
    #[allow(clippy::single_range_in_vec_init)] // A list of runs that holds one.
    const RUNS: &[Range<u32>] = &[0..3];
    Geometry { positions, indices: &[0, 1, 2], runs: RUNS }
}

/// Clip coordinates of the point at texel coordinates (x, y) (right and down from the
/// map's top-left corner) and depth z, for a map of `size`² texels.
fn at(x: f32, y: f32, z: f32, size: u32) -> Vec4 {
    let s = size as f32;
    Vec4::new(2.0 * x / s - 1.0, 1.0 - 2.0 * y / s, z, 1.0)
}

/// A repeatable stream of numbers in [0, 1] (xorshift32 from `seed`).
fn xorshift(mut state: u32) -> impl FnMut() -> f32 {
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    }
}

fn covered(map: &Map) -> Vec<(u32, u32)> {
    (0..map.size.y)
        .flat_map(|y| (0..map.size.x).map(move |x| (x, y)))
        .filter(|&(x, y)| map.depths[(y * map.size.x + x) as usize] > 0.0)
        .collect()
}

#[test]
fn texels_on_an_edge_go_to_the_top_and_left_only_and_shared_edges_cover_once() {
    // A square whose edges run through texel centres (x and y 2.5 … 6.5), split along
    // its diagonal, which runs through centres too: Vulkan's top-left rule gives the left
    // column and the top row to the square and the right column and bottom row to its
    // neighbours, and every centre on the diagonal to one of the halves.
    let size = 10;
    let [a, b, c, d] = [(2.5, 2.5), (6.5, 2.5), (6.5, 6.5), (2.5, 6.5)].map(|(x, y)| at(x, y, 0.5, size));
    let (mut upper, mut lower) = (blank(size), blank(size));
    upper.triangle([a, b, c]);
    lower.triangle([a, c, d]);
    let (upper, lower) = (covered(&upper), covered(&lower));
    let mut both: Vec<_> = upper.iter().chain(&lower).copied().collect();
    both.sort();
    let square: Vec<(u32, u32)> = (2..6).flat_map(|y| (2..6).map(move |x| (x, y))).collect();
    let mut expected = square.clone();
    expected.sort();
    assert_eq!(both, expected, "upper {upper:?}, lower {lower:?}");
    // Either winding draws the same texels: both faces cast shadows.
    let mut reversed = blank(size);
    reversed.triangle([a, c, b]);
    assert_eq!(covered(&reversed), upper);
}

#[test]
fn rows_solved_for_their_span_cover_what_testing_every_texel_covers() {
    let size = 64;
    let mut random = xorshift(0x9e37_79b9);
    let mut drawn = 0;
    for k in 0..400 {
        // Large and small triangles, some reaching past the map, some with vertices on
        // texel centres (ties for the top-left rule).
        let reach = if k % 2 == 0 { 80.0 } else { 12.0 };
        let corner = |r: &mut dyn FnMut() -> f32| {
            let (x, y) = (r() * reach - 8.0, r() * reach - 8.0);
            if k % 3 == 0 {
                (x.floor() + 0.5, y.floor() + 0.5)
            } else {
                (x, y)
            }
        };
        let [a, b, c] = [0; 3].map(|_| corner(&mut random));
        let screen = [a, b, c].map(|(x, y)| Vec3::new(x, y, 0.1 + 0.8 * (x + y) / 200.0));
        // One triangle a map: the nearest depth of another would hide a texel's difference.
        let (mut spans, mut texels) = (blank(size), blank(size));
        let fixed = screen.map(|s| [round_to_i64(s.x * SUBTEXEL), round_to_i64(s.y * SUBTEXEL)]);
        spans.fixed_spans_from(screen, fixed, 0);
        texels.fixed_spans_from(screen, fixed, i64::MAX);
        assert!(spans.depths == texels.depths, "triangle {k} {screen:?}: the two ways draw different texels");
        drawn += covered(&spans).len();
    }
    assert!(drawn > 10_000, "{drawn} texels drawn");
}

#[test]
fn depth_is_affine_across_the_map_and_the_nearest_surface_is_kept() {
    let size = 16;
    let mut map = blank(size);
    // A plane tilted in x: depth 0.2 at x = 0 to 0.6 at x = 16, over the whole map.
    let z = |x: f32| 0.2 + 0.4 * x / 16.0;
    let corners = [(0.0, 0.0), (16.0, 0.0), (16.0, 16.0), (0.0, 16.0)].map(|(x, y)| at(x, y, z(x), size));
    map.triangle([corners[0], corners[1], corners[2]]);
    map.triangle([corners[0], corners[2], corners[3]]);
    // A nearer square (larger reversed depth) over part of it; a farther one, hidden.
    let near = [(4.0, 4.0), (8.0, 4.0), (8.0, 8.0), (4.0, 8.0)].map(|(x, y)| at(x, y, 0.9, size));
    let far = [(10.0, 10.0), (14.0, 10.0), (14.0, 14.0), (10.0, 14.0)].map(|(x, y)| at(x, y, 0.1, size));
    for quad in [near, far] {
        map.triangle([quad[0], quad[1], quad[2]]);
        map.triangle([quad[0], quad[2], quad[3]]);
    }
    for y in 0..size {
        for x in 0..size {
            let stored = map.depths[(y * size + x) as usize];
            let expected = if (4..8).contains(&x) && (4..8).contains(&y) { 0.9 } else { z(x as f32 + 0.5) };
            assert!((stored - expected).abs() < 1e-6, "texel ({x}, {y}): {stored} against {expected}");
        }
    }
}

#[test]
fn a_triangle_through_the_near_plane_is_drawn_in_front_of_it_only() {
    // Clip z is the near plane (0.1) and w the view depth: one vertex at depth 0.05 lies
    // behind it. What is left is a quadrilateral whose vertices all lie in front of it.
    let near = 0.1;
    let vertices = [Vec4::new(-0.5, -0.5, near, 1.0), Vec4::new(0.5, -0.5, near, 1.0), Vec4::new(0.0, 0.02, near, 0.05)];
    let polygon = clip_near(vertices);
    assert_eq!(polygon.len(), 4);
    assert!(polygon.iter().all(|v| v.w >= v.z - 1e-7), "{polygon:?}");
    // Through a map's own projection: a triangle reaching behind the sample (view z > 0)
    // is drawn where it lies in front of the near plane, every depth within (0, 1].
    let view_proj = Mat4::perspective_infinite_reverse_rh(90f32.to_radians(), 1.0, near);
    let sample = CpuSample { view_proj, origin: [0.0; 2], texels_per_tan: 1.0, crop_origin: Some(UVec2::ZERO), weight: Vec3::ONE };
    let mut map = blank(32);
    map.draw(&sample, one_triangle(&[Vec3::new(-1.0, -0.5, -1.0), Vec3::new(1.0, -0.5, -1.0), Vec3::new(0.0, -0.5, 0.5)]));
    let drawn = covered(&map);
    assert!(drawn.len() > 50, "{} texels", drawn.len());
    assert!(map.depths.iter().all(|&d| (0.0..=1.0).contains(&d)), "depths within the clip volume");
    // Entirely behind it: nothing.
    let mut map = blank(32);
    map.draw(&sample, one_triangle(&[Vec3::new(-1.0, -0.5, 1.0), Vec3::new(1.0, -0.5, 1.0), Vec3::new(0.0, 0.5, 0.5)]));
    assert!(covered(&map).is_empty());
}

#[test]
fn small_triangles_drawn_eight_texels_at_a_time_match_the_scalar_code_bit_for_bit() {
    if !has_avx2() {
        return; // Nothing to compare: the scalar code draws everything.
    }
    let size = 64;
    let mut random = xorshift(0x2545_f491);
    let (mut fast, mut scalar) = (blank(size), blank(size).scalar());
    for k in 0..2000 {
        // Boxes of one to ten texels, some at the map's edges, some with corners on texel
        // centres (ties for the top-left rule); many drawn over one another.
        let (cx, cy) = (random() * 72.0 - 4.0, random() * 72.0 - 4.0);
        let spread = 1.0 + 9.0 * random();
        let corner = |r: &mut dyn FnMut() -> f32| {
            let (x, y) = (cx + (r() - 0.5) * spread, cy + (r() - 0.5) * spread);
            if k % 3 == 0 {
                (x.floor() + 0.5, y.floor() + 0.5)
            } else {
                (x, y)
            }
        };
        let [a, b, c] = [0; 3].map(|_| corner(&mut random));
        let depth = 0.1 + 0.8 * random();
        let screen = [a, b, c].map(|(x, y)| Vec3::new(x, y, depth + 0.01 * (x - y)));
        let fixed = screen.map(|s| [round_to_i64(s.x * SUBTEXEL), round_to_i64(s.y * SUBTEXEL)]);
        fast.fixed_spans_from(screen, fixed, 8);
        scalar.fixed_spans_from(screen, fixed, 8);
    }
    assert!(covered(&fast).len() > 1000, "{} texels drawn", covered(&fast).len());
    let bits = |map: &Map| map.depths.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
    assert!(bits(&fast) == bits(&scalar), "the two ways draw different depths");
}

#[test]
fn a_map_drawn_again_holds_only_its_new_triangles() {
    // A map is cleared where its last drawing wrote, not whole: drawn over a large triangle,
    // then over a small one elsewhere, it holds what a new map holds.
    let view_proj = Mat4::perspective_infinite_reverse_rh(90f32.to_radians(), 1.0, 0.1);
    let sample = CpuSample { view_proj, origin: [0.0; 2], texels_per_tan: 1.0, crop_origin: Some(UVec2::ZERO), weight: Vec3::ONE };
    let large = [Vec3::new(-3.0, -3.0, -1.0), Vec3::new(3.0, -2.0, -1.0), Vec3::new(0.0, 3.0, -1.5)];
    let small = [Vec3::new(0.5, 0.5, -1.0), Vec3::new(0.9, 0.5, -1.0), Vec3::new(0.7, 0.9, -1.2)];
    let mut reused = Map::new(UVec2::splat(64));
    reused.draw(&sample, one_triangle(&large));
    assert!(covered(&reused).len() > 64 * 64 / 2, "{} texels", covered(&reused).len());
    reused.draw(&sample, one_triangle(&small));
    let mut fresh = Map::new(UVec2::splat(64));
    fresh.draw(&sample, one_triangle(&small));
    assert!(!covered(&fresh).is_empty());
    assert_eq!(reused.depths, fresh.depths);
}

#[test]
fn the_avx2_tests_match_the_scalar_ones_bit_for_bit() {
    if !has_avx2() {
        return;
    }
    let size = 64u32;
    let mut map = blank(size);
    let mut random = xorshift(0x1234_5678);
    for texel in &mut map.depths {
        *texel = if random() < 0.3 { 0.0 } else { random() };
    }
    let mut block = ReceiverBlock::default();
    for l in 0..LANES {
        block.x[l] = random() * 4.0 - 2.0;
        block.y[l] = random() * 4.0 - 2.0;
        block.nx[l] = random() - 0.5;
        block.ny[l] = random() - 0.5;
        let depth = if l == 7 { 0.0 } else { 0.5 + 3.0 * random() };
        block.depth[l] = depth;
        block.n_dot_z[l] = -0.7 * depth;
        block.bias[l] = 1.0 + random();
    }
    let constants = TestConstants {
        rotation: Mat4::IDENTITY,
        plane: 0.0,
        near: 0.3,
        resolution: size,
        bias_texels: 1.0,
        slope_bias_texels: 1.0,
        light_center: Vec3::ZERO,
    };
    for (k, crop) in [(20.0, None), (35.0, Some(UVec2::new(3, 5))), (8.0, Some(UVec2::ZERO))] {
        for empty in [false, true] {
            map.empty = empty;
            let sample = CpuSample {
                view_proj: Mat4::IDENTITY,
                origin: [random() - 0.5, random() - 0.5],
                texels_per_tan: k,
                crop_origin: crop.or(Some(UVec2::ZERO)),
                weight: Vec3::new(0.3, 0.5, 0.9),
            };
            let test = SampleTest::new(&map, &sample, &constants);
            // A block's sums of three channels: Σ L·G·V of each, then Σ L·G of each.
            let (mut scalar, mut vector) = ([[0.0f32; LANES]; 6], [[0.0f32; LANES]; 6]);
            let (mut scalar_met, mut vector_met) = (BlockerBlock::default(), BlockerBlock::default());
            for _ in 0..3 {
                scalar_add_sample::<true>(&block, &mut scalar, &mut scalar_met, &test, 3);
                // Safety: checked above.
                #[cfg(target_arch = "x86_64")]
                unsafe {
                    avx2::add_sample::<true>(&block, &mut vector, &mut vector_met, &test, 3)
                };
            }
            for c in 0..3 {
                for l in 0..LANES {
                    assert_eq!(scalar[c][l].to_bits(), vector[c][l].to_bits(), "shadowed, lane {l}");
                    assert_eq!(scalar[3 + c][l].to_bits(), vector[3 + c][l].to_bits(), "unshadowed, lane {l}");
                }
            }
            // The blockers met (method `filtered`), alike to the bit.
            for l in 0..LANES {
                assert_eq!(scalar_met.count[l], vector_met.count[l], "blockers, lane {l}");
                assert_eq!(scalar_met.depth_sum[l].to_bits(), vector_met.depth_sum[l].to_bits(), "blocker depths, lane {l}");
            }
            if !empty {
                assert!(scalar_met.count.iter().any(|&c| c > 0.0), "some lane meets a blocker");
            }
            assert!(scalar[3][..7].iter().any(|&u| u > 0.0), "some lane faces the sample");
            assert_eq!(scalar[3][7], 0.0, "a lane at depth 0 has no weight");
        }
    }
}

#[test]
fn snapping_rounds_as_f32_round_does() {
    let mut next = xorshift(7);
    let special = [0.5, -0.5, 1.5, -1.5, 2.5, 0.49999997, -0.49999997, 0.0, -0.0, 8_388_607.5, 262_143.5, -1e9];
    let range = super::raster::FIXED_RANGE * super::raster::SUBTEXEL;
    let random = (0..100_000).map(|_| (next() - 0.5) * 2.0 * range);
    for v in special.into_iter().chain(random) {
        assert_eq!(super::raster::round_to_i64(v), v.round() as i64, "{v}");
    }
}

/// A floor (y = 0) under a square light at y = 5 facing down, a triangle between them at y =
/// 1 (its vertices), and pixels with no surface here and there, `width` × `height` of them;
/// three samples of the light with maps of `resolution`² texels.
fn floor_under_a_triangle(width: u32, height: u32, resolution: u32) -> (Surfaces, TestConstants, Vec<CpuSample>, [Vec3; 3]) {
    let surfaces = Surfaces::from_fn(width, height, |x, y| {
        let position = Vec3::new(4.0 * x as f32 / width as f32 - 2.0, 0.0, 4.0 * y as f32 / height as f32 - 2.0);
        (position, if (x * 7 + y * 3) % 11 == 0 { Vec3::ZERO } else { Vec3::Y })
    });
    let rotation = Mat4::look_to_rh(Vec3::ZERO, -Vec3::Y, Vec3::Z);
    let center = Vec3::new(0.0, 5.0, 0.0);
    let near = 0.5f32;
    let constants = TestConstants {
        rotation,
        plane: rotation.transform_point3(center).z,
        near,
        resolution,
        bias_texels: 1.0,
        slope_bias_texels: 1.0,
        light_center: center,
    };
    let projection = super::super::samples::reversed_projection(1.0, near);
    let samples: Vec<CpuSample> = [(-0.3, -0.2), (0.25, 0.1), (0.0, 0.3)]
        .into_iter()
        .map(|(dx, dz)| {
            let position = center + Vec3::new(dx, 0.0, dz);
            let view = rotation.transform_point3(position);
            CpuSample {
                view_proj: projection * rotation * Mat4::from_translation(-position),
                origin: [view.x, view.y],
                texels_per_tan: projection.y_axis.y * resolution as f32 * 0.5,
                crop_origin: Some(UVec2::ZERO),
                weight: Vec3::new(0.2, 0.5, 0.8),
            }
        })
        .collect();
    let positions = [Vec3::new(-1.0, 1.0, -1.0), Vec3::new(1.5, 1.0, -0.5), Vec3::new(0.0, 1.0, 1.5)];
    (surfaces, constants, samples, positions)
}

#[test]
fn receivers_made_a_task_at_a_time_sum_as_the_whole_frame_s_do() {
    // Enough pixels for several waves of tasks.
    let resolution = 64;
    let (surfaces, constants, samples, positions) = floor_under_a_triangle(240, 160, resolution);
    let geometry = one_triangle(&positions);
    let crop = UVec2::splat(resolution);
    let (pixels, segments) = covered_pixels(&surfaces, 16, |_, _| true);
    assert!(pixels.len() > 8 * BLOCKS_PER_TASK * LANES, "several tasks");
    let receivers = Receivers::of_list(&surfaces, pixels.clone(), segments, &constants);
    let (sums, met, _) = estimate_with::<true>(&receivers, &samples, &constants, geometry, 3, &mut Maps::new(crop), |_| true);
    let mut seen = 0;
    estimate_tiled(&surfaces, &pixels, &samples, &constants, geometry, 3, &mut Maps::new(crop), |task_pixels, task_sums, task_met| {
        assert_eq!(task_pixels, &pixels[seen..seen + task_pixels.len()], "tasks in order");
        for k in 0..task_pixels.len() {
            let (whole, task) = (seen + k, k);
            let bits = |(shadowed, unshadowed): ([f32; 3], [f32; 3])| [shadowed, unshadowed].map(|sums| sums.map(f32::to_bits));
            let (a, b) = (sums.lane(whole / LANES, whole % LANES), task_sums.lane(task / LANES, task % LANES));
            assert_eq!(bits(a), bits(b), "receiver {whole}");
            let (a, b) = (&met[whole / LANES], &task_met[task / LANES]);
            assert_eq!(a.count[whole % LANES], b.count[task % LANES], "receiver {whole}");
            assert_eq!(a.depth_sum[whole % LANES].to_bits(), b.depth_sum[task % LANES].to_bits(), "receiver {whole}");
        }
        seen += task_pixels.len();
    });
    assert_eq!(seen, pixels.len());
    // The triangle shadows some receivers and not others.
    let shadowed = (0..pixels.len()).filter(|&k| met[k / LANES].count[k % LANES] > 0.0).count();
    assert!(shadowed > 0 && shadowed < pixels.len(), "{shadowed} of {}", pixels.len());
}

#[test]
fn tiles_found_lit_without_a_test_are_lit_by_every_test_and_sum_as_maps_that_hold_nothing() {
    let (mut surfaces, constants, samples, positions) = floor_under_a_triangle(240, 160, 512);
    // A shelf of the floor raised to just under the triangle (y = 1): receivers whose
    // blocker is a hair nearer the light.
    for y in 40..120 {
        for position in &mut surfaces.positions[y * 240..(y + 1) * 240] {
            position.y = 0.95;
        }
    }
    let geometry = one_triangle(&positions);
    let crop = UVec2::splat(constants.resolution);
    let (maxima, _) = settled::cell_maxima(&samples, geometry, &mut Maps::new(crop));
    let tile = 8;
    let lit = settled::lit_tiles(&surfaces, tile, &samples, &maxima, &constants, 3);
    let columns = surfaces.width.div_ceil(tile);
    let in_lit = |x: u32, y: u32| lit[(y / tile * columns + x / tile) as usize];
    let (pixels, segments) = covered_pixels(&surfaces, 16, in_lit);
    // Much of the floor is found lit, and the triangle's shadow is not.
    let found = lit.iter().filter(|&&l| l).count();
    assert!(found > lit.len() / 4 && found < lit.len(), "{found} of {} tiles", lit.len());
    let receivers = Receivers::of_list(&surfaces, pixels.clone(), segments, &constants);
    let (sums, met, _) = estimate_with::<true>(&receivers, &samples, &constants, geometry, 3, &mut Maps::new(crop), |_| true);
    // The same samples with no map: every test lit.
    let unmapped: Vec<CpuSample> = samples.iter().map(|s| CpuSample { crop_origin: None, ..s.clone() }).collect();
    let (open, open_met, _) = estimate_with::<true>(&receivers, &unmapped, &constants, geometry, 3, &mut Maps::new(crop), |_| true);
    let bits = |sums: [f32; 3]| sums.map(f32::to_bits);
    for (k, pixel) in pixels.iter().enumerate() {
        let (b, l) = (k / LANES, k % LANES);
        let ((shadowed, unshadowed), (open_shadowed, open_unshadowed)) = (sums.lane(b, l), open.lane(b, l));
        assert_eq!(bits(shadowed), bits(unshadowed), "pixel {pixel} lit by every test");
        assert!(unshadowed.iter().sum::<f32>() > 0.0, "pixel {pixel} lit at all");
        assert_eq!([bits(shadowed), bits(unshadowed)], [bits(open_shadowed), bits(open_unshadowed)], "pixel {pixel}");
        assert_eq!([met[b].count[l], open_met[b].count[l]], [0.0, 0.0], "pixel {pixel}");
    }
}
