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
//! takes the mean σ of the tiles around it. d_b is the mean depth of the blockers the pixel's
//! tests met, not Mehta's least shear (the blocker nearest the receiver): sized by that, the
//! kernel left 1–2 % more error at 1080p (docs/performance-log.md).
//!
//! The weights (SVGF, Schied et al. 2017 §4): the world distance between the two points, the
//! distance of the neighbour from the pixel's tangent plane (beyond half σ and a pixel's
//! footprint it is another surface, even one close on screen, and gets none), the agreement of
//! their normals, and two that the samples give (`Guide`): the light each sees unshadowed and
//! the shadow each is in. The ratio estimator divides the neighbours' summed Σ L·G·V by their
//! summed Σ L·G, so a neighbour that sees more of the light than the pixel weighs more; where
//! the tangent plane cuts the light (a terminator, a grazing slope) a neighbour can see parts
//! of it, or colours, the pixel does not, and would lend it their visibility. And the filter
//! is there to average the samples' noise, not the shadow's shape: next to a contact, where the
//! kernel is cut by the occluder's wall, the neighbours left are all on one side and brighter.
//! SVGF stops its kernel where the luminance differs by more than a few of its estimated
//! deviations; here a neighbour whose visibility differs from the pixel's by several times
//! their estimated error (below) is told apart the same way.
//!
//! The error estimate: the two halves of the samples, told apart. The reference's two
//! halves (`half_of_index` in `samples.rs`: its two independently scrambled sequences) each
//! cover the whole light; every pixel keeps the second half's sums beside the whole's, and the
//! filter averages both with the same weights. The two halves' estimates err independently
//! (two randomisations of one design), and the whole's is their mean, so for errors e_a, e_b
//! symmetric about 0, E|e_a − e_b| / 2 = E|e_a + e_b| / 2: half the halves' difference is an
//! estimate of the whole's error with no constant to fit (`estimate::halves_error`, which also
//! weighs halves of unequal light: a colour the light emits in a few places), and, measured
//! after the filter, it counts what the filter gathered — neighbours whose samples err together
//! as well as those that do not. Halves cut from one stratified design (blocks of a grid, or of
//! one sequence) would each be stratified worse than the whole and differ by more than its
//! error (docs/performance-log.md).
//! It misses what neither half sees: a pixel the probes left unrefined (both halves agree), and
//! the filter's own bias.

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;

use super::super::estimate::{PenumbraMean, Texel, Texels};
pub(super) use crate::render::method::Surfaces;
use crate::render::Camera;

/// Pixels a tile side, for the classification and the fallback width.
pub(super) const TILE: u32 = 8;

/// The widest a pass reaches on each side of a pixel: past it a penumbra is filtered less
/// than its width asks (its samples' banding then shows).
const MAX_RADIUS: u32 = 24;

/// The least σ filtered, in pixels: where the strata's steps are finer than half a pixel, the
/// pixel grid has averaged them already, and a kernel on the grid would only blur the ramp
/// (measured in docs/performance-log.md).
const MIN_SIGMA_PIXELS: f32 = 0.5;

/// How far the kernel reaches, in its σ.
const REACH_SIGMAS: f32 = 2.5;

/// The sharpness of the normal weight: (n·n')^this, ½ at 2° apart. Sharper than SVGF's 128:
/// where a surface bends, the part of the light above its tangent plane, and so V, can jump
/// (a faceted model's every edge), and a softer weight averages across those jumps, adding
/// error the unfiltered samples do not have (measured: docs/performance-log.md). Smooth
/// surfaces and planes keep their neighbours.
const NORMAL_POWER: i32 = 1024;

/// The unshadowed guide's sharpness: a neighbour weighs r^this, r the least ratio over the
/// channels between its Σ L·G and the pixel's (1 on a plane under a distant light, 0 where one
/// of the two sees a colour of the light the other does not). Measured on `terrain` at 1080p
/// under `stripes`, where grazing slopes see the light's stripes set one by one: 2 to 16 do
/// alike (docs/performance-log.md).
const UNSHADOWED_POWER: i32 = 4;

/// How far apart two pixels' visibilities may be and still be averaged, in their estimated
/// errors: a Gaussian of this many errors (SVGF's luminance weight stops at 4 deviations of an
/// L1 distance; measured from 4 to 16, docs/performance-log.md).
const VISIBILITY_ERRORS: f32 = 8.0;

/// The least error the visibility weight assumes: where both halves agree (a pixel in a
/// stratum's step, or one its probes settled) the estimate is 0, and a step of the strata
/// must still be smoothed.
const LEAST_ERROR: f32 = 0.01;

/// What a pixel's samples say of its shadow: its gray visibility and estimated error, taken
/// once per pixel a pass reads (the error costs three square roots).
#[derive(Debug, Clone, Copy)]
struct Verdict {
    gray: f32,
    error: f32,
}

impl Verdict {
    fn of(texel: &Texel) -> Self {
        // Samples that all agree, in both halves (a neighbour its probes settled), have no
        // error, as `Texel::error` would find (each half's ratio the same 1, or 0).
        if texel.lit_by_every_sample() || (texel.shadowed == [0.0; 3] && texel.half_shadowed == [0.0; 3]) {
            return Self { gray: texel.gray(), error: 0.0 };
        }
        Self { gray: texel.gray(), error: texel.error() }
    }
}

/// What the samples say a neighbour must share with a pixel to be averaged with it (module
/// docs): the light it sees unshadowed, and its visibility within their errors.
struct Guide {
    unshadowed: [f32; 3],
    verdict: Verdict,
}

impl Guide {
    /// Neighbour `q`'s weight, from 0 to 1, given its geometry's as exp(`exponent`) (one
    /// exponential for both); its first `channels` are read (1: the gray one stands for all).
    fn weight(&self, q: &Texel, verdict: Verdict, exponent: f32, channels: usize) -> f32 {
        let seen = (0..channels).fold(1.0f32, |least, c| {
            let (a, b) = (self.unshadowed[c], q.unshadowed[c]);
            if a.max(b) > 0.0 {
                least.min(a.min(b) / a.max(b))
            } else {
                least // Neither sees this colour.
            }
        });
        let tolerance = VISIBILITY_ERRORS * (0.5 * (self.verdict.error + verdict.error)).max(LEAST_ERROR);
        let apart = (self.verdict.gray - verdict.gray) / tolerance;
        seen.powi(UNSHADOWED_POWER) * (exponent - 0.5 * apart * apart).exp()
    }
}

/// What a pixel's own samples say of it.
fn state(texel: &Texel) -> State {
    if !texel.lit_at_all() {
        State::Dark
    } else if texel.shadowed == texel.unshadowed {
        State::Lit
    } else if texel.shadowed == [0.0; 3] {
        State::Umbra
    } else {
        State::Mixed
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
    /// The effective count of a refined pixel's samples (`estimate::PenumbraMean`).
    pub samples_effective: f32,
    pub camera: &'a Camera,
    /// A surface's depth from the light's plane (`cpu::TestConstants::depth_of`).
    pub depth_of: &'a (dyn Fn(Vec3) -> f32 + Sync),
}

/// The filtered texels of the `written` rows, with what the filter did there.
pub(super) struct FilterOutput {
    pub texels: Texels,
    pub pixels_filtered: usize,
    /// The effective count of a refined pixel's samples (`FilterInputs`).
    samples_effective: f32,
}

impl FilterOutput {
    /// Writes the visibility of texels `range`, whole rows of `width`, into `out` as
    /// `vec4<f32>` texels (rgb, and w the estimated error), and adds the estimate's sum over
    /// their penumbra to `penumbra` — row by row on every core, the rows' sums added in order:
    /// the same mean however the rows are cut into calls or bands.
    pub fn write_visibility(&self, range: Range<usize>, width: usize, out: &mut [u8], penumbra: &mut PenumbraMean) {
        debug_assert_eq!(out.len(), range.len() * 16);
        let rows: Vec<PenumbraMean> = out
            .par_chunks_mut(width * 16)
            .enumerate()
            .map(|(r, row)| {
                let mut mean = PenumbraMean::default();
                for (x, texel) in row.chunks_exact_mut(16).enumerate() {
                    let mut write = |v: [f32; 4]| texel.copy_from_slice(bytemuck::bytes_of(&v));
                    let t = self.texels.get(range.start + r * width + x);
                    // Samples that all agree, in both halves (most pixels: those the probes
                    // settled), say 1 or 0 with no error and no penumbra, to the bit as the
                    // general case would.
                    if t.lit_by_every_sample() || !t.lit_at_all() {
                        write([1.0, 1.0, 1.0, 0.0]);
                        continue;
                    }
                    if t.shadowed == [0.0; 3] {
                        write([0.0; 4]);
                        continue;
                    }
                    let ([red, green, blue], error) = (t.visibility(), t.error());
                    write([red, green, blue, error]);
                    mean.add(&t, error, self.samples_effective);
                }
                mean
            })
            .collect();
        for row in rows {
            penumbra.merge(row);
        }
    }
}

/// The pixels to test against every sample: the surfaces in the tiles that vary, by their
/// probes — or, in a `lit` tile (`cpu::lit_tiles`), lit by every probe without a test.
///
/// A surface that no probe lights (`Dark`) counts as a state of its own: next to lit or
/// shadowed pixels it is a terminator, where the probes may all lie below a horizon the other
/// samples clear. A pixel without a surface counts for nothing.
pub(super) fn refined(surfaces: &Surfaces, texels: &Texels, lit: Option<&[bool]>) -> Vec<bool> {
    let tiles = Tiles::new(surfaces.width, surfaces.height);
    let (width, height) = (surfaces.width as usize, surfaces.height as usize);
    let covered = |i: usize| has_surface(surfaces, i);
    // Per tile: the states its pixels' probes are in, a bit per `State` (a row of tiles a task).
    let states: Vec<u8> = (0..tiles.rows as usize)
        .into_par_iter()
        .flat_map_iter(|ty| {
            let mut row = vec![0u8; tiles.columns as usize];
            let lit = |x: usize| lit.is_some_and(|lit| lit[ty * tiles.columns as usize + x / TILE as usize]);
            for y in ty * TILE as usize..((ty + 1) * TILE as usize).min(height) {
                for (x, i) in (y * width..(y + 1) * width).enumerate().filter(|&(_, i)| covered(i)) {
                    let state = if lit(x) { State::Lit } else { state(&texels.get(i)) };
                    row[x / TILE as usize] |= 1 << state as u8;
                }
            }
            row
        })
        .collect();
    // A tile varies with a mixed pixel around it, or two of the states.
    let varies: Vec<bool> = (0..tiles.count())
        .into_par_iter()
        .map(|t| {
            let seen = tiles.around_tile(t).fold(0u8, |seen, t| seen | states[t]);
            seen & (1 << State::Mixed as u8) != 0 || seen.count_ones() > 1
        })
        .collect();
    (0..texels.len()).into_par_iter().map(|i| covered(i) && varies[tiles.of(i)]).collect()
}

/// The tiles (rows of ⌈width / `TILE`⌉) whose texels the filter may read: those within its
/// reach (`MAX_RADIUS`, along a row or a column) of a `refined` pixel, which it filters.
pub(super) fn read_tiles(refined: &[bool], width: u32, height: u32) -> Vec<bool> {
    let tiles = Tiles::new(width, height);
    let (columns, rows) = (tiles.columns as usize, tiles.rows as usize);
    let mut holds = vec![false; tiles.count()];
    for (i, _) in refined.iter().enumerate().filter(|(_, &r)| r) {
        holds[tiles.of(i)] = true;
    }
    // A pixel's reach ends at most this many tiles past its own; the square of tiles around
    // each, a row's then a column's.
    let reach = MAX_RADIUS.div_ceil(TILE) as usize;
    let near = |at: usize, len: usize| at.saturating_sub(reach)..(at + reach + 1).min(len);
    let across: Vec<bool> = (0..tiles.count()).map(|t| near(t % columns, columns).any(|x| holds[t - t % columns + x])).collect();
    (0..tiles.count()).map(|t| near(t / columns, rows).any(|y| across[y * columns + t % columns])).collect()
}

/// Every pixel with a surface: a frame refined everywhere.
pub(super) fn covered(surfaces: &Surfaces) -> Vec<bool> {
    (0..surfaces.normals.len()).into_par_iter().map(|i| has_surface(surfaces, i)).collect()
}

/// Whether a surface covers pixel `i` (`Surfaces::normal` by index).
fn has_surface(surfaces: &Surfaces, i: usize) -> bool {
    surfaces.normals[i] != Vec3::ZERO
}

/// Filters the `refined` pixels' `texels` over `surfaces`, sized by `blockers` ([blockers
/// met, their summed depth from the light's plane] per pixel) and the receiver's own depth.
pub(super) fn filter(
    inputs: &FilterInputs<'_>,
    surfaces: &Surfaces,
    mut texels: Texels,
    blockers: &[[f32; 2]],
    refined: &[bool],
) -> FilterOutput {
    let (width, height) = (inputs.width as usize, inputs.height as usize);
    // Only refined pixels are filtered: the others' probes agree (V 0 or 1).
    let listed: Vec<usize> = (0..width * height).into_par_iter().filter(|&i| refined[i]).collect();
    let written = inputs.written.start as usize * width..inputs.written.end as usize * width;
    if inputs.scale <= 0.0 || listed.is_empty() {
        return output(texels, written, 0, inputs.samples_effective);
    }
    // A pixel's footprint in the world at its distance (the slant of its surface aside).
    let per_distance = 2.0 * (0.5 * inputs.camera.fov_y_deg.to_radians()).tan() / inputs.frame_height as f32;
    let footprint = |i: usize| footprint(surfaces, inputs.camera.eye, per_distance, i);
    // σ from the pixel's own blockers, where it met any; else the mean of the tiles around.
    let own_sigma: Vec<f32> = listed
        .par_iter()
        .map(|&i| {
            let [count, depth] = blockers[i];
            let receiver = (inputs.depth_of)(surfaces.positions[i]);
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
    let pass = Pass {
        listed: &listed,
        kernels: &kernels,
        surfaces,
        width,
        height,
        channels: texels.channels(),
        eye: inputs.camera.eye,
        per_distance,
    };
    // The verdicts of what each pass reads, listed pixels' taken once; an unlisted neighbour's
    // (its probes' 0 or 1) as it is read.
    let verdict_of =
        |listed: &[Verdict], j: usize| if slot[j] == u32::MAX { Verdict::of(&texels.get(j)) } else { listed[slot[j] as usize] };
    let first: Vec<Verdict> = listed.par_iter().map(|&i| Verdict::of(&texels.get(i))).collect();
    let rows = pass.run(|j| texels.get(j), |j| verdict_of(&first, j), (1, 0));
    drop(first);
    let second: Vec<Verdict> = (0..listed.len()).into_par_iter().map(|k| Verdict::of(&rows.get(k))).collect();
    let both =
        pass.run(|j| if slot[j] == u32::MAX { texels.get(j) } else { rows.get(slot[j] as usize) }, |j| verdict_of(&second, j), (0, 1));
    for (k, &i) in listed.iter().enumerate() {
        texels.set(i, both.get(k));
    }
    output(texels, written, pixels_filtered, inputs.samples_effective)
}

/// Pixel `i`'s footprint in the world at its distance from the `eye` (`per_distance` a unit
/// of distance; the slant of its surface aside).
#[inline]
fn footprint(surfaces: &Surfaces, eye: Vec3, per_distance: f32, i: usize) -> f32 {
    (surfaces.positions[i] - eye).length() * per_distance
}

/// One pass of the filter over the listed pixels, by their kernels.
struct Pass<'a> {
    listed: &'a [usize],
    /// Each listed pixel's σ (world) and reach (pixels; 0: not filtered).
    kernels: &'a [(f32, u32)],
    surfaces: &'a Surfaces,
    width: usize,
    height: usize,
    channels: usize,
    eye: Vec3,
    per_distance: f32,
}

impl Pass<'_> {
    /// The listed pixels' texels averaged along `step` (a row: (1, 0); a column: (0, 1)); a
    /// neighbour's sums are `read(j)` and its verdict `verdict(j)`.
    fn run(&self, read: impl Fn(usize) -> Texel + Sync, verdict: impl Fn(usize) -> Verdict + Sync, step: (isize, isize)) -> Texels {
        let Self { listed, kernels, surfaces, width, height, channels, eye, per_distance } = *self;
        Texels::par_from_fn(listed.len(), channels, |k| {
            let (i, (sigma, radius)) = (listed[k], kernels[k]);
            let own = read(i);
            if radius == 0 {
                return own;
            }
            let guide = Guide { unshadowed: own.unshadowed, verdict: verdict(i) };
            let (x, y) = ((i % width) as isize, (i / width) as isize);
            let (p, n) = (surfaces.positions[i], surfaces.normals[i]);
            let inv_two_sigma2 = 0.5 / (sigma * sigma);
            let tolerance = 0.5 * sigma + footprint(surfaces, eye, per_distance, i);
            let inv_two_tolerance2 = 0.5 / (tolerance * tolerance);
            let mut sum = Texel::UNCOVERED;
            let mut weights = 0.0f32;
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
                let exponent = -d.length_squared() * inv_two_sigma2 - plane * plane * inv_two_tolerance2;
                let w = guide.weight(&q, verdict(j), exponent, channels) * facing;
                for c in 0..channels {
                    sum.shadowed[c] += w * q.shadowed[c];
                    sum.unshadowed[c] += w * q.unshadowed[c];
                    sum.half_shadowed[c] += w * q.half_shadowed[c];
                    sum.half_unshadowed[c] += w * q.half_unshadowed[c];
                }
                weights += w;
            }
            if weights <= 0.0 {
                return own;
            }
            if channels == 1 {
                // The gray sums stand for all three.
                for sums in [&mut sum.shadowed, &mut sum.unshadowed, &mut sum.half_shadowed, &mut sum.half_unshadowed] {
                    *sums = [sums[0]; 3];
                }
            }
            let mean = |sums: [f32; 3]| sums.map(|s| s / weights);
            Texel {
                shadowed: mean(sum.shadowed),
                unshadowed: mean(sum.unshadowed),
                half_shadowed: mean(sum.half_shadowed),
                half_unshadowed: mean(sum.half_unshadowed),
            }
        })
    }
}

/// The `written` texels (the rest let go).
fn output(mut texels: Texels, written: Range<usize>, pixels_filtered: usize, samples_effective: f32) -> FilterOutput {
    texels.keep(written);
    FilterOutput { texels, pixels_filtered, samples_effective }
}

/// The frame in tiles of `TILE`², rows of them: the refinement's classes, the fallback σ and
/// the tiles found lit (`cpu::lit_tiles`).
pub(super) struct Tiles {
    width: u32,
    columns: u32,
    rows: u32,
}

impl Tiles {
    pub(super) fn new(width: u32, height: u32) -> Self {
        Self { width, columns: width.div_ceil(TILE), rows: height.div_ceil(TILE) }
    }

    fn count(&self) -> usize {
        (self.columns * self.rows) as usize
    }

    /// The tiles of pixel rows `rows` (whole rows of tiles: `rows` begins on a tile's edge).
    pub(super) fn of_rows(&self, rows: Range<u32>) -> Range<usize> {
        let columns = self.columns as usize;
        (rows.start / TILE) as usize * columns..(rows.end.div_ceil(TILE) as usize * columns).min(self.count())
    }

    /// The tile of pixel `i`.
    pub(super) fn of(&self, i: usize) -> usize {
        let (x, y) = (i as u32 % self.width, i as u32 / self.width);
        ((y / TILE) * self.columns + x / TILE) as usize
    }

    /// The tiles around pixel `i`'s, its own included.
    fn around(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        self.around_tile(self.of(i))
    }

    /// The tiles around tile `t`, itself included.
    fn around_tile(&self, t: usize) -> impl Iterator<Item = usize> + '_ {
        let (tx, ty) = ((t as u32 % self.columns) as i64, (t as u32 / self.columns) as i64);
        (ty - 1..=ty + 1)
            .flat_map(move |j| (tx - 1..=tx + 1).map(move |i| (i, j)))
            .filter(|&(i, j)| i >= 0 && j >= 0 && i < self.columns as i64 && j < self.rows as i64)
            .map(|(i, j)| (j * self.columns as i64 + i) as usize)
    }
}
