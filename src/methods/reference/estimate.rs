//! A pixel's sums of the ratio estimator (Σ L·G·V and Σ L·G per channel) with its second
//! half's apart, and what they say: the visibility, and the error estimate from the halves'
//! difference (the derivation: `filtered/filter.rs`'s module docs). Method `reference`'s CPU
//! engine and method `filtered` keep their pixels so.

/// The visibility range counted as penumbra for the estimate's mean.
pub(super) const PENUMBRA: (f32, f32) = (0.01, 0.99);

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
        let first = |c: usize| (self.shadowed[c] - self.half_shadowed[c], self.unshadowed[c] - self.half_unshadowed[c]);
        let second = |c: usize| (self.half_shadowed[c], self.half_unshadowed[c]);
        let gray = |sums: [(f32, f32); 3]| sums.iter().fold((0.0, 0.0), |(s, u), x| (s + x.0, u + x.1));
        let Some(gray) = halves_error(gray([0, 1, 2].map(first)), gray([0, 1, 2].map(second))) else {
            return 0.0; // One half has no light here: nothing to compare.
        };
        (0..3).map(|c| halves_error(first(c), second(c)).unwrap_or(gray)).sum::<f32>() / 3.0
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

impl Texel {
    /// The error estimate where the pixel is in a penumbra by its own samples (its gray
    /// visibility within `PENUMBRA`): what the estimate's mean over the penumbra averages.
    pub fn penumbra_error(&self) -> Option<f32> {
        let gray = self.gray();
        (self.lit_at_all() && gray > PENUMBRA.0 && gray < PENUMBRA.1).then(|| self.error())
    }
}
