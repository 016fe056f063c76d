//! Method `pcss` (Fernando 2005, "Percentage-closer soft shadows"): the shared filter pass
//! (`filter.rs`) with the plain average of its shadow tests, gray — the baseline Chun & Oh
//! 2016 compare with (`shaders/methods/pcss.wgsl`).

use super::filter::{self, Uniforms, FILTER_PARAMS};
use super::{Counters, MethodContext, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;

pub struct Pcss;

impl ShadowMethod for Pcss {
    fn name(&self) -> &'static str {
        "pcss"
    }

    fn summary(&self) -> &'static str {
        "Fernando 2005: blocker search, penumbra estimate from light size and blocker/receiver depths, percentage-closer filtering (plain average, gray)"
    }

    fn params(&self) -> &'static [ParamSpec] {
        &FILTER_PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let uniforms = Uniforms::new(ctx, params);
        // pcss reads no light colours; the binding still needs a table.
        let regions = filter::light_regions_buffer(ctx);
        let counts = filter::run(ctx, "pcss", "methods/pcss.wgsl", uniforms, &regions)?;
        Ok(counts.counters(u64::from(ctx.width) * u64::from(ctx.height)))
    }
}
