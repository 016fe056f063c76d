//! Unit tests of `filtered`'s filter and refinement, on surfaces made by hand: a floor seen
//! from straight above, one world unit a pixel.

use glam::Vec3;

use super::super::estimate::{PenumbraMean, Texel, Texels};
use super::filter::{self, FilterInputs, FilterOutput, Surfaces};
use crate::render::Camera;

const SIZE: u32 = 64;

/// A camera 100 units above the floor's centre whose pixel footprint there is about 1 unit.
fn camera() -> Camera {
    let fov = 2.0 * (0.5 * SIZE as f32 / 100.0).atan().to_degrees();
    Camera { eye: Vec3::new(32.0, 100.0, 32.0), target: Vec3::new(32.0, 0.0, 32.0), up: -Vec3::Z, fov_y_deg: fov, near: 1.0, far: 200.0 }
}

/// Every texel's visibility (rgb and the error estimate) as written, and the estimate's mean.
fn written(out: &FilterOutput) -> (Vec<[f32; 4]>, PenumbraMean) {
    let mut penumbra = PenumbraMean::default();
    let mut bytes = vec![0u8; out.texels.len() * 16];
    out.write_visibility(0..out.texels.len(), SIZE as usize, &mut bytes, &mut penumbra);
    (bytemuck::pod_collect_to_vec(&bytes), penumbra)
}

/// The floor y = `height(x)` under pixel (x, y), facing up.
fn floor(height: impl Fn(u32) -> f32) -> Surfaces {
    Surfaces::from_fn(SIZE, SIZE, |x, y| (Vec3::new(x as f32, height(x), y as f32), Vec3::Y))
}

/// Gray texels of visibility `v(x)`, both halves of their samples agreeing.
fn texels(v: impl Fn(u32) -> f32) -> Texels {
    halves(|x| (v(x), v(x)), 0.5)
}

/// Gray texels whose halves see visibility `v(x)` (first, second), the second holding `share`
/// of the light.
fn halves(v: impl Fn(u32) -> (f32, f32), share: f32) -> Texels {
    let texel = |i: u32| {
        let (a, b) = v(i % SIZE);
        let mut texel = Texel::UNCOVERED;
        texel.add([a * (1.0 - share); 3], [1.0 - share; 3], false);
        texel.add([b * share; 3], [share; 3], true);
        texel
    };
    Texels::from_texels(1, (0..SIZE * SIZE).map(texel))
}

fn inputs(camera: &Camera, scale: f32) -> FilterInputs<'_> {
    FilterInputs {
        width: SIZE,
        height: SIZE,
        written: 0..SIZE,
        frame_height: SIZE,
        light_extent: 1.0,
        samples_across: 1.0,
        scale,
        samples_effective: 256.0,
        camera,
        depth_of: &|_| RECEIVER_DEPTH,
    }
}

/// Every surface's depth from the light's plane.
const RECEIVER_DEPTH: f32 = 2.0;

/// Blockers that make σ = `sigma` world units with `inputs` (light 1, one stratum across):
/// (d_r − d_b) / d_b = σ, one blocker met at d_b = d_r / (1 + σ).
fn blockers(sigma: f32) -> Vec<[f32; 2]> {
    vec![[1.0, RECEIVER_DEPTH / (1.0 + sigma)]; (SIZE * SIZE) as usize]
}

#[test]
fn a_straight_ramp_stays_where_it_was_and_steps_are_smoothed() {
    let camera = camera();
    // A penumbra from x = 16 to 48, cut into steps of 4 pixels as coarse strata would (each
    // step at the ramp's mean over it), the two halves' steps 2 pixels apart, as two
    // independently stratified sets put them.
    let ramp = |x: u32| ((x as f32 + 0.5 - 16.0) / 32.0).clamp(0.0, 1.0);
    let steps = |x: u32, offset: f32| match x {
        ..16 => 0.0,
        48.. => 1.0,
        _ => ((((x as f32 - offset) / 4.0).floor() * 4.0 + 2.0 + offset - 16.0) / 32.0).clamp(0.0, 1.0),
    };
    let halved = |x: u32| (steps(x, 16.0), steps(x, 14.0));
    let stepped = |x: u32| 0.5 * (halved(x).0 + halved(x).1);
    let surfaces = floor(|_| 0.0);
    let refined = filter::refined(&surfaces, &halves(halved, 0.5), None);
    assert!(refined[(32 * SIZE + 32) as usize] && !refined[(32 * SIZE + 2) as usize], "the penumbra is refined, the lit floor not");
    let out = filter::filter(&inputs(&camera, 1.0), &surfaces, halves(halved, 0.5), &blockers(2.0), &refined);
    let error = |v: &dyn Fn(u32) -> f32| (20..44).map(|x| (v(x) - ramp(x)).abs()).sum::<f32>() / 24.0;
    let (visibility, _) = written(&out);
    let filtered = |x: u32| visibility[(32 * SIZE + x) as usize][0];
    let (before, after) = (error(&stepped), error(&filtered));
    assert!(after < 0.3 * before, "the steps are smoothed: mean error {before} → {after}");
    // Far from the penumbra nothing changes.
    assert_eq!(filtered(2), 0.0);
    assert_eq!(filtered(60), 1.0);
    assert!(out.pixels_filtered > 0);
}

#[test]
fn nothing_is_filtered_across_another_surface() {
    let camera = camera();
    // Two floors meeting at x = 32, one 5 units above the other: shadowed left, lit right.
    let surfaces = floor(|x| if x < 32 { 0.0 } else { 5.0 });
    let values = texels(|x| if x < 32 { 0.0 } else { 1.0 });
    let refined = vec![true; (SIZE * SIZE) as usize];
    let out = filter::filter(&inputs(&camera, 1.0), &surfaces, values, &blockers(3.0), &refined);
    for x in [30, 31, 32, 33] {
        let v = written(&out).0[(10 * SIZE + x) as usize][0];
        assert_eq!(v, if x < 32 { 0.0 } else { 1.0 }, "pixel {x}: the other surface is out of the average");
    }
}

#[test]
fn the_error_estimate_is_the_halves_difference_weighed_by_their_light() {
    let camera = camera();
    let surfaces = floor(|_| 0.0);
    let refined = vec![true; (SIZE * SIZE) as usize];
    let estimate = |v: &dyn Fn(u32) -> (f32, f32), share: f32, scale: f32| {
        filter::filter(&inputs(&camera, scale), &surfaces, halves(v, share), &blockers(1.0), &refined)
    };
    // Halves of equal light at 0.4 and 0.6: the whole is 0.5, its error half the difference.
    let even = estimate(&|_| (0.4, 0.6), 0.5, 0.0);
    let (visibility, penumbra) = written(&even);
    assert!(visibility.iter().all(|v| (v[0] - 0.5).abs() < 1e-6 && (v[3] - 0.1).abs() < 1e-6), "{:?}", visibility[0]);
    assert!((penumbra.mean() - 0.1).abs() < 1e-6 && penumbra.pixels() == f64::from(SIZE * SIZE));
    // A second half of a quarter of the light: |0.4 − 0.6| · √(¾ · ¼).
    let uneven = estimate(&|_| (0.4, 0.6), 0.25, 0.0);
    let first = written(&uneven).0[0];
    assert!((first[3] - 0.2 * (0.1875f32).sqrt()).abs() < 1e-6, "{first:?}");
    // Halves that agree: no error. Halves whose errors alternate from pixel to pixel: the filter
    // averages them away, and its estimate says so.
    assert_eq!(written(&estimate(&|_| (0.5, 0.5), 0.5, 0.0)).1.mean(), 0.0);
    let alternating = |x: u32| if x.is_multiple_of(2) { (0.4, 0.6) } else { (0.6, 0.4) };
    let (raw, filtered) = (estimate(&alternating, 0.5, 0.0), estimate(&alternating, 0.5, 1.0));
    let (raw, filtered) = (written(&raw).1.mean(), written(&filtered).1.mean());
    assert!(filtered < 0.3 * raw, "{raw} → {filtered}");
}

#[test]
fn a_neighbour_that_sees_other_colours_of_the_light_lends_it_none() {
    let camera = camera();
    let surfaces = floor(|_| 0.0);
    // Left of x = 32 the whole light is above the horizon, half of it shadowed. Right of it,
    // a terminator: only its red part is (green and blue barely), and the red is half
    // shadowed, the rest lit — the same gray visibility, another colour.
    let texel = |x: u32| {
        let (shadowed, unshadowed) = if x < 32 { ([0.5; 3], [1.0; 3]) } else { ([0.5, 0.01, 0.01], [1.0, 0.01, 0.01]) };
        let mut texel = Texel::UNCOVERED;
        texel.add(shadowed.map(|s| 0.5 * s), unshadowed.map(|u| 0.5 * u), false);
        texel.add(shadowed.map(|s| 0.5 * s), unshadowed.map(|u| 0.5 * u), true);
        texel
    };
    let values = Texels::from_texels(3, (0..SIZE * SIZE).map(|i| texel(i % SIZE)));
    let refined = vec![true; (SIZE * SIZE) as usize];
    let out = filter::filter(&inputs(&camera, 1.0), &surfaces, values, &blockers(3.0), &refined);
    let (visibility, _) = written(&out);
    let at = |x: u32| visibility[(10 * SIZE + x) as usize];
    for x in [30, 31] {
        assert!(at(x)[..3].iter().all(|v| (v - 0.5).abs() < 1e-4), "pixel {x}: {:?}", at(x));
    }
    for x in [32, 33] {
        let v = at(x);
        assert!((v[0] - 0.5).abs() < 1e-4 && v[1] > 0.999 && v[2] > 0.999, "pixel {x} keeps its green and blue lit: {v:?}");
    }
}

#[test]
fn the_kernel_stops_where_the_shadow_differs_by_more_than_its_noise() {
    let camera = camera();
    let surfaces = floor(|_| 0.0);
    // One surface whose visibility jumps from 0.3 to 0.7 at x = 32 (next to a contact), each
    // side's halves 0.02 apart: the jump is ten times the estimated error, and stays.
    let jump = |x: u32| if x < 32 { (0.29, 0.31) } else { (0.69, 0.71) };
    let refined = vec![true; (SIZE * SIZE) as usize];
    let out = filter::filter(&inputs(&camera, 1.0), &surfaces, halves(jump, 0.5), &blockers(3.0), &refined);
    let (visibility, _) = written(&out);
    for x in [29, 30, 31, 32, 33, 34] {
        let v = visibility[(10 * SIZE + x) as usize][0];
        let own = if x < 32 { 0.3 } else { 0.7 };
        assert!((v - own).abs() < 2e-3, "pixel {x}: {v}, not {own}");
    }
}

#[test]
fn samples_that_all_agree_in_both_halves_estimate_no_error() {
    // The filter takes such a neighbour's error as 0 without computing it: all lit, all
    // shadowed, or unlit, whatever the sums and however the halves share the light (none in
    // one half, or in one channel).
    let mut texels = Vec::new();
    for (whole, second) in [([0.7, 0.2, 0.1], [0.3, 0.0, 0.05]), ([1e-30, 2.0, 0.0], [0.0; 3]), ([0.0; 3], [0.0; 3]), ([5.0; 3], [5.0; 3])]
    {
        let first = [0, 1, 2].map(|c| whole[c] - second[c]);
        let mut lit = Texel::UNCOVERED;
        lit.add(first, first, false);
        lit.add(second, second, true);
        let mut shadowed = Texel::UNCOVERED;
        shadowed.add([0.0; 3], first, false);
        shadowed.add([0.0; 3], second, true);
        texels.extend([lit, shadowed]);
    }
    for texel in texels {
        assert_eq!(texel.error().to_bits(), 0.0f32.to_bits(), "{texel:?}");
    }
}
