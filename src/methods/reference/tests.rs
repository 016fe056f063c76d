//! Unit tests of `reference`.

use glam::{Mat4, UVec2, Vec2, Vec3};

use super::crop::{MapCrop, CROP_GRANULE};
use super::gpu::BATCH_SAMPLES;
use super::*;
use crate::light::{AreaLight, LightImage};

#[test]
fn the_batch_matches_its_wgsl_mirror() {
    let declaration = format!("const MAX_SAMPLES: u32 = {BATCH_SAMPLES}u;");
    crate::gpu::shaders::assert_declares("methods/reference/accumulate.wgsl", &declaration);
    // The pass spells its samples out by `#unroll`, whose bound is a literal: one per slot.
    crate::gpu::shaders::assert_declares("methods/reference/accumulate.wgsl", &format!("#unroll k in 0..{BATCH_SAMPLES} {{"));
    crate::gpu::shaders::assert_declares("methods/reference/accumulate.wgsl", &format!("const SEGMENT: u32 = {SEGMENT}u;"));
}

#[test]
fn a_crop_holds_every_receiver_and_lands_its_texels_where_the_whole_map_has_them() {
    let resolution = 2048;
    let bounds =
        vec![Some((Vec2::new(300.2, 1000.0), Vec2::new(900.7, 1500.5))), None, Some((Vec2::new(1700.0, -20.0), Vec2::new(2100.0, 380.0)))];
    let crop = MapCrop::fit(bounds, resolution);
    // The widest extents with their margins (900.7 + 2 → 903, 300.2 − 2 → 298: 605 texels
    // across; 998 to 1503: 505 down), rounded up to whole granules.
    assert_eq!(crop.size, UVec2::new(640, 512));
    assert_eq!(crop.origins, vec![Some(UVec2::new(298, 998)), None, Some(UVec2::new(2048 - 640, 0))]);
    // A point's texel in its crop is its texel in the whole map less the crop's origin.
    let view_proj = Mat4::perspective_infinite_reverse_rh(1.1, 1.0, 0.3) * Mat4::look_to_rh(Vec3::new(0.5, 8.0, 0.2), -Vec3::Y, -Vec3::Z);
    let texel = |m: Mat4, p: Vec3, size: Vec2| {
        let c = m * p.extend(1.0);
        Vec2::new(c.x / c.w + 1.0, 1.0 - c.y / c.w) * 0.5 * size
    };
    for origin in [crop.origins[0], crop.origins[2]] {
        let layer = crop.layer_view_proj(origin, resolution, view_proj);
        for p in [Vec3::new(0.3, 0.0, -1.2), Vec3::new(-2.0, 1.0, 2.5), Vec3::new(1.7, 0.4, 0.9)] {
            let whole = texel(view_proj, p, Vec2::splat(resolution as f32));
            let cropped = texel(layer, p, crop.size.as_vec2());
            assert!((cropped - (whole - origin.unwrap().as_vec2())).abs().max_element() < 1e-3, "{cropped} against {whole}");
            // The depth is untouched: the same z and w.
            let (a, b) = (view_proj * p.extend(1.0), layer * p.extend(1.0));
            assert_eq!((a.z, a.w), (b.z, b.w));
        }
    }
    // A crop more than a quarter of the map is the whole map, drawn as before.
    for hi in [Vec2::new(2000.0, 2047.0), Vec2::new(1100.0, 1100.0)] {
        let whole = MapCrop::fit(vec![Some((Vec2::new(-5.0, 10.0), hi)), None], resolution);
        assert_eq!(whole, MapCrop::whole(2, resolution));
    }
    let whole = MapCrop::whole(1, resolution);
    assert_eq!(whole.layer_view_proj(whole.origins[0], resolution, view_proj), view_proj);
    // No receiver in any map: the smallest crop, nothing drawn.
    assert_eq!(MapCrop::fit(vec![None, None], resolution), MapCrop { size: UVec2::splat(CROP_GRANULE), origins: vec![None, None] });
}

#[test]
fn samples_are_stratified_and_skip_black() {
    let light = AreaLight::new(Vec3::Y, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 3.0).unwrap();
    let white = LightImage::builtin("white", &Default::default(), "f").unwrap();
    let (samples, indices, strata) = light_samples(&light, &white, 200, 1);
    assert_eq!((samples.len(), indices, strata), (200, (0..200).collect(), 200));
    // A weight is L × area, whatever the count: their mean estimates the light's power.
    assert!(samples.iter().all(|s| (s.weight - Vec3::splat(3.0 * 2.0)).abs().max_element() < 1e-5));
    // The disk leaves out its corners: about 1 − π/4 of the points.
    let disk = LightImage::builtin("disk", &Default::default(), "f").unwrap();
    let square = AreaLight { size_m: Vec2::ONE, ..light };
    let (samples, _, strata) = light_samples(&square, &disk, 1024, 1);
    let skipped = 1.0 - samples.len() as f32 / strata as f32;
    assert!((skipped - (1.0 - std::f32::consts::FRAC_PI_4)).abs() < 0.01, "{skipped}");
}

/// The progressive rounds' premise: the samples of fewer are the first of more, and every
/// prefix of 2^k points is stratified as a (0, k, 2)-net — one point in each of its 2^k boxes of
/// every shape — while another seed draws other points.
#[test]
fn the_sequence_is_nested_and_every_power_of_two_prefix_is_a_net() {
    let light = AreaLight::new(Vec3::Y, -Vec3::Y, -Vec3::Z, Vec2::new(1.0, 1.0), 3.0).unwrap();
    let white = LightImage::builtin("white", &Default::default(), "f").unwrap();
    let (more, _, _) = light_samples(&light, &white, 512, 9);
    for n in [1, 16, 100, 256] {
        assert_eq!(light_samples(&light, &white, n, 9).0[..], more[..n as usize]);
    }
    assert_ne!(light_samples(&light, &white, 16, 10).0, more[..16]);
    let scramble = (0x1234_5678, 0x9abc_def0);
    for k in [2u32, 4, 6, 8] {
        let points: Vec<(f32, f32)> = (0..1u32 << k).map(|i| super::samples::sequence_point(i, scramble)).collect();
        for a in 0..=k {
            let (nx, ny) = (1u32 << a, 1u32 << (k - a));
            let mut seen = vec![false; (nx * ny) as usize];
            for (x, y) in &points {
                let cell = ((y * ny as f32) as u32).min(ny - 1) * nx + ((x * nx as f32) as u32).min(nx - 1);
                assert!(!std::mem::replace(&mut seen[cell as usize], true), "k {k}: boxes {nx}×{ny}: two points in box {cell}");
            }
        }
    }
}

/// The halves the error estimate compares: equal at every multiple of eight samples, and each
/// spread over the whole light.
#[test]
fn the_reference_halves_are_equal_and_each_covers_the_light() {
    let light = AreaLight::new(Vec3::Y, -Vec3::Y, -Vec3::Z, Vec2::new(1.0, 1.0), 3.0).unwrap();
    let white = LightImage::builtin("white", &Default::default(), "f").unwrap();
    for n in [8, 16, 64, 256] {
        let (samples, indices, _) = light_samples(&light, &white, n, 3);
        let halves: Vec<bool> = indices.into_iter().map(half_of_index).collect();
        assert_eq!(halves.iter().filter(|&&h| h).count() as u32, n / 2, "{n} samples");
        for half in [false, true] {
            let points: Vec<Vec3> = samples.iter().zip(&halves).filter(|(_, h)| **h == half).map(|(s, _)| s.position).collect();
            // Each quadrant of the light holds a quarter of the half's points.
            for (sx, sz) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                let inside = points.iter().filter(|p| p.x * sx > 0.0 && p.z * sz > 0.0).count();
                assert_eq!(inside as u32, n / 8, "{n} samples, half {half}, quadrant ({sx}, {sz})");
            }
        }
    }
}

#[test]
fn half_the_halves_difference_estimates_the_error() {
    let light = AreaLight::new(Vec3::Y, -Vec3::Y, -Vec3::Z, Vec2::new(1.0, 1.0), 3.0).unwrap();
    let white = LightImage::builtin("white", &Default::default(), "f").unwrap();
    for n in [64u32, 256, 1024] {
        let (samples, indices, _) = light_samples(&light, &white, n, 5);
        let halves: Vec<bool> = indices.into_iter().map(half_of_index).collect();
        let (mut estimated, mut measured) = (0.0, 0.0);
        let edges = 400;
        for e in 0..edges {
            // A point sees the part of the light left of a tilted line (its exact share: x0).
            let x0 = 0.1 + 0.8 * e as f32 / edges as f32;
            let lit = |p: Vec3| (p.x + 0.5) + 0.3 * (p.z + 0.5 - 0.5) < x0;
            let mut sums = [(0.0f32, 0.0f32); 2];
            for (s, &h) in samples.iter().zip(&halves) {
                let sum = &mut sums[usize::from(h)];
                *sum = (sum.0 + if lit(s.position) { 1.0 } else { 0.0 }, sum.1 + 1.0);
            }
            let [(a, na), (b, nb)] = sums;
            estimated += (a / na - b / nb).abs() / 2.0;
            measured += ((a + b) / (na + nb) - x0).abs();
        }
        let ratio = estimated / measured;
        assert!((0.7..1.3).contains(&ratio), "{n} samples: estimated ÷ measured = {ratio}");
    }
}

/// `Texel::error`'s shortcut for a gray light's texels gives what the channel-by-channel
/// estimate gives, to the bit: sums of pixels in penumbra, lit, in umbra and with a half
/// that sees no light, and zeros of both signs.
#[test]
fn a_gray_texels_error_is_its_channels_to_the_bit() {
    use super::estimate::Texel;
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut checked = 0;
    for k in 0..20_000 {
        let (whole_light, half_light) = (next() * 40.0, next() * 20.0);
        let pick = |value: f32, case: u32| match case {
            0 => 0.0,
            1 => -0.0,
            _ => value,
        };
        let (u, hu) = (pick(whole_light + half_light, k % 7), pick(half_light, k % 5));
        let (s, hs) = match k % 4 {
            0 => (u, hu),    // lit by every sample
            1 => (0.0, 0.0), // umbra
            _ => (u * next(), hu * next()),
        };
        let texel = Texel { shadowed: [s; 3], unshadowed: [u; 3], half_shadowed: [hs; 3], half_unshadowed: [hu; 3] };
        assert_eq!(texel.error().to_bits(), texel.error_by_channel().to_bits(), "{texel:?}");
        checked += usize::from(texel.error() > 0.0);
    }
    // Most of them are in penumbra: the shortcut's arithmetic was exercised.
    assert!(checked > 3_000, "{checked} with an error");
}
