//! Method `chun-oh` (Chun & Oh 2016, "An Efficient Soft Shadow Mapping for Area Lights in
//! Various Shapes and Colors"): the PCSS filter of `filter.rs`, adaptively subdivided like a
//! quad tree where the shadow or the light is complex, each sub-region's visibility weighting
//! the colour of the matching part of the light image (§3, Fig. 3). Shader:
//! `shaders/methods/chun_oh/chun_oh.wgsl`.
//!
//! Choices where the paper is brief:
//! - Sub-regions partition the filter's one lattice of shadow tests (kept as bit rows, so a
//!   region's visibility is a few popcounts); subdividing refers to finer groups of the same
//!   tests. Under a uniform light the sum of leaves then equals the undivided average exactly,
//!   and the cost of a split is bookkeeping, as the paper's Table 1 suggests (fixed 4×4 costs
//!   1.67× the plain average, not 16×).
//! - A region splits when its visibility variance E − E² exceeds `threshold`, or when it is
//!   not 0 and the light part it maps to has a relative colour variance above
//!   `light_threshold` ("when we use a colorful area light, we subdivide the filter area even
//!   if the shadow is not very changeful"); never below 4×4.
//! - The light's colour statistics come from one pass over the image per light (the 21 regions
//!   of the quadtree, with overlaps of fractional texels), kept for later jobs.
//! - Orientation: as `filter.rs` says.

use super::filter::{self, light_regions_buffer, Uniforms, FILTER_PARAMS, MODE_ADAPTIVE, MODE_FIXED};
use super::{CounterKey, Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;
use crate::params::choice;

pub struct ChunOh;

/// Pixels whose filter split 0, 1 and 2 times (the paper's Table 2).
pub const PIXELS_SUBDIVIDED: [CounterKey; 3] =
    [CounterKey("pixels_subdivided_0"), CounterKey("pixels_subdivided_1"), CounterKey("pixels_subdivided_2")];
/// Splits only the light's colour asked for.
pub const SPLITS_FORCED_BY_LIGHT: CounterKey = CounterKey("splits_forced_by_light");

choice! {
    /// Where the quadtree splits.
    enum Mode { Adaptive = "adaptive", Fixed = "fixed" }
}
const MODE: Param<Mode> =
    Param::choice("mode", "adaptive: split where variance asks (0–2 times, the paper's default); fixed: always 4×4 (Table 1)");
const THRESHOLD: Param<f32> = Param::float(
    "threshold",
    0.2244,
    0.0,
    0.25,
    "visibility variance E − E² above which a region splits (§3; 0.25 is the maximum, so 0.25 never splits)",
);
const LIGHT_THRESHOLD: Param<f32> = Param::float(
    "light_threshold",
    0.05,
    0.0,
    1.0e6,
    "relative colour variance of the light part a region maps to above which a partly shadowed region splits",
);

const PARAMS: &[ParamSpec] = &[
    MODE.spec,
    THRESHOLD.spec,
    LIGHT_THRESHOLD.spec,
    FILTER_PARAMS[0],
    FILTER_PARAMS[1],
    FILTER_PARAMS[2],
    FILTER_PARAMS[3],
    FILTER_PARAMS[4],
    FILTER_PARAMS[5],
];

impl ShadowMethod for ChunOh {
    fn name(&self) -> &'static str {
        "chun-oh"
    }

    fn summary(&self) -> &'static str {
        "Chun & Oh 2016: PCSS filter from the cone to the light's corners, blocker-average sizing, variance-driven quadtree subdivision up to 4×4, sub-region visibility × light-image colour"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let mode = match params.get(&MODE) {
            Mode::Adaptive => MODE_ADAPTIVE,
            Mode::Fixed => MODE_FIXED,
        };
        let uniforms = Uniforms::new(ctx, params).subdividing(mode, params.get(&THRESHOLD), params.get(&LIGHT_THRESHOLD));
        let regions = light_regions_buffer(ctx);
        let counts = filter::run(ctx, "chun-oh", "methods/chun_oh/chun_oh.wgsl", uniforms, &regions)?;
        let mut counters = counts.counters(u64::from(ctx.width) * u64::from(ctx.height));
        for (key, &count) in PIXELS_SUBDIVIDED.iter().zip(&counts.levels) {
            key.set(&mut counters, f64::from(count));
        }
        SPLITS_FORCED_BY_LIGHT.set(&mut counters, f64::from(counts.forced_by_light));
        Ok(counters)
    }
}
