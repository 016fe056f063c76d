//! Method `hard`: classic shadow mapping from the light centre with binary visibility — the
//! baseline every soft method is measured against (contract §2). Shader:
//! `shaders/methods/hard.wgsl`.

use wgpu::util::DeviceExt;

use super::{Counters, MethodContext, ParamSpec, Params, ShadowMethod, BIAS_TEXELS, SLOPE_BIAS_TEXELS};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;

pub struct Hard;

const PARAMS: &[ParamSpec] = &[BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec];

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
        let pipeline = ctx.screen_pipeline(
            PipelineKey::new("hard"),
            "methods/hard.wgsl",
            &[layout::storage_texture(0, wgpu::TextureFormat::Rgba32Float), layout::uniform(1)],
        );
        let device = &ctx.gpu.device;
        let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("Hard::uniforms"),
            contents: bytemuck::bytes_of(&HardUniforms {
                bias_texels: params.get(&BIAS_TEXELS),
                slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS),
                _pad: [0.0; 2],
            }),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let outputs = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Hard::outputs"),
            layout: &pipeline.get_bind_group_layout(1),
            entries: &layout::entries(&[wgpu::BindingResource::TextureView(ctx.visibility), uniforms.as_entire_binding()]),
        });
        let (gx, gy) = ctx.dispatch_size();
        let mut pass = ctx.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("Hard::pass"),
            timestamp_writes: ctx.timer.compute_scope("method"),
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        pass.set_bind_group(1, &outputs, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
        Ok(Counters::new())
    }
}
