//! Quality of a method against `reference` (contract §4): RMSE, PSNR, SSIM and FLIP on the
//! colour image and on the visibility, over the whole frame and over the penumbra only
//! (pixels where `0 < Vref < 1` in some channel — lit and umbra areas would otherwise
//! dominate every score). SSIM comes from `image-compare`, FLIP from `nv-flip`.
//!
//! Colour is compared as displayed: exposure applied, sRGB-encoded, in [0,1] (FLIP and SSIM
//! are defined on display-referred images). Visibility is compared as is, V ∈ [0,1], shown
//! as a gray image for SSIM and FLIP. PSNR uses a peak of 1; identical images have RMSE 0
//! and an infinite PSNR (written `null` in JSON).

use serde::Serialize;

use crate::color::linear_to_srgb;
use crate::render::FrameOutput;

/// Visibility strictly between these bounds in some channel marks a penumbra pixel. The
/// reference's ratio estimator gives exactly 0 and 1 outside penumbrae; the margin only
/// absorbs float rounding.
const PENUMBRA_EPSILON: f32 = 1e-4;

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Metrics {
    pub rmse: f64,
    /// Mean absolute error (contract §4 quotes "mean penumbra visibility error").
    pub mae: f64,
    /// The same per channel (red, green, blue): where a coloured light's hue goes wrong.
    pub mae_rgb: [f64; 3],
    pub psnr_db: f64,
    pub ssim: f64,
    pub flip: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Regions {
    pub whole: Metrics,
    pub penumbra: Metrics,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct QualityReport {
    pub color: Regions,
    pub visibility: Regions,
    /// Pixels in the reference's penumbra.
    pub penumbra_pixels: usize,
    /// Mean |V − Vref| (channels' mean) over the tenth of the reference's penumbra next to the
    /// occluders' contacts (`contact_mask`), where a filter would bleed across them.
    pub contact_mae: f64,
}

/// An image as the metrics see it: three channels per pixel in [0,1].
struct Planar {
    width: u32,
    height: u32,
    rgb: Vec<[f32; 3]>,
}

impl Planar {
    fn color(frame: &FrameOutput, exposure: f32) -> Self {
        let scale = exposure.exp2();
        let rgb = frame.color.iter().map(|c| [0, 1, 2].map(|k| linear_to_srgb(c[k] * scale))).collect();
        Self { width: frame.width, height: frame.height, rgb }
    }

    fn visibility(frame: &FrameOutput) -> Self {
        let rgb =
            frame.visibility.as_ref().expect("visibility read back for comparison").iter().map(|v| v.map(|c| c.clamp(0.0, 1.0))).collect();
        Self { width: frame.width, height: frame.height, rgb }
    }

    fn rgb8(&self) -> image::RgbImage {
        let bytes = self.rgb.iter().flat_map(|p| p.map(|c| (c * 255.0 + 0.5) as u8)).collect();
        image::RgbImage::from_raw(self.width, self.height, bytes).expect("sized from the frame")
    }
}

/// The penumbra of a reference frame: per pixel, whether some channel of Vref is in (0, 1).
pub fn penumbra_mask(reference: &FrameOutput) -> Vec<bool> {
    let visibility = reference.visibility.as_ref().expect("reference visibility");
    visibility
        .iter()
        .zip(&reference.color)
        .map(|(v, c)| c[3] > 0.0 && v.iter().any(|&x| x > PENUMBRA_EPSILON && x < 1.0 - PENUMBRA_EPSILON))
        .collect()
}

/// Compares `test` with `reference` (same scene, view, light and size).
pub fn compare(test: &FrameOutput, reference: &FrameOutput, exposure: f32) -> QualityReport {
    assert_eq!((test.width, test.height), (reference.width, reference.height), "frames of different sizes");
    let mask = penumbra_mask(reference);
    let everywhere = vec![true; mask.len()];
    let regions = |a: &Planar, b: &Planar| Regions { whole: metrics(a, b, &everywhere), penumbra: metrics(a, b, &mask) };
    let contact = contact_mask(reference, &mask);
    let visibility = (Planar::visibility(test), Planar::visibility(reference));
    QualityReport {
        color: regions(&Planar::color(test, exposure), &Planar::color(reference, exposure)),
        visibility: regions(&visibility.0, &visibility.1),
        penumbra_pixels: mask.iter().filter(|m| **m).count(),
        contact_mae: mean_absolute(&visibility.0, &visibility.1, &contact),
    }
}

/// The tenth of the reference's `penumbra` next to the occluders' contacts: where its penumbra
/// is narrowest in the world. A penumbra's width goes as the gap between occluder and receiver
/// (light × gap / occluder distance), to 0 at a contact, so its pixels with the steepest
/// visibility per unit of world distance — the gray visibility's gradient in pixels over the
/// view depth, which a pixel's footprint follows — are those nearest a contact. Without depth
/// (a PNG's frame), the steepest in pixels.
pub fn contact_mask(reference: &FrameOutput, penumbra: &[bool]) -> Vec<bool> {
    let visibility = reference.visibility.as_ref().expect("reference visibility");
    let (width, height) = (reference.width as usize, reference.height as usize);
    let gray = |i: usize| visibility[i].iter().sum::<f32>() / 3.0;
    let covered = |i: usize| reference.color.get(i).is_none_or(|c| c[3] > 0.0);
    // Central differences where both neighbours are covered, one-sided where one is.
    let slope = |i: usize, before: Option<usize>, after: Option<usize>| {
        let (b, a) = (before.filter(|&j| covered(j)), after.filter(|&j| covered(j)));
        match (b, a) {
            (Some(b), Some(a)) => 0.5 * (gray(a) - gray(b)),
            (Some(b), None) => gray(i) - gray(b),
            (None, Some(a)) => gray(a) - gray(i),
            (None, None) => 0.0,
        }
    };
    let mut steepness: Vec<(f32, usize)> = (0..width * height)
        .filter(|&i| penumbra[i])
        .map(|i| {
            let (x, y) = (i % width, i / width);
            let dx = slope(i, (x > 0).then(|| i - 1), (x + 1 < width).then(|| i + 1));
            let dy = slope(i, (y > 0).then(|| i - width), (y + 1 < height).then(|| i + width));
            let depth = reference.depth.as_ref().map_or(1.0, |d| if d[i].is_finite() && d[i] > 0.0 { d[i] } else { 1.0 });
            ((dx * dx + dy * dy).sqrt() / depth, i)
        })
        .collect();
    steepness.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut mask = vec![false; penumbra.len()];
    for &(_, i) in steepness.iter().take(steepness.len().div_ceil(10)) {
        mask[i] = true;
    }
    mask
}

/// Mean absolute difference over `mask`, the channels' mean (`Metrics::mae`; 0 for an empty
/// mask).
fn mean_absolute(test: &Planar, reference: &Planar, mask: &[bool]) -> f64 {
    let count = mask.iter().filter(|m| **m).count();
    if count == 0 {
        return 0.0;
    }
    differences(test, reference, mask).1.iter().sum::<f64>() / (count * 3) as f64
}

/// Over `mask`: the sum of squared differences, and of absolute differences per channel.
fn differences(test: &Planar, reference: &Planar, mask: &[bool]) -> (f64, [f64; 3]) {
    let (mut squared, mut absolute) = (0.0f64, [0.0f64; 3]);
    for ((a, b), _) in test.rgb.iter().zip(&reference.rgb).zip(mask).filter(|(_, m)| **m) {
        for k in 0..3 {
            let d = f64::from(a[k] - b[k]);
            squared += d * d;
            absolute[k] += d.abs();
        }
    }
    (squared, absolute)
}

fn metrics(test: &Planar, reference: &Planar, mask: &[bool]) -> Metrics {
    let count = mask.iter().filter(|m| **m).count();
    if count == 0 {
        // No pixels in the region: nothing differs.
        return Metrics { rmse: 0.0, mae: 0.0, mae_rgb: [0.0; 3], psnr_db: f64::INFINITY, ssim: 1.0, flip: 0.0 };
    }
    let (squared, absolute) = differences(test, reference, mask);
    let samples = (count * 3) as f64;
    let rmse = (squared / samples).sqrt();
    let (a8, b8) = (test.rgb8(), reference.rgb8());
    // SSIM over 8×8 windows; per pixel the least similar channel (image-compare's convention
    // for RGB), averaged over the region. image-compare exposes the per-pixel map only as an
    // 8-bit image, so the regional SSIM is quantised to 1/255; the whole-frame score is exact.
    let similarity = image_compare::rgb_similarity_structure(&image_compare::Algorithm::MSSIMSimple, &b8, &a8).expect("same size");
    let ssim = if count == mask.len() {
        similarity.score
    } else {
        let map = similarity.image.to_color_map().to_rgb8();
        masked_mean(map.pixels().map(|p| f64::from(p.0[0].min(p.0[1]).min(p.0[2])) / 255.0), mask)
    };
    let flip_map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(reference.width, reference.height, b8.as_raw()),
        nv_flip::FlipImageRgb8::with_data(test.width, test.height, a8.as_raw()),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let flip = masked_mean(flip_map.to_vec().into_iter().map(f64::from), mask);
    let mae_rgb = absolute.map(|a| a / count as f64);
    Metrics {
        rmse,
        mae: absolute.iter().sum::<f64>() / samples,
        mae_rgb,
        psnr_db: if rmse > 0.0 { -20.0 * rmse.log10() } else { f64::INFINITY },
        ssim,
        flip,
    }
}

fn masked_mean(values: impl Iterator<Item = f64>, mask: &[bool]) -> f64 {
    let (sum, n) = values.zip(mask).filter(|(_, m)| **m).fold((0.0, 0usize), |(s, n), (v, _)| (s + v, n + 1));
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// `|V − Vref|`, the largest channel, per pixel: what the error heat-maps show.
pub fn visibility_error(test: &FrameOutput, reference: &FrameOutput) -> Vec<f32> {
    let (a, b) = (test.visibility.as_ref().expect("visibility"), reference.visibility.as_ref().expect("visibility"));
    a.iter().zip(b).map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).abs()).fold(0.0, f32::max)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(width: u32, height: u32, f: impl Fn(u32, u32) -> f32) -> FrameOutput {
        let mut color = Vec::new();
        let mut visibility = Vec::new();
        for y in 0..height {
            for x in 0..width {
                let v = f(x, y);
                color.push([0.5 * v, 0.4 * v, 0.3 * v, 1.0]);
                visibility.push([v; 3]);
            }
        }
        FrameOutput {
            width,
            height,
            color,
            srgb8: None,
            visibility: Some(visibility),
            error_estimate: None,
            depth: None,
            e0: None,
            counters: Default::default(),
            warnings: Vec::new(),
            staging: Default::default(),
        }
    }

    /// A soft edge: lit on the left, umbra on the right, a penumbra from 0.75 to 0.25 between
    /// (so that ±0.1 stays inside (0, 1)).
    fn edge(x: u32, _: u32) -> f32 {
        match x {
            0..20 => 1.0,
            20..43 => 0.75 - 0.5 * (x - 20) as f32 / 22.0,
            _ => 0.0,
        }
    }

    #[test]
    fn identical_frames_have_no_error() {
        let a = frame(64, 48, edge);
        let report = compare(&a, &a, 0.0);
        for regions in [report.color, report.visibility] {
            for m in [regions.whole, regions.penumbra] {
                assert_eq!(m.rmse, 0.0);
                assert!(m.psnr_db.is_infinite());
                assert!((m.ssim - 1.0).abs() < 1e-9, "{}", m.ssim);
                assert_eq!(m.flip, 0.0);
            }
        }
        assert_eq!(report.penumbra_pixels, 23 * 48);
    }

    #[test]
    fn a_known_perturbation_gives_the_expected_rmse() {
        let reference = frame(64, 48, edge);
        // +0.1 on every visibility value inside the penumbra, nothing elsewhere.
        let test = frame(64, 48, |x, y| {
            let v = edge(x, y);
            if v > 0.0 && v < 1.0 {
                v + 0.1
            } else {
                v
            }
        });
        let report = compare(&test, &reference, 0.0);
        assert!((report.visibility.penumbra.rmse - 0.1).abs() < 1e-5, "{:?}", report.visibility.penumbra);
        assert!((report.visibility.penumbra.mae - 0.1).abs() < 1e-5);
        assert!(report.visibility.penumbra.mae_rgb.iter().all(|m| (m - 0.1).abs() < 1e-5));
        assert!((report.visibility.penumbra.psnr_db - 20.0).abs() < 1e-3);
        let fraction = report.penumbra_pixels as f64 / (64.0 * 48.0);
        assert!((report.visibility.whole.rmse - 0.1 * fraction.sqrt()).abs() < 1e-5);
        assert!(report.visibility.penumbra.ssim < 1.0 && report.visibility.penumbra.flip > 0.0);
    }

    /// A penumbra that narrows down the frame, as one does towards an occluder's contact: row y
    /// has a ramp 4 + (47 − y)/2 pixels wide. Its contact tenth is the steepest rows', and an error
    /// only there shows in `contact_mae` and not (much) over the whole penumbra.
    #[test]
    fn the_contact_tenth_is_where_the_penumbra_is_narrowest() {
        let width = |y: u32| 4.0 + 0.5 * (47 - y) as f32;
        let ramp = |x: u32, y: u32| (1.0 - (x as f32 + 0.5 - 20.0) / width(y)).clamp(0.0, 1.0);
        let reference = frame(64, 48, ramp);
        let mask = penumbra_mask(&reference);
        let contact = contact_mask(&reference, &mask);
        let (count, listed) = (mask.iter().filter(|&&m| m).count(), contact.iter().filter(|&&m| m).count());
        assert_eq!(listed, count.div_ceil(10));
        // Every contact pixel lies in the narrowest rows (the bottom ones).
        let rows: Vec<usize> = contact.iter().enumerate().filter(|(_, &c)| c).map(|(i, _)| i / 64).collect();
        assert!(rows.iter().all(|&y| y >= 32), "{rows:?}");
        // An error in the contact rows alone.
        let test = frame(64, 48, |x, y| {
            let v = ramp(x, y);
            if y >= 32 && v > 0.0 && v < 1.0 {
                (v + 0.1).min(1.0)
            } else {
                v
            }
        });
        let report = compare(&test, &reference, 0.0);
        assert!(report.contact_mae > 0.05, "{}", report.contact_mae);
        assert!(report.visibility.penumbra.mae < 0.5 * report.contact_mae, "{:?}", report.visibility.penumbra);
        assert_eq!(compare(&reference, &reference, 0.0).contact_mae, 0.0);
    }
}
