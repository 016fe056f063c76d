//! The filter of method `filtered`, and which pixels get every sample.
//!
//! Refinement. The probes' verdicts are classified by tiles of `TILE`² pixels, as AMD
//! FidelityFX's shadow denoiser classifies its tiles: a tile varies when a pixel in it or in a
//! neighbouring tile is partly lit by its probes, or when both fully lit and fully shadowed
//! pixels are there (an edge the probes cut cleanly). Every pixel of a varying tile is tested
//! against every sample; the rest keep their probes' 0 or 1.
//!
//! The filter. Each refined pixel's sums Σ L·G·V and Σ L·G (per channel) are averaged with
//! its neighbours' over the receiver's surface, in two passes (rows, then columns), and V is
//! their ratio — Heitz, Hill & McGuire 2018 filter numerator and denominator alike, so that E0
//! stays exact and only the shadow is smoothed. Mehta, Wang & Ramamoorthi 2012 (§4) bound the
//! visibility's spectrum on the receiver by the light's size and the distances to occluder and
//! light, and filter with a Gaussian in world space whose width follows. Here the limit is the
//! samples' own: the penumbra (of world width `light × (d_r − d_b) / d_b`, d the depths of
//! receiver and blocker from the light's plane) is a ramp the strata cut into `samples_across`
//! steps, so the Gaussian's σ is that step (× `filter_scale`): it erases the banding while a
//! straight ramp, symmetric about each of its points, stays where it was. Near a contact,
//! d_r − d_b → 0 and so does σ: nothing bleeds across it. A pixel whose tests met no blocker
//! takes the mean σ of the tiles around it.
//!
//! The weights (SVGF, Schied et al. 2017 §4): the world distance between the two points, the
//! distance of the neighbour from the pixel's tangent plane (beyond half σ and a pixel's
//! footprint it is another surface, even one close on screen, and gets none), and the
//! agreement of their normals.
//!
//! The error estimate. Stratified samples of an edge err as n^(−3/4) (n samples; a jittered
//! grid's error on a step), times √(V(1 − V)) for the level, per channel with the samples that
//! carry the channel (a colour emitted by half the light has half the samples); the constant is
//! fitted to the built-in suite against the 1,024-sample reference. The passes carry its square
//! as Σ w² e² / (Σ w)².

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;

use crate::render::method::GBufferView;
use crate::render::Camera;

/// Pixels a tile side, for the classification and the fallback width.
pub(super) const TILE: u32 = 8;

/// The widest a pass reaches on each side of a pixel: past it a penumbra is filtered less
/// than its width asks (its samples' banding then shows).
const MAX_RADIUS: u32 = 24;

/// The least σ filtered, in pixels: where the strata's steps are finer than half a pixel, the
/// pixel grid has averaged them already, and a kernel on the grid would only blur the ramp
/// (measured: `terrain` under `stripes` at 256×192, 0.0175 → 0.0147 with this floor; the rest
/// within 0.0001, 1080p unchanged).
const MIN_SIGMA_PIXELS: f32 = 0.5;

/// How far the kernel reaches, in its σ.
const REACH_SIGMAS: f32 = 2.5;

/// The sharpness of the normal weight: (n·n')^this.
const NORMAL_POWER: i32 = 8;

/// The visibility range counted as penumbra for the estimate's mean.
const PENUMBRA: (f32, f32) = (0.01, 0.99);

/// A pixel's sums per channel (Σ L·G·V, Σ L·G), the samples they hold and the square of its
/// estimated error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Texel {
    pub shadowed: [f32; 3],
    pub unshadowed: [f32; 3],
    pub variance: f32,
    pub samples: u32,
}

impl Texel {
    pub const UNCOVERED: Self = Self { shadowed: [0.0; 3], unshadowed: [0.0; 3], variance: 0.0, samples: 0 };

    /// Whether any sample saw the light from here (else V is undefined: 1).
    fn lit_at_all(&self) -> bool {
        self.unshadowed.iter().sum::<f32>() > 0.0
    }

    /// The gray ratio: the white twin's visibility.
    fn gray(&self) -> f32 {
        let total: f32 = self.unshadowed.iter().sum();
        if total > 0.0 {
            (self.shadowed.iter().sum::<f32>() / total).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    /// The ratio per channel (`write_visibility` in `cpu`), the gray one where a channel has
    /// no light.
    fn visibility(&self) -> [f32; 3] {
        let gray = self.gray();
        [0, 1, 2].map(|c| if self.unshadowed[c] > 0.0 { (self.shadowed[c] / self.unshadowed[c]).clamp(0.0, 1.0) } else { gray })
    }

    fn state(&self) -> State {
        if !self.lit_at_all() {
            State::Dark
        } else if self.shadowed == self.unshadowed {
            State::Lit
        } else if self.shadowed == [0.0; 3] {
            State::Umbra
        } else {
            State::Mixed
        }
    }
}

/// What a pixel's own samples say.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// No sample lights it (it faces away, or no surface): left out of every average.
    Dark,
    Lit,
    Umbra,
    Mixed,
}

/// The surface each pixel shows: world position and normal (zero: none), copied from the
/// G-buffer once for the tests and the filter.
pub(super) struct Surfaces {
    width: u32,
    height: u32,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
}

impl Surfaces {
    pub fn new(gbuffer: &GBufferView<'_>) -> Self {
        let (width, height) = (gbuffer.width, gbuffer.height);
        let pixels = (0..height).flat_map(|y| (0..width).map(move |x| (x, y)));
        let (positions, normals) = pixels.map(|(x, y)| (gbuffer.position(x, y), gbuffer.normal(x, y).unwrap_or(Vec3::ZERO))).unzip();
        Self { width, height, positions, normals }
    }
}

#[cfg(test)]
impl Surfaces {
    /// Surfaces made by hand: `at(x, y)` gives a pixel's position and normal (zero: none).
    pub fn from_fn(width: u32, height: u32, at: impl Fn(u32, u32) -> (Vec3, Vec3)) -> Self {
        let (positions, normals) = (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| at(x, y)).unzip();
        Self { width, height, positions, normals }
    }
}

impl super::cpu::Surfaces for Surfaces {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn position(&self, x: u32, y: u32) -> Vec3 {
        self.positions[(y * self.width + x) as usize]
    }

    fn normal(&self, x: u32, y: u32) -> Option<Vec3> {
        let normal = self.normals[(y * self.width + x) as usize];
        (normal != Vec3::ZERO).then_some(normal)
    }
}

/// What the filter needs of the frame and the samples.
pub(super) struct FilterInputs<'a> {
    /// The surfaces' size: the frame's, or a band's rows with their halo.
    pub width: u32,
    pub height: u32,
    /// The rows of these surfaces whose visibility is written (a band's, without its halo).
    pub written: Range<u32>,
    /// The frame's height in pixels, for a pixel's footprint.
    pub frame_height: u32,
    /// The light's size, one length (the geometric mean of its sides).
    pub light_extent: f32,
    /// Strata across the light: the steps a penumbra is cut into.
    pub samples_across: f32,
    /// The filter's width in those steps (0: no filter).
    pub scale: f32,
    /// Per channel, the samples' effective share (Kish's (Σ w)² / (n Σ w²) of the channel's
    /// weights): 1 under a white light, ½ where a channel comes from half the light.
    pub channel_share: [f32; 3],
    pub camera: &'a Camera,
}

/// The visibility of the `written` rows (rgb, and w the estimated error), with what the filter
/// did there.
pub(super) struct FilterOutput {
    pub visibility: Vec<[f32; 4]>,
    pub pixels_filtered: usize,
    /// The mean estimated error over the pixels in penumbra, and how many they were.
    pub penumbra_error: f64,
    pub penumbra_pixels: usize,
}

/// The pixels to test against every sample: the surfaces in the tiles that vary, by their
/// probes.
///
/// A surface that no probe lights (`Dark`) counts as a state of its own: next to lit or
/// shadowed pixels it is a terminator, where the probes may all lie below a horizon the other
/// samples clear. A pixel without a surface counts for nothing.
pub(super) fn refined(surfaces: &Surfaces, texels: &[Texel]) -> Vec<bool> {
    let tiles = Tiles::new(surfaces.width, surfaces.height);
    let covered = |i: usize| surfaces.normals[i] != Vec3::ZERO;
    // Per tile: the states its pixels' probes are in, a bit per `State`.
    let mut states = vec![0u8; tiles.count()];
    for (i, texel) in texels.iter().enumerate().filter(|&(i, _)| covered(i)) {
        states[tiles.of(i)] |= 1 << texel.state() as u8;
    }
    // A tile varies with a mixed pixel around it, or two of the states.
    let varies = |i: usize| {
        let seen = tiles.around(i).fold(0u8, |seen, t| seen | states[t]);
        seen & (1 << State::Mixed as u8) != 0 || seen.count_ones() > 1
    };
    (0..texels.len()).map(|i| covered(i) && varies(i)).collect()
}

/// Filters the `refined` pixels' `texels` over `surfaces`, sized by `blockers` ([receiver
/// depth, blockers met, their summed depth] from the light's plane, per pixel).
pub(super) fn filter(
    inputs: &FilterInputs<'_>,
    surfaces: &Surfaces,
    mut texels: Vec<Texel>,
    blockers: &[[f32; 3]],
    refined: &[bool],
) -> FilterOutput {
    let (width, height) = (inputs.width as usize, inputs.height as usize);
    // Only refined pixels err and are filtered: the others' probes agree (V 0 or 1).
    let listed: Vec<usize> = (0..width * height).into_par_iter().filter(|&i| refined[i]).collect();
    let errors: Vec<f32> = listed.par_iter().map(|&i| own_variance(&texels[i], inputs.channel_share)).collect();
    for (&i, variance) in listed.iter().zip(errors) {
        texels[i].variance = variance;
    }
    let written = inputs.written.start as usize * width..inputs.written.end as usize * width;
    if inputs.scale <= 0.0 || listed.is_empty() {
        return output(&texels[written], 0);
    }
    // A pixel's footprint in the world at its distance (the slant of its surface aside).
    let per_distance = 2.0 * (0.5 * inputs.camera.fov_y_deg.to_radians()).tan() / inputs.frame_height as f32;
    let footprint = |i: usize| (surfaces.positions[i] - inputs.camera.eye).length() * per_distance;
    // σ from the pixel's own blockers, where it met any; else the mean of the tiles around.
    let own_sigma: Vec<f32> = listed
        .par_iter()
        .map(|&i| {
            let [receiver, count, depth] = blockers[i];
            let blocker = if count > 0.0 { depth / count } else { 0.0 };
            if blocker > 0.0 && receiver > blocker {
                inputs.scale * inputs.light_extent * (receiver - blocker) / blocker / inputs.samples_across.max(1.0)
            } else {
                0.0
            }
        })
        .collect();
    // Per tile, the mean σ of its pixels that have their own (0: none has).
    let tiles = Tiles::new(inputs.width, inputs.height);
    let mut sums = vec![(0.0f32, 0u32); tiles.count()];
    for (&i, &sigma) in listed.iter().zip(&own_sigma).filter(|(_, s)| **s > 0.0) {
        let tile = &mut sums[tiles.of(i)];
        *tile = (tile.0 + sigma, tile.1 + 1);
    }
    let tile_sigma: Vec<f32> = sums.iter().map(|&(sum, n)| if n > 0 { sum / n as f32 } else { 0.0 }).collect();
    // The mean σ of the tiles around pixel i that have one (0: none).
    let sigma_around = |i: usize| {
        let (sum, n) = tiles.around(i).map(|t| tile_sigma[t]).filter(|&s| s > 0.0).fold((0.0, 0), |(sum, n), s| (sum + s, n + 1));
        if n > 0 {
            sum / n as f32
        } else {
            0.0
        }
    };
    let kernels: Vec<(f32, u32)> = listed
        .par_iter()
        .zip(&own_sigma)
        .map(|(&i, &own)| {
            let sigma = if own > 0.0 { own } else { sigma_around(i) };
            let sigma_px = sigma / footprint(i).max(1e-9);
            let radius = if sigma_px < MIN_SIGMA_PIXELS { 0 } else { (REACH_SIGMAS * sigma_px).ceil().min(MAX_RADIUS as f32) as u32 };
            (sigma, radius)
        })
        .collect();
    let pixels_filtered = listed.iter().zip(&kernels).filter(|(i, (_, r))| *r > 0 && written.contains(i)).count();
    // Where each listed pixel is in `listed` (u32::MAX: not listed), for the second pass to
    // read the first pass's result of a listed neighbour.
    let mut slot = vec![u32::MAX; width * height];
    for (k, &i) in listed.iter().enumerate() {
        slot[i] = k as u32;
    }
    // One pass over the listed pixels along `step`; a neighbour's sums are `read(j)`.
    let pass = |read: &(dyn Fn(usize) -> Texel + Sync), step: (isize, isize)| -> Vec<Texel> {
        listed
            .par_iter()
            .zip(&kernels)
            .map(|(&i, &(sigma, radius))| {
                let own = read(i);
                if radius == 0 {
                    return own;
                }
                let (x, y) = ((i % width) as isize, (i / width) as isize);
                let (p, n) = (surfaces.positions[i], surfaces.normals[i]);
                let inv_two_sigma2 = 0.5 / (sigma * sigma);
                let tolerance = 0.5 * sigma + footprint(i);
                let inv_two_tolerance2 = 0.5 / (tolerance * tolerance);
                let (mut shadowed, mut unshadowed) = ([0.0f32; 3], [0.0f32; 3]);
                let (mut weights, mut variance) = (0.0f32, 0.0f32);
                let r = radius as isize;
                for k in -r..=r {
                    let (qx, qy) = (x + k * step.0, y + k * step.1);
                    if qx < 0 || qy < 0 || qx >= width as isize || qy >= height as isize {
                        continue;
                    }
                    let j = qy as usize * width + qx as usize;
                    let q = read(j);
                    if !q.lit_at_all() {
                        continue;
                    }
                    let d = surfaces.positions[j] - p;
                    let plane = n.dot(d);
                    if plane.abs() > tolerance {
                        continue; // Off the pixel's tangent plane: another surface.
                    }
                    let facing = n.dot(surfaces.normals[j]).max(0.0).powi(NORMAL_POWER);
                    let w = (-d.length_squared() * inv_two_sigma2 - plane * plane * inv_two_tolerance2).exp() * facing;
                    for c in 0..3 {
                        shadowed[c] += w * q.shadowed[c];
                        unshadowed[c] += w * q.unshadowed[c];
                    }
                    weights += w;
                    variance += w * w * q.variance;
                }
                if weights <= 0.0 {
                    return own;
                }
                Texel {
                    shadowed: shadowed.map(|s| s / weights),
                    unshadowed: unshadowed.map(|u| u / weights),
                    variance: variance / (weights * weights),
                    samples: own.samples,
                }
            })
            .collect()
    };
    let rows = pass(&|j| texels[j], (1, 0));
    let both = pass(&|j| if slot[j] == u32::MAX { texels[j] } else { rows[slot[j] as usize] }, (0, 1));
    for (&i, texel) in listed.iter().zip(both) {
        texels[i] = texel;
    }
    output(&texels[written], pixels_filtered)
}

/// The constant of the error model, fitted to the built-in suite (module docs).
const ERROR_SCALE: f32 = 1.5;

/// The square of `texel`'s own estimate's expected error, its channels' mean (module docs).
fn own_variance(texel: &Texel, share: [f32; 3]) -> f32 {
    let v = texel.visibility();
    let n = texel.samples.max(1) as f32;
    let error = (0..3).map(|c| (v[c] * (1.0 - v[c])).sqrt() * (n * share[c]).max(1.0).powf(-0.75)).sum::<f32>() / 3.0;
    let error = ERROR_SCALE * error;
    error * error
}

/// The visibility (w: the estimated error) and the estimate's mean over the penumbra.
fn output(texels: &[Texel], pixels_filtered: usize) -> FilterOutput {
    let visibility: Vec<[f32; 4]> = texels
        .par_iter()
        .map(|t| {
            let [r, g, b] = t.visibility();
            [r, g, b, t.variance.max(0.0).sqrt()]
        })
        .collect();
    let (mut sum, mut count) = (0.0f64, 0usize);
    for (t, v) in texels.iter().zip(&visibility) {
        let gray = t.gray();
        if t.lit_at_all() && gray > PENUMBRA.0 && gray < PENUMBRA.1 {
            sum += f64::from(v[3]);
            count += 1;
        }
    }
    FilterOutput { visibility, pixels_filtered, penumbra_error: if count > 0 { sum / count as f64 } else { 0.0 }, penumbra_pixels: count }
}

/// The frame in tiles of `TILE`², for the refinement's classes and the fallback σ.
struct Tiles {
    width: u32,
    columns: u32,
    rows: u32,
}

impl Tiles {
    fn new(width: u32, height: u32) -> Self {
        Self { width, columns: width.div_ceil(TILE), rows: height.div_ceil(TILE) }
    }

    fn count(&self) -> usize {
        (self.columns * self.rows) as usize
    }

    /// The tile of pixel `i`.
    fn of(&self, i: usize) -> usize {
        let (x, y) = (i as u32 % self.width, i as u32 / self.width);
        ((y / TILE) * self.columns + x / TILE) as usize
    }

    /// The tiles around pixel `i`'s, its own included.
    fn around(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        let (tx, ty) = ((i as u32 % self.width / TILE) as i64, (i as u32 / self.width / TILE) as i64);
        (ty - 1..=ty + 1)
            .flat_map(move |j| (tx - 1..=tx + 1).map(move |i| (i, j)))
            .filter(|&(i, j)| i >= 0 && j >= 0 && i < self.columns as i64 && j < self.rows as i64)
            .map(|(i, j)| (j * self.columns as i64 + i) as usize)
    }
}
