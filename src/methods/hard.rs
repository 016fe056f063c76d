//! Method `hard`: classic shadow mapping from the light centre with binary visibility — the
//! baseline every soft method is measured against (DESIGN.md §2). Shader:
//! `shaders/methods/hard.wgsl`.

use wgpu::util::DeviceExt;

use super::{Counters, MethodContext, ParamKind, ParamSpec, Params, ShadowMethod};
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;

pub struct Hard;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "bias_texels",
        kind: ParamKind::Float { default: 1.5, min: 0.0, max: 64.0 },
        doc: "constant depth bias, in shadow-map texels at the receiver's depth",
    },
    ParamSpec {
        name: "slope_bias_texels",
        kind: ParamKind::Float { default: 1.0, min: 0.0, max: 64.0 },
        doc: "slope-scaled depth bias: texels × tan of the angle between normal and light",
    },
];

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

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> Counters {
        let pipeline = ctx.screen_pipeline(
            PipelineKey::new("hard"),
            "methods/hard.wgsl",
            &[layout::storage_texture(0, wgpu::TextureFormat::Rgba32Float), layout::uniform(1)],
        );
        let device = &ctx.gpu.device;
        let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("Hard::uniforms"),
            contents: bytemuck::bytes_of(&HardUniforms {
                bias_texels: params.f32("bias_texels"),
                slope_bias_texels: params.f32("slope_bias_texels"),
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
        Counters::new()
    }
}
