//! Drawing the scene's triangles: one pipeline builder for every pass that rasterises the
//! scene (the shadow map, the G-buffer, the reference's per-sample depth maps), with the one
//! vertex layout of `scene::Vertex`, depth testing, no culling (contract §1: back faces cast
//! shadows), and the attachments those passes clear.

use crate::gpu::shaders;
use crate::scene::Vertex;

/// The depth buffer of every scene-drawing pass.
pub const DEPTH_BUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// A pipeline that draws the scene: `shader`'s `vs_main` and its `fragment` entry, these bind groups,
/// these colour targets, and a depth test that writes depth.
pub struct ScenePipeline<'a> {
    pub label: &'static str,
    pub shader: &'static str,
    /// The fragment entry point (`fs_main` unless a shader has several), or None for a pass
    /// that writes depth alone: no fragment shader runs, only the rasteriser's own depth test
    /// and write — on lavapipe the cheapest pass there is.
    pub fragment: Option<&'static str>,
    pub bind_group_layouts: &'a [&'a wgpu::BindGroupLayout],
    pub targets: &'a [wgpu::TextureFormat],
    /// `Less` for depth cleared to 1 (`depth_attachment`); `Greater` for a reversed-Z
    /// projection, cleared to 0.
    pub depth_compare: wgpu::CompareFunction,
}

impl ScenePipeline<'_> {
    pub fn build(&self, device: &wgpu::Device) -> wgpu::RenderPipeline {
        let module = shaders::module(device, self.shader);
        let groups: Vec<Option<&wgpu::BindGroupLayout>> = self.bind_group_layouts.iter().map(|l| Some(*l)).collect();
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(self.label),
            bind_group_layouts: &groups,
            immediate_size: 0,
        });
        let targets: Vec<Option<wgpu::ColorTargetState>> = self.targets.iter().map(|f| Some((*f).into())).collect();
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(self.label),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(vertex_layout())],
            },
            primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_BUFFER_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(self.depth_compare),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: self.fragment.map(|entry| wgpu::FragmentState {
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        })
    }
}

/// `scene::Vertex` as the vertex shaders read it: position, normal, uv, object id, material.
pub fn vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    const ATTRIBUTES: [wgpu::VertexAttribute; 5] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Uint32, 4 => Uint32];
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &ATTRIBUTES,
    }
}

/// Begins a pass that draws the scene: clears these attachments, sets `pipeline`, the frame's
/// group 0 and the scene's vertex and index buffers; the caller issues the draws.
pub fn begin_scene_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &'static str,
    color_attachments: &[Option<wgpu::RenderPassColorAttachment<'_>>],
    depth: &wgpu::TextureView,
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'_>>,
    (pipeline, group0): (&wgpu::RenderPipeline, &wgpu::BindGroup),
    scene: &crate::gpu::scene::GpuScene,
) -> wgpu::RenderPass<'e> {
    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments,
        depth_stencil_attachment: Some(depth_attachment(depth)),
        timestamp_writes,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, group0, &[]);
    pass.set_vertex_buffer(0, scene.vertex_buffer.slice(..));
    pass.set_index_buffer(scene.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
    pass
}

/// A colour attachment cleared to `value` in every channel.
pub fn clear_attachment(view: &wgpu::TextureView, value: f64) -> wgpu::RenderPassColorAttachment<'_> {
    wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations {
            load: wgpu::LoadOp::Clear(wgpu::Color { r: value, g: value, b: value, a: value }),
            store: wgpu::StoreOp::Store,
        },
    }
}

/// A depth attachment cleared to the far plane.
pub fn depth_attachment(view: &wgpu::TextureView) -> wgpu::RenderPassDepthStencilAttachment<'_> {
    wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
        stencil_ops: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vertex buffer's attributes lie where `Vertex` puts its fields, in the order of the
    /// shaders' `@location`s.
    #[test]
    fn the_vertex_layout_matches_the_vertex() {
        use std::mem::offset_of;
        let offsets: Vec<u64> = vertex_layout().attributes.iter().map(|a| a.offset).collect();
        let fields = [
            offset_of!(Vertex, position),
            offset_of!(Vertex, normal),
            offset_of!(Vertex, uv),
            offset_of!(Vertex, object_id),
            offset_of!(Vertex, material),
        ];
        assert_eq!(offsets, fields.map(|o| o as u64));
        assert_eq!(vertex_layout().array_stride, std::mem::size_of::<Vertex>() as u64);
    }
}
