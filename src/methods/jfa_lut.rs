//! The intensity look-up texture of Rong & Tan 2006 (§3, §4.1), coloured: for a point q on
//! the light, the part of the light's emission on the side of the line through q orthogonal
//! to c→q that contains the centre c — what a receiver sees when the ray from it through an
//! occluder's silhouette meets the light at q. Stored per channel (RGB), so jump flooding
//! casts coloured penumbrae from coloured lights (the paper's lights are uniform discs).

use glam::Vec2;

use crate::light::{AreaLight, LightImage};

/// Side of the look-up texture, texels (even, so no texel centre falls on c itself, where the
/// partition is undefined).
pub const LUT_SIZE: u32 = 64;

/// Samples per side used to integrate each entry, at the centres of a regular grid over the
/// light (nearest texel): the partition line cuts through texels, so even a 1×1 image needs
/// many samples.
const SAMPLES: u32 = 96;

/// The look-up texture, `LUT_SIZE`² entries, row 0 at image row 0 (top, +u): RGB visible
/// fraction of each channel's emission, alpha the luminance-weighted fraction.
pub fn intensity_lut(light: &AreaLight, image: &LightImage) -> Vec<[f32; 4]> {
    let (nx, ny) = (SAMPLES, SAMPLES);
    // Sample points in light-local metres (x along r, y along u) with their emission.
    let samples: Vec<(Vec2, [f32; 3])> = (0..ny)
        .flat_map(|j| (0..nx).map(move |i| (i, j)))
        .filter_map(|(i, j)| {
            let (s, t) = ((i as f32 + 0.5) / nx as f32, (j as f32 + 0.5) / ny as f32);
            let texel = (((s * image.width as f32) as u32).min(image.width - 1), ((t * image.height as f32) as u32).min(image.height - 1));
            let e = image.emission(texel.0, texel.1);
            (e.max_element() > 0.0).then(|| (local(light, s, t), e.to_array()))
        })
        .collect();
    let total = samples.iter().fold([0.0f32; 3], |acc, (_, e)| [acc[0] + e[0], acc[1] + e[1], acc[2] + e[2]]);
    let luminance = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let entry = |i: u32, j: u32| {
        let q = local(light, (i as f32 + 0.5) / LUT_SIZE as f32, (j as f32 + 0.5) / LUT_SIZE as f32);
        // c is the origin: the centre's side of the line through q orthogonal to q.
        let limit = q.length_squared();
        let mut visible = [0.0f32; 3];
        for (y, e) in &samples {
            if y.dot(q) < limit {
                for k in 0..3 {
                    visible[k] += e[k];
                }
            }
        }
        let gray = if luminance(total) > 0.0 { luminance(visible) / luminance(total) } else { 0.0 };
        let fraction = |k: usize| if total[k] > 0.0 { visible[k] / total[k] } else { gray };
        [fraction(0), fraction(1), fraction(2), gray]
    };
    // ~4·10⁷ sample tests in all: rows are shared among the CPU's cores.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()) as u32;
    let rows_per_thread = LUT_SIZE.div_ceil(threads);
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..LUT_SIZE)
            .step_by(rows_per_thread as usize)
            .map(|first| {
                let entry = &entry;
                scope.spawn(move || {
                    (first..(first + rows_per_thread).min(LUT_SIZE))
                        .flat_map(|j| (0..LUT_SIZE).map(move |i| entry(i, j)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers.into_iter().flat_map(|worker| worker.join().expect("a look-up row worker panicked")).collect()
    })
}

/// Image coordinates (s right, t down) to light-local metres (x along r, y along u).
fn local(light: &AreaLight, s: f32, t: f32) -> Vec2 {
    Vec2::new((s - 0.5) * light.size_m.x, (0.5 - t) * light.size_m.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn light(size: Vec2) -> AreaLight {
        AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, size, 1.0).unwrap()
    }

    fn entry(lut: &[[f32; 4]], i: u32, j: u32) -> [f32; 4] {
        lut[(j * LUT_SIZE + i) as usize]
    }

    #[test]
    fn white_light_fraction_matches_direct_summation() {
        // On the horizontal axis through c, the partition line is vertical: the visible
        // fraction is the part of the light left of q's column.
        let light = light(Vec2::new(2.0, 1.0));
        let lut = intensity_lut(&light, &LightImage::builtin("white", &Default::default(), "f").unwrap());
        for i in [0, 5, 20, 40, 63] {
            let s = (i as f32 + 0.5) / LUT_SIZE as f32;
            // The row nearest the axis (t = 0.5 lies between rows 31 and 32).
            let got = entry(&lut, i, 31)[0];
            let expected = if s > 0.5 { s } else { 1.0 - s };
            assert!((got - expected).abs() < 0.02, "column {i}: {got} vs {expected}");
        }
        // Mirror points on the axis see mirror halves of a uniform light: equal fractions.
        assert!((entry(&lut, 10, 31)[0] - entry(&lut, 53, 31)[0]).abs() < 0.02);
    }

    #[test]
    fn colored_light_fractions_follow_the_bands() {
        // `stripes`: red is column 0 (s < 1/6), magenta the last. A q near the right edge cuts
        // off a sliver of magenta only, keeping all the green; a q near the left edge cuts into
        // the red band, keeping all the blue.
        let light = light(Vec2::new(3.0, 1.0));
        let image = LightImage::builtin("stripes", &Default::default(), "f").unwrap();
        let lut = intensity_lut(&light, &image);
        let right = entry(&lut, 62, 31);
        let left = entry(&lut, 2, 31);
        assert!(right[1] > 0.99 && right[2] < 0.99, "green kept, magenta cut on the right: {right:?}");
        assert!(left[0] < 0.97 && left[2] > 0.99, "red cut, blue kept on the left: {left:?}");
        // Direct summation at full resolution for the left entry: the visible part is s > s_q.
        let s_q = 2.5 / LUT_SIZE as f32;
        let (mut red_visible, mut red_total) = (0.0, 0.0);
        for k in 0..6000 {
            let s = (k as f32 + 0.5) / 6000.0;
            let red = image.emission(((s * 6.0) as u32).min(5), 0).x;
            red_total += red;
            if s > s_q {
                red_visible += red;
            }
        }
        assert!((left[0] - red_visible / red_total).abs() < 0.02, "{} vs {}", left[0], red_visible / red_total);
    }
}
