//! The reference's GPU engine: each batch's depth maps drawn into a layered texture, then one
//! accumulate pass over the listed receivers (`shaders/methods/reference/`).

use glam::UVec2;

use super::samples::SamplePlan;
use super::MethodContext;
use crate::gpu::layout;
use crate::gpu::pool::{PipelineKey, TextureKey};
use crate::render::{PixelListBuffers, ScenePipeline, DEPTH_BUFFER_FORMAT};
use crate::timing::PhaseName;

/// Samples recorded between submissions at least: the frame is submitted, progress reported
/// and cancellation checked after each batch that completes another 16 (every batch where
/// a batch holds 16 or more maps, every other one of 8 at 4096²).
pub(super) const BATCH: u64 = 16;

/// Memory the depth maps of one accumulate batch may take: 32 maps at the default 1024² and at
/// 2048², eight at 4096². Each batch but the last stores every pixel's sums and each but the
/// first reads them, and on lavapipe a pixel's stores cost about as much as a sample's test,
/// so fewer, larger batches are cheaper.
pub(super) const BATCH_MAP_BYTES: u64 = 512 << 20;

/// The most samples one accumulate pass reads; mirrors `MAX_SAMPLES` in `accumulate.wgsl`
/// (checked by a test below).
pub(super) const BATCH_SAMPLES: usize = 32;

/// Depth maps drawn before one accumulate pass reads them all: more per pass reads the
/// G-buffer and updates the sums less often, fewer keeps the maps' memory bounded.
pub(super) fn batch_layers(resolution: u32) -> u32 {
    let map_bytes = u64::from(resolution) * u64::from(resolution) * 4;
    (BATCH_MAP_BYTES / map_bytes).clamp(1, BATCH_SAMPLES as u64) as u32
}

/// One accumulate pass's samples, laid out as `Batch` in `accumulate.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct BatchUniforms {
    pub(super) rotation: [[f32; 4]; 3],
    pub(super) resolution: u32,
    pub(super) bias_texels: f32,
    pub(super) slope_bias_texels: f32,
    pub(super) plane: f32,
    pub(super) near: f32,
    pub(super) _pad: [u32; 3],
    pub(super) samples: [BatchSample; BATCH_SAMPLES],
}

/// One light sample as the accumulate pass reads it (`BatchSample` in `accumulate.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct BatchSample {
    pub(super) origin: [f32; 4],
    pub(super) radiance: [f32; 4],
}

/// Pixels of a row per listed segment; mirrors `SEGMENT` in `accumulate.wgsl` (checked by a
/// test below).
pub(super) const SEGMENT: u32 = 8;

/// A batch's depth maps: the depth buffers themselves (`sample_depth.wgsl`), one layer each of
/// a pooled array the size of the crop, drawn with every sample's projection.
pub(super) struct DepthMaps {
    /// Where each layer is drawn.
    pub(super) layer_views: Vec<wgpu::TextureView>,
    /// The whole array, as the accumulate pass reads it.
    pub(super) array_view: wgpu::TextureView,
    pub(super) pipeline: std::sync::Arc<wgpu::RenderPipeline>,
    /// Every sample's projection, one slot each (`layout::uniform_slots`).
    pub(super) projections: wgpu::BindGroup,
}

impl DepthMaps {
    pub(super) fn new(ctx: &mut MethodContext<'_>, size: UVec2, layers: u32, view_projs: &[[[f32; 4]; 4]]) -> Self {
        let device = ctx.gpu.device.clone();
        let uniform_buffer = layout::uniform_slots(&device, "Reference::samples", view_projs);
        let depth = ctx.scratch_texture(TextureKey {
            label: "Reference::depths",
            width: size.x,
            height: size.y,
            layers,
            format: DEPTH_BUFFER_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        });
        let layer_views = (0..layers)
            .map(|layer| {
                depth.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: layer,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        let array_view =
            depth.create_view(&wgpu::TextureViewDescriptor { dimension: Some(wgpu::TextureViewDimension::D2Array), ..Default::default() });
        let pipeline = depth_pipeline(ctx);
        let projections = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Reference::sample"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &layout::entries(&[layout::slot_binding::<[[f32; 4]; 4]>(&uniform_buffer)]),
        });
        Self { layer_views, array_view, pipeline, projections }
    }

    /// Draws a batch's maps, timed as `pass`: samples `first..` of the frame, whose crop origins are `origins`
    /// (`None`: no receiver of the frame falls in that map, cleared and left empty), into
    /// layers `0..`. Timed together where timestamps can be written between passes (a scope per
    /// map would take the timer's queries at 256 samples). A render pass each, though lavapipe
    /// begins every pass by waiting until the one before is rasterised: a multiview pass saved
    /// little and needs a guard against a lavapipe bug, and a batch in one pass (an atlas) would round each map's vertices
    /// differently (`docs/performance-log.md`).
    pub(super) fn draw(&self, ctx: &mut MethodContext<'_>, pass: &'static str, first: usize, origins: &[Option<UVec2>]) {
        let scene = ctx.scene;
        // The triangles that can shadow (`GpuScene::casting_runs`), as the CPU engine draws.
        let runs = scene.casting_runs(&ctx.spec.light);
        ctx.timer.time_encoder(ctx.encoder, PhaseName::Method, pass, |encoder| {
            for (layer, origin) in origins.iter().enumerate() {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("Reference::sample_depth"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &self.layer_views[layer],
                        depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                if origin.is_none() {
                    continue;
                }
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.projections, &[layout::slot_offset(first + layer)]);
                pass.set_vertex_buffer(0, scene.vertex_buffer.slice(..));
                pass.set_index_buffer(scene.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
                for run in runs.iter() {
                    pass.draw_indexed(run.clone(), 0, 0..1);
                }
            }
        });
    }
}

/// Binding 1 of an accumulate pass (`accumulate.wgsl`): the batch's depth maps, a layer each.
pub(super) fn maps_entry() -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding: 1,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Depth,
            view_dimension: wgpu::TextureViewDimension::D2Array,
            multisampled: false,
        },
        count: None,
    }
}

/// What every batch's accumulate pass binds besides its maps, and what picks its pipeline.
pub(super) struct Accumulation {
    /// The batches' uniforms, a slot each.
    pub(super) batches: wgpu::Buffer,
    /// Every covered pixel's two sums, per channel: the first batch writes them and the last
    /// reads them (a single batch needs none).
    pub(super) sums: wgpu::Buffer,
    /// The row segments that hold a receiver, and the dispatch over them.
    pub(super) segments: PixelListBuffers,
    /// How many were listed, for the counter `segments_tested`.
    pub(super) segments_count: wgpu::Buffer,
    pub(super) channels: u32,
    pub(super) cropped: bool,
}

impl Accumulation {
    /// Takes the sums from the pool and lists the segments (recorded here, before the first
    /// batch's maps).
    pub(super) fn new(ctx: &mut MethodContext<'_>, plan: &SamplePlan, batches: &[(u32, BatchUniforms)]) -> Self {
        let uniforms: Vec<BatchUniforms> = batches.iter().map(|(_, b)| *b).collect();
        let batches_buffer = layout::uniform_slots(&ctx.gpu.device, "Reference::batches", &uniforms);
        let channels = plan.channels();
        let pixels = u64::from(ctx.width) * u64::from(ctx.height);
        let sums_bytes = if batches.len() > 1 { pixels * 8 * u64::from(channels) } else { 16 };
        let sums = ctx.scratch_buffer("Reference::sums", sums_bytes, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST);
        let (segments, segments_count) = list_segments(ctx);
        let cropped = plan.crop.size != UVec2::splat(plan.resolution);
        Self { batches: batches_buffer, sums, segments, segments_count, channels, cropped }
    }

    /// Records batch `b`'s pass over the listed segments: each pixel tests the batch's `count`
    /// maps and adds `L·G·V` and `L·G` to its sums (the first batch writes them, the `last`
    /// writes their ratio to the visibility instead).
    pub(super) fn record(&self, ctx: &mut MethodContext<'_>, maps: &DepthMaps, b: usize, count: u32, last: bool) {
        // One pipeline per batch size (`SAMPLES` in accumulate.wgsl: all but the last batch
        // are full), channels of the sums, whether it is the first or last, and whether the
        // maps are cropped.
        let first = b == 0;
        let pipeline = ctx.screen_specialized(
            "reference.accumulate",
            ("methods/reference/accumulate.wgsl", "main"),
            &[
                layout::uniform_dynamic(0),
                maps_entry(),
                layout::storage_read_write(2),
                layout::storage_read_write(3),
                layout::storage_read_write(4),
            ],
            &[
                ("SAMPLES", f64::from(count)),
                ("CHANNELS", f64::from(self.channels)),
                ("FIRST", f64::from(u8::from(first))),
                ("LAST", f64::from(u8::from(last))),
                ("CROPPED", f64::from(u8::from(self.cropped))),
            ],
        );
        let group = ctx.bind(
            "Reference::accumulate",
            &pipeline,
            &[
                layout::slot_binding::<BatchUniforms>(&self.batches),
                wgpu::BindingResource::TextureView(&maps.array_view),
                self.sums.as_entire_binding(),
                ctx.visibility.as_entire_binding(),
                self.segments.list.as_entire_binding(),
            ],
        );
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, "reference_accumulate");
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        pass.set_bind_group(1, &group, &[layout::slot_offset_of::<BatchUniforms>(b)]);
        self.segments.dispatch(&mut pass);
    }
}

/// Lists the frame's row segments that hold a covered pixel (`list_segments` in
/// accumulate.wgsl, which writes the others' visibility) and sizes the batches' dispatch over
/// them: recorded once, before the first batch.
pub(super) fn list_segments(ctx: &mut MethodContext<'_>) -> (PixelListBuffers, wgpu::Buffer) {
    let segments = u64::from(ctx.width.div_ceil(SEGMENT)) * u64::from(ctx.height);
    let list = ctx.pixel_list("Reference::segments", segments);
    let shader = "methods/reference/accumulate.wgsl";
    let lister = ctx.screen_entry(
        "reference.list_segments",
        shader,
        "list_segments",
        &[layout::storage_read_write(3), layout::storage_read_write(4)],
    );
    let sizer = ctx.screen_entry(
        "reference.segments_size",
        shader,
        "segments_size",
        &[layout::storage_read_write(4), layout::storage_read_write(5)],
    );
    // Group 1 of a pipeline whose bindings are numbered as the batches' (`accumulate.wgsl`).
    let bind = |label: &'static str, pipeline: &wgpu::ComputePipeline, buffers: &[(u32, &wgpu::Buffer)]| {
        let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
            .iter()
            .map(|(binding, buffer)| wgpu::BindGroupEntry { binding: *binding, resource: buffer.as_entire_binding() })
            .collect();
        ctx.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &pipeline.get_bind_group_layout(1),
            entries: &entries,
        })
    };
    let lister_group = bind("Reference::list_segments", &lister, &[(3, ctx.visibility), (4, &list.list)]);
    let sizer_group = bind("Reference::segments_size", &sizer, &[(4, &list.list), (5, &list.groups)]);
    let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, "reference_list");
    pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
    pass.set_pipeline(&lister);
    pass.set_bind_group(1, &lister_group, &[]);
    pass.dispatch_workgroups(ctx.width.div_ceil(SEGMENT * 8), ctx.height.div_ceil(8), 1);
    pass.set_pipeline(&sizer);
    pass.set_bind_group(1, &sizer_group, &[]);
    pass.dispatch_workgroups(1, 1, 1);
    drop(pass);
    // The count, for the counter `segments_tested`.
    let count = ctx.gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("Reference::segments_count"),
        size: 4,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    ctx.encoder.copy_buffer_to_buffer(&list.list, 0, &count, 0, 4);
    (list, count)
}

/// The depth-only pipeline that draws a sample's map.
pub(super) fn depth_pipeline(ctx: &mut MethodContext<'_>) -> std::sync::Arc<wgpu::RenderPipeline> {
    let device = &ctx.gpu.device;
    ctx.pipelines.render(PipelineKey::render("reference.sample_depth", "methods/reference/sample_depth.wgsl", None, &[]), || {
        let sample_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("Reference::sample_layout"),
            entries: &[layout::uniform_dynamic(0)],
        });
        let pipeline = ScenePipeline {
            label: "Reference::sample_depth",
            shader: "methods/reference/sample_depth.wgsl",
            fragment: None,
            bind_group_layouts: &[&sample_layout],
            targets: &[],
            depth_compare: wgpu::CompareFunction::Greater,
        };
        pipeline.build(device)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_batch_matches_its_wgsl() {
        let shader = "methods/reference/accumulate.wgsl";
        crate::gpu::shaders::assert_wgsl_layout!(BatchSample, shader, "BatchSample", [origin, radiance]);
        crate::gpu::shaders::assert_wgsl_layout!(
            BatchUniforms,
            shader,
            "Batch",
            [rotation, resolution, bias_texels, slope_bias_texels, plane, near, _pad, samples]
        );
    }
}
