//! A pixel's sums of the ratio estimator (Σ L·G·V and Σ L·G per channel) with its second
//! half's apart, and what they say: the visibility, and the error estimate from the halves'
//! difference (the derivation: `filtered/filter.rs`'s module docs). Method `reference`'s CPU
//! engine and method `filtered` keep their pixels so.

use glam::Vec3;
use rayon::prelude::*;

/// The gray visibility counted as penumbra for the estimate's mean (`PenumbraMean`).
const PENUMBRA: (f32, f32) = (0.01, 0.99);

/// A pixel's sums per channel (Σ L·G·V, Σ L·G) over its samples, and over the second half of
/// them alone (module docs: the error estimate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Texel {
    pub shadowed: [f32; 3],
    pub unshadowed: [f32; 3],
    pub half_shadowed: [f32; 3],
    pub half_unshadowed: [f32; 3],
}

impl Texel {
    pub const UNCOVERED: Self = Self { shadowed: [0.0; 3], unshadowed: [0.0; 3], half_shadowed: [0.0; 3], half_unshadowed: [0.0; 3] };

    /// Adds samples' sums, of the second half or not.
    pub fn add(&mut self, shadowed: [f32; 3], unshadowed: [f32; 3], second_half: bool) {
        for c in 0..3 {
            self.shadowed[c] += shadowed[c];
            self.unshadowed[c] += unshadowed[c];
            if second_half {
                self.half_shadowed[c] += shadowed[c];
                self.half_unshadowed[c] += unshadowed[c];
            }
        }
    }

    /// The estimated error |V − Vref|, the channels' mean (module docs): per channel where both
    /// halves see its light, else from the gray sums.
    pub fn error(&self) -> f32 {
        // Three channels of the same bits (a gray light's texel, `Texels` of one channel): each
        // channel's error is the first's, and the gray sums (three times each) have light in
        // both halves exactly where the first channel has. One error, not four: the same bits.
        let same = |sums: [f32; 3]| sums[0].to_bits() == sums[1].to_bits() && sums[1].to_bits() == sums[2].to_bits();
        if [self.shadowed, self.unshadowed, self.half_shadowed, self.half_unshadowed].into_iter().all(same) {
            let Some(error) = halves_error(self.first_half(0), self.second_half(0)) else { return 0.0 };
            return [error; 3].iter().sum::<f32>() / 3.0;
        }
        self.error_by_channel()
    }

    /// `error` channel by channel, whatever the light.
    pub(super) fn error_by_channel(&self) -> f32 {
        let gray = |sums: [(f32, f32); 3]| sums.iter().fold((0.0, 0.0), |(s, u), x| (s + x.0, u + x.1));
        let Some(gray) = halves_error(gray([0, 1, 2].map(|c| self.first_half(c))), gray([0, 1, 2].map(|c| self.second_half(c)))) else {
            return 0.0; // One half has no light here: nothing to compare.
        };
        (0..3).map(|c| halves_error(self.first_half(c), self.second_half(c)).unwrap_or(gray)).sum::<f32>() / 3.0
    }

    /// Channel `c`'s sums (Σ L·G·V, Σ L·G) of the first half of the samples.
    fn first_half(&self, c: usize) -> (f32, f32) {
        (self.shadowed[c] - self.half_shadowed[c], self.unshadowed[c] - self.half_unshadowed[c])
    }

    /// Channel `c`'s sums of the second half.
    fn second_half(&self, c: usize) -> (f32, f32) {
        (self.half_shadowed[c], self.half_unshadowed[c])
    }

    /// Whether every sample, in both halves, that sees the light from here sees it unshadowed:
    /// each sum of Σ L·G·V is its Σ L·G, so V is 1 with no error, to the bit.
    pub fn lit_by_every_sample(&self) -> bool {
        self.shadowed == self.unshadowed && self.half_shadowed == self.half_unshadowed
    }

    /// Whether any sample saw the light from here (else V is undefined: 1).
    pub fn lit_at_all(&self) -> bool {
        self.unshadowed.iter().sum::<f32>() > 0.0
    }

    /// The gray ratio: the white twin's visibility.
    pub fn gray(&self) -> f32 {
        let total: f32 = self.unshadowed.iter().sum();
        if total > 0.0 {
            (self.shadowed.iter().sum::<f32>() / total).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    /// The ratio per channel (`write_visibility` in `cpu`), the gray one where a channel has
    /// no light.
    pub fn visibility(&self) -> [f32; 3] {
        let gray = self.gray();
        [0, 1, 2].map(|c| if self.unshadowed[c] > 0.0 { (self.shadowed[c] / self.unshadowed[c]).clamp(0.0, 1.0) } else { gray })
    }
}

/// Pixels' `Texel`s stored by the light's channels: under a gray light every channel holds the
/// same sums (the gray one stands for all three), so one is kept — 16 bytes a pixel instead
/// of 48 — and copied to the three as a pixel is read. The same values as a `Vec<Texel>`.
#[derive(Debug, Clone)]
pub(super) struct Texels {
    channels: usize,
    /// Per pixel: Σ L·G·V, Σ L·G, and the second half's two, each `channels` wide.
    sums: Vec<f32>,
}

impl Texels {
    /// `pixels` uncovered texels of `channels` (1 or 3) channels.
    pub fn new(pixels: usize, channels: usize) -> Self {
        assert!(channels == 1 || channels == 3, "{channels} channels");
        Self { channels, sums: vec![0.0; pixels * 4 * channels] }
    }

    /// These texels, `channels` of them kept (1: the first stands for all three).
    #[cfg(test)]
    pub fn from_texels(channels: usize, texels: impl IntoIterator<Item = Texel>) -> Self {
        let mut all = Self::new(0, channels);
        for texel in texels {
            all.sums.resize(all.sums.len() + 4 * channels, 0.0);
            all.set(all.len() - 1, texel);
        }
        all
    }

    /// The channels kept a sum: 1 or 3.
    pub fn channels(&self) -> usize {
        self.channels
    }

    pub fn len(&self) -> usize {
        self.sums.len() / (4 * self.channels)
    }

    /// Pixel `i`'s sums.
    #[inline]
    pub fn get(&self, i: usize) -> Texel {
        if self.channels == 1 {
            let &[s, u, hs, hu] = self.sums[4 * i..4 * i + 4].first_chunk::<4>().expect("a texel");
            Texel { shadowed: [s; 3], unshadowed: [u; 3], half_shadowed: [hs; 3], half_unshadowed: [hu; 3] }
        } else {
            let at = self.sums[12 * i..12 * i + 12].first_chunk::<12>().expect("a texel");
            let three = |k: usize| [at[3 * k], at[3 * k + 1], at[3 * k + 2]];
            Texel { shadowed: three(0), unshadowed: three(1), half_shadowed: three(2), half_unshadowed: three(3) }
        }
    }

    /// `len` texels of `channels` channels, texel k `make(k)`, made on every core.
    pub fn par_from_fn(len: usize, channels: usize, make: impl Fn(usize) -> Texel + Sync) -> Self {
        let mut all = Self::new(len, channels);
        all.sums.par_chunks_mut(4 * channels).enumerate().for_each(|(k, at)| store(at, make(k)));
        all
    }

    /// Sets pixel `i`'s sums (its first channel alone under a gray light).
    #[inline]
    pub fn set(&mut self, i: usize, texel: Texel) {
        let c = self.channels;
        store(&mut self.sums[4 * c * i..4 * c * (i + 1)], texel);
    }

    /// `Texel::add` to pixel `i`.
    #[inline]
    pub fn add(&mut self, i: usize, shadowed: [f32; 3], unshadowed: [f32; 3], second_half: bool) {
        let c = self.channels;
        let at = &mut self.sums[4 * c * i..4 * c * (i + 1)];
        let (whole, half) = at.split_at_mut(2 * c);
        for k in 0..c {
            whole[k] += shadowed[k];
            whole[c + k] += unshadowed[k];
            if second_half {
                half[k] += shadowed[k];
                half[c + k] += unshadowed[k];
            }
        }
    }

    /// Keeps the texels `range` alone.
    pub fn keep(&mut self, range: std::ops::Range<usize>) {
        let per = 4 * self.channels;
        self.sums.truncate(range.end * per);
        self.sums.drain(..range.start * per);
    }
}

/// Stores `texel` in a `Texels` pixel's sums, `at`: its channels are `at`'s length over 4.
#[inline]
fn store(at: &mut [f32], texel: Texel) {
    let sums = [texel.shadowed, texel.unshadowed, texel.half_shadowed, texel.half_unshadowed];
    if let Some(at) = at.first_chunk_mut::<12>() {
        *at = bytemuck::cast(sums);
    } else if let Some(at) = at.first_chunk_mut::<4>() {
        *at = sums.map(|s| s[0]);
    }
}

/// The error of the ratio of two halves' sums taken together, from the halves' sums
/// ((Σ L·G·V, Σ L·G) each): |V_a − V_b| · √(α(1 − α)), α the first half's share of Σ L·G. The
/// whole's error is α e_a + (1 − α) e_b; with independent errors whose variances go as 1/α and
/// 1/(1 − α), its spread is that of e_a − e_b times √(α(1 − α)) — half of it for equal halves.
/// `None` where a half has no light.
fn halves_error((s_a, u_a): (f32, f32), (s_b, u_b): (f32, f32)) -> Option<f32> {
    if u_a <= 0.0 || u_b <= 0.0 {
        return None;
    }
    let (v_a, v_b) = ((s_a / u_a).clamp(0.0, 1.0), (s_b / u_b).clamp(0.0, 1.0));
    let alpha = u_a / (u_a + u_b);
    Some((v_a - v_b).abs() * (alpha * (1.0 - alpha)).sqrt())
}

/// The mean over a frame's penumbra of its pixels' error estimates, as `compare` measures the
/// error: over the pixels the truth (`reference` of many samples) sees in penumbra, some channel
/// of V in (ε, 1 − ε) (`quality::penumbra_mask`). A few samples see fewer pixels so: a pixel of
/// visibility v is in their penumbra only where they neither all see the light nor all miss it,
/// with a chance p(v) = 1 − vⁿ − (1 − v)ⁿ for n samples of equal weight — at 16 samples, three
/// quarters of the truth's penumbra on the built-in scenes, half under `flame`. So the
/// penumbra's size is estimated as Horvitz and Thompson estimate a population's from a sample
/// (1952): each pixel whose own gray visibility v̂ is within `PENUMBRA` counts 1/p(v̂), n the
/// samples' effective count (Kish's (Σw)²/Σw²: fewer where the light's samples weigh
/// unequally). The errors of the pixels no sample saw partly shadowed (small: their v is within
/// about 1/n of 0 or 1) are not counted. Measured against the truth: docs/performance-log.md.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct PenumbraMean {
    error_sum: f64,
    pixels: f64,
}

impl PenumbraMean {
    /// Counts a pixel, `error` its `Texel::error` (taken once, by the caller that writes it),
    /// `samples` the effective count of the samples it was estimated from.
    pub fn add(&mut self, texel: &Texel, error: f32, samples: f32) {
        let gray = texel.gray();
        if !texel.lit_at_all() || gray <= PENUMBRA.0 || gray >= PENUMBRA.1 {
            return;
        }
        // The chance of a pixel seen partly shadowed, at least that of one sample's worth of
        // shadow (v = 1/n): a v̂ nearer 0 or 1 comes of a light sample of little weight. Fewer
        // than two samples' worth (a light whose few samples weigh very unequally) counts as
        // two: a pixel seen partly shadowed then stands for at most two.
        let n = samples.max(2.0);
        let v = gray.clamp(1.0 / n, 1.0 - 1.0 / n);
        let seen = (1.0 - v.powf(n) - (1.0 - v).powf(n)).max(f32::EPSILON);
        self.error_sum += f64::from(error);
        self.pixels += f64::from(1.0 / seen);
    }

    pub fn merge(&mut self, other: Self) {
        self.error_sum += other.error_sum;
        self.pixels += other.pixels;
    }

    /// The mean error over the estimated penumbra; 0 without one.
    pub fn mean(&self) -> f64 {
        if self.pixels > 0.0 {
            self.error_sum / self.pixels
        } else {
            0.0
        }
    }

    /// The penumbra's estimated size, in pixels.
    pub fn pixels(&self) -> f64 {
        self.pixels
    }
}

/// Kish's effective count of samples of these weights, (Σw)²/Σw² of their gray weights: the
/// count of equal-weight samples whose mean is as noisy.
pub(super) fn effective_samples(weights: impl Iterator<Item = Vec3>) -> f32 {
    let (sum, squares) =
        weights.map(|w| w.element_sum()).fold((0.0f64, 0.0f64), |(s, q), w| (s + f64::from(w), q + f64::from(w) * f64::from(w)));
    if squares > 0.0 {
        (sum * sum / squares) as f32
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A texel of visibility `v` (every channel) whose halves differ by `spread`.
    fn texel(v: f32, spread: f32) -> Texel {
        let mut t = Texel::UNCOVERED;
        t.add([v - spread; 3], [1.0; 3], false);
        t.add([v + spread; 3], [1.0; 3], true);
        t
    }

    /// Counts `t` in `mean`, with its own error.
    fn counted(mean: &mut PenumbraMean, t: Texel, samples: f32) {
        mean.add(&t, t.error(), samples);
    }

    #[test]
    fn the_penumbra_mean_counts_each_pixel_by_its_chance_to_be_seen() {
        // Many samples: every pixel in a penumbra is seen, and the mean is the plain mean.
        let mut many = PenumbraMean::default();
        for (v, spread) in [(0.3, 0.01), (0.5, 0.03), (0.8, 0.02)] {
            counted(&mut many, texel(v, spread), 4096.0);
        }
        assert!((many.pixels() - 3.0).abs() < 1e-6 && (many.mean() - 0.02).abs() < 1e-6, "{many:?}");
        // Two samples see a pixel of v = ½ partly shadowed half the time: it stands for two.
        let mut two = PenumbraMean::default();
        counted(&mut two, texel(0.5, 0.25), 2.0);
        assert!((two.pixels() - 2.0).abs() < 1e-5, "{two:?}");
        assert!((two.mean() - 0.125).abs() < 1e-5, "{two:?}");
        // Less than two samples' worth (unequal weights): as two, never a degenerate clamp.
        for samples in [0.0, 1.0, 1.5, 1.98] {
            let mut few = PenumbraMean::default();
            counted(&mut few, texel(0.3, 0.1), samples);
            assert!((few.pixels() - 2.0).abs() < 1e-5, "{samples}: {few:?}");
        }
        // Pixels out of the penumbra count nothing.
        let mut none = PenumbraMean::default();
        counted(&mut none, texel(1.0, 0.0), 16.0);
        counted(&mut none, texel(0.0, 0.0), 16.0);
        assert_eq!((none.pixels(), none.mean()), (0.0, 0.0));
    }

    #[test]
    fn texels_of_one_channel_read_as_the_three_they_stand_for() {
        let sums = [([0.25; 3], [1.5; 3], false), ([0.5; 3], [2.0; 3], true), ([0.125; 3], [0.75; 3], true)];
        let mut whole = Texel::UNCOVERED;
        let (mut gray, mut coloured) = (Texels::new(3, 1), Texels::new(3, 3));
        for (shadowed, unshadowed, second_half) in sums {
            whole.add(shadowed, unshadowed, second_half);
            gray.add(1, shadowed, unshadowed, second_half);
            coloured.add(1, shadowed, unshadowed, second_half);
        }
        assert_eq!((gray.get(1), coloured.get(1), gray.get(0)), (whole, whole, Texel::UNCOVERED));
        // Three channels keep each its own; one keeps its first.
        let rgb = texel(0.5, 0.1);
        let rgb = Texel { shadowed: [0.1, 0.2, 0.3], ..rgb };
        coloured.set(2, rgb);
        gray.set(2, rgb);
        assert_eq!(coloured.get(2), rgb);
        assert_eq!(gray.get(2).shadowed, [0.1; 3]);
        let made = Texels::par_from_fn(3, 3, |k| coloured.get(k));
        assert_eq!((0..3).map(|k| made.get(k)).collect::<Vec<_>>(), (0..3).map(|k| coloured.get(k)).collect::<Vec<_>>());
        let mut kept = made.clone();
        kept.keep(1..3);
        assert_eq!((kept.len(), kept.get(0), kept.get(1)), (2, whole, rgb));
    }

    #[test]
    fn effective_samples_are_fewer_where_weights_differ() {
        assert!((effective_samples([Vec3::ONE; 16].into_iter()) - 16.0).abs() < 1e-4);
        // One sample of nearly all the light: about one sample's worth.
        let uneven = std::iter::once(Vec3::splat(100.0)).chain([Vec3::splat(0.01); 15]);
        assert!(effective_samples(uneven) < 1.01);
        assert_eq!(effective_samples(std::iter::empty()), 0.0);
    }
}
