//! Method `hard`: classic shadow mapping from the light centre with binary visibility — the
//! baseline every soft method is measured against (contract §2). Shader:
//! `shaders/methods/hard.wgsl`.

use super::{Counters, MethodContext, ParamSpec, Params, ShadowMethod, BIAS_TEXELS, SLOPE_BIAS_TEXELS};
use crate::error::JobResult;
use crate::gpu::layout;

pub struct Hard;

const PARAMS: &[ParamSpec] = &[BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec];

/// Group 1 of the pass (`hard.wgsl`).
const BINDINGS: [wgpu::BindGroupLayoutEntry; 2] = [layout::storage_read_write(0), layout::uniform(1)];

/// `HardParams` in `hard.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct HardUniforms {
    bias_texels: f32,
    slope_bias_texels: f32,
    _pad: [f32; 2],
}

impl ShadowMethod for Hard {
    fn name(&self) -> &'static str {
        "hard"
    }

    fn summary(&self) -> &'static str {
        "one shadow map from the light centre, binary visibility (baseline)"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let pipeline = ctx.screen_pipeline("hard", "methods/hard.wgsl", &BINDINGS);
        let uniforms = ctx.uniforms(
            "Hard::uniforms",
            &HardUniforms { bias_texels: params.get(&BIAS_TEXELS), slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS), _pad: [0.0; 2] },
        );
        let outputs = ctx.bind("Hard::outputs", &pipeline, &[ctx.visibility.as_entire_binding(), uniforms.as_entire_binding()]);
        ctx.dispatch_screen("Hard::pass", &pipeline, &outputs);
        Ok(Counters::new())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_uniforms_and_bindings_match_the_shader() {
        crate::gpu::shaders::assert_wgsl_layout!(HardUniforms, "methods/hard.wgsl", "HardParams", [bias_texels, slope_bias_texels, _pad]);
        crate::gpu::shaders::assert_bindings(&["methods/hard.wgsl"], 1, &BINDINGS);
    }
}
