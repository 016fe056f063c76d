//! One frame, pass by pass: light-space shadow map → eye-space G-buffer → unshadowed
//! irradiance E0 → the method's visibility → composite → readback. The `Renderer` owns the
//! long-lived state (pipelines, target pool, timer, bind group layouts) and is reused by every
//! job; each phase is submitted and waited for on its own so its wall time is honest even on
//! adapters without timestamp queries.

pub mod frame;
pub mod method;

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;

use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::{DerivedResources, PipelineKey, PipelinePool, PooledTexture, ReadbackPool, TextureKey, TexturePool};
use crate::gpu::readback::Readback;
use crate::gpu::scene::GpuScene;
use crate::gpu::shaders;
use crate::gpu::timing::GpuTimer;
use crate::gpu::GpuContext;
use crate::light::{LightCell, E0_GRID};
use crate::render::method::{Counters, MethodContext};
use crate::scene::Vertex;
use crate::supervise::{cancelled_error, Supervisor};
use crate::timing::Timings;
pub use frame::{Camera, ExtraImages, FrameSpec, LightProjection};

/// The per-frame constants, laid out as `Frame` in `shaders/common/frame.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrameUniforms {
    view_proj: [[f32; 4]; 4],
    light_view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    view_dir: [f32; 4],
    light_center: [f32; 4],
    light_n: [f32; 4],
    light_u: [f32; 4],
    light_r: [f32; 4],
    light_proj: [f32; 4],
    ambient: [f32; 4],
    sizes: [u32; 4],
}

/// A light cell as `LightCell` in `shaders/common/light.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LightCellGpu {
    corners: [[f32; 4]; 4],
    radiance: [f32; 4],
}

/// Group 0 of every screen-space pass (`shaders/common/frame_inputs.wgsl`).
pub struct FrameInputs {
    pub layout: wgpu::BindGroupLayout,
    pub bind_group: wgpu::BindGroup,
}

/// What a frame produces on the CPU. Pixels are row-major from the top-left.
pub struct FrameOutput {
    pub width: u32,
    pub height: u32,
    /// Linear radiance and coverage alpha, RGBA.
    pub color: Vec<[f32; 4]>,
    /// Per-channel visibility V (EXR and comparisons), 1 wherever E0 = 0.
    pub visibility: Option<Vec<[f32; 3]>>,
    /// View depth in metres, +∞ for background (EXR only).
    pub depth: Option<Vec<f32>>,
    pub counters: Counters,
}

struct Layouts {
    /// Shadow-map and G-buffer group 0: frame constants and material colours.
    draw: wgpu::BindGroupLayout,
    /// G-buffer group 1: base-colour texture and sampler.
    material: wgpu::BindGroupLayout,
    inputs: wgpu::BindGroupLayout,
    e0_output: wgpu::BindGroupLayout,
    composite_io: wgpu::BindGroupLayout,
}

/// The frame's render targets, drawn from and returned to the pool.
struct FrameTargets {
    shadow_depth_buffer: PooledTexture,
    shadow_depth: PooledTexture,
    shadow_id: PooledTexture,
    shadow_position: PooledTexture,
    depth_buffer: PooledTexture,
    position: PooledTexture,
    normal: PooledTexture,
    albedo: PooledTexture,
    object_id: PooledTexture,
    e0: PooledTexture,
    visibility: PooledTexture,
    color: PooledTexture,
    depth: PooledTexture,
}

const SHADOW_DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
const DEPTH_BUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
const POSITION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
const ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
const FLOAT_TARGET: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

impl FrameTargets {
    fn alloc(pool: &mut TexturePool, device: &wgpu::Device, width: u32, height: u32, shadow: u32) -> Self {
        use wgpu::TextureUsages as U;
        let attachment = U::RENDER_ATTACHMENT | U::TEXTURE_BINDING;
        let storage = U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC;
        let mut get = |label, w, h, format, usage| pool.alloc(device, TextureKey { label, width: w, height: h, format, usage });
        Self {
            shadow_depth_buffer: get("FrameTargets::shadow_depth_buffer", shadow, shadow, DEPTH_BUFFER_FORMAT, U::RENDER_ATTACHMENT),
            shadow_depth: get("FrameTargets::shadow_depth", shadow, shadow, SHADOW_DEPTH_FORMAT, attachment),
            shadow_id: get("FrameTargets::shadow_id", shadow, shadow, ID_FORMAT, attachment),
            shadow_position: get("FrameTargets::shadow_position", shadow, shadow, POSITION_FORMAT, attachment),
            depth_buffer: get("FrameTargets::depth_buffer", width, height, DEPTH_BUFFER_FORMAT, U::RENDER_ATTACHMENT),
            position: get("FrameTargets::position", width, height, POSITION_FORMAT, attachment),
            normal: get("FrameTargets::normal", width, height, NORMAL_FORMAT, attachment),
            albedo: get("FrameTargets::albedo", width, height, ALBEDO_FORMAT, attachment),
            object_id: get("FrameTargets::object_id", width, height, ID_FORMAT, attachment),
            e0: get("FrameTargets::e0", width, height, FLOAT_TARGET, storage),
            visibility: get("FrameTargets::visibility", width, height, FLOAT_TARGET, storage),
            color: get("FrameTargets::color", width, height, FLOAT_TARGET, storage),
            depth: get("FrameTargets::depth", width, height, wgpu::TextureFormat::R32Float, storage),
        }
    }

    fn release(self, pool: &mut TexturePool) {
        for t in [
            self.shadow_depth_buffer,
            self.shadow_depth,
            self.shadow_id,
            self.shadow_position,
            self.depth_buffer,
            self.position,
            self.normal,
            self.albedo,
            self.object_id,
            self.e0,
            self.visibility,
            self.color,
            self.depth,
        ] {
            pool.release(t);
        }
    }
}

pub struct Renderer {
    gpu: Arc<GpuContext>,
    pub pipelines: PipelinePool,
    pub textures: TexturePool,
    pub derived: DerivedResources,
    pub readbacks: ReadbackPool,
    timer: GpuTimer,
    layouts: Layouts,
    uniforms: wgpu::Buffer,
    cells: wgpu::Buffer,
}

impl Renderer {
    pub fn new(gpu: Arc<GpuContext>) -> Self {
        let device = &gpu.device;
        let bgl = |label, entries: &[wgpu::BindGroupLayoutEntry]| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries })
        };
        let layouts = Layouts {
            draw: bgl("Renderer::draw_layout", &[layout::uniform(0), layout::storage_read(1)]),
            material: bgl("Renderer::material_layout", &[layout::texture_filterable(0), layout::sampler(1)]),
            inputs: bgl(
                "Renderer::inputs_layout",
                &[
                    layout::uniform(0),
                    layout::texture_float(1),
                    layout::texture_float(2),
                    layout::texture_float(3),
                    layout::texture_uint(4),
                    layout::texture_float(5),
                    layout::texture_uint(6),
                    layout::storage_read(7),
                    layout::texture_float(8),
                ],
            ),
            e0_output: bgl("Renderer::e0_output_layout", &[layout::storage_texture(0, FLOAT_TARGET)]),
            composite_io: bgl(
                "Renderer::composite_io_layout",
                &[
                    layout::texture_float(0),
                    layout::texture_float(1),
                    layout::storage_texture(2, FLOAT_TARGET),
                    layout::storage_texture(3, wgpu::TextureFormat::R32Float),
                ],
            ),
        };
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Renderer::uniforms"),
            size: std::mem::size_of::<FrameUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let cells = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Renderer::cells"),
            size: (E0_GRID * E0_GRID) as u64 * std::mem::size_of::<LightCellGpu>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let timer = GpuTimer::new(&gpu);
        Self {
            gpu,
            pipelines: PipelinePool::default(),
            textures: TexturePool::default(),
            derived: DerivedResources::default(),
            readbacks: ReadbackPool::default(),
            timer,
            layouts,
            uniforms,
            cells,
        }
    }

    pub fn gpu(&self) -> &Arc<GpuContext> {
        &self.gpu
    }

    /// The layout scenes need for their material bind groups.
    pub fn material_layout(&self) -> &wgpu::BindGroupLayout {
        &self.layouts.material
    }

    /// Renders one frame and records its phases in `timings`; stops between phases (and
    /// between a long method's batches) once `supervisor` says the job is cancelled.
    pub fn render(
        &mut self,
        scene: &GpuScene,
        spec: &FrameSpec,
        timings: &mut Timings,
        supervisor: &dyn Supervisor,
    ) -> JobResult<FrameOutput> {
        let compiled_before = self.pipelines.stats.created;
        self.timer.begin_frame();
        let targets = FrameTargets::alloc(&mut self.textures, &self.gpu.device, spec.width, spec.height, spec.shadow_resolution);
        let frame = self.render_into(&targets, scene, spec, timings, supervisor);
        // A cancelled frame gives its targets back too: the next job reuses them.
        targets.release(&mut self.textures);
        timings.pipelines_compiled += self.pipelines.stats.created - compiled_before;
        frame
    }

    fn render_into(
        &mut self,
        targets: &FrameTargets,
        scene: &GpuScene,
        spec: &FrameSpec,
        timings: &mut Timings,
        supervisor: &dyn Supervisor,
    ) -> JobResult<FrameOutput> {
        let gpu = self.gpu.clone();
        let device = &gpu.device;
        let go_on = || if supervisor.cancelled() { Err(cancelled_error()) } else { Ok(()) };
        let projection = LightProjection::fit(&spec.light, &scene.corners());
        self.write_constants(spec, &projection);
        let encoder = || device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Renderer::encoder") });
        let submit = |encoder: wgpu::CommandEncoder| -> JobResult<()> {
            gpu.queue.submit([encoder.finish()]);
            Ok(gpu.wait_idle()?)
        };

        // Shadow map from the light centre.
        let start = Instant::now();
        let mut enc = encoder();
        self.record_shadow_map(&mut enc, scene, targets);
        submit(enc)?;
        let start = timings.phase("shadow_map", start);
        go_on()?;

        // Eye-space G-buffer.
        let mut enc = encoder();
        self.record_gbuffer(&mut enc, scene, targets);
        submit(enc)?;
        let start = timings.phase("gbuffer", start);
        go_on()?;

        let inputs = self.frame_inputs(targets);

        // Unshadowed irradiance E0.
        let mut enc = encoder();
        self.record_e0(&mut enc, &inputs, targets, spec);
        submit(enc)?;
        let start = timings.phase("e0", start);
        go_on()?;

        // The method's visibility.
        let mut enc = encoder();
        let counters = {
            let mut ctx = MethodContext {
                gpu: &gpu,
                pipelines: &mut self.pipelines,
                derived: &mut self.derived,
                inputs: &inputs,
                visibility: &targets.visibility.view,
                width: spec.width,
                height: spec.height,
                encoder: &mut enc,
                timer: &mut self.timer,
                scene,
                spec,
                projection: &projection,
                supervisor,
            };
            spec.method.record(&mut ctx, &spec.params)?
        };
        submit(enc)?;
        let start = timings.phase("method", start);
        // A long method stops recording its batches once cancelled; what it left is discarded.
        go_on()?;

        // Composite.
        let mut enc = encoder();
        self.record_composite(&mut enc, &inputs, targets, spec);
        submit(enc)?;
        let start = timings.phase("composite", start);

        // Readback of what the output format needs, and of the GPU timestamps.
        let mut enc = encoder();
        let mut readback = Readback::new();
        let pool = &mut self.readbacks;
        let color_index = readback.copy(&gpu, pool, &mut enc, &targets.color.texture);
        let visibility_index = spec.extra_images.visibility.then(|| readback.copy(&gpu, pool, &mut enc, &targets.visibility.texture));
        let e0_index = spec.extra_images.visibility.then(|| readback.copy(&gpu, pool, &mut enc, &targets.e0.texture));
        let depth_index = spec.extra_images.depth.then(|| readback.copy(&gpu, pool, &mut enc, &targets.depth.texture));
        gpu.queue.submit([enc.finish()]);
        let images = readback.finish(&gpu, pool)?;
        let gpu_times = self.timer.read(&gpu)?;
        let color: Vec<[f32; 4]> = bytemuck::cast_slice(&images[color_index]).to_vec();
        // V = E/E0 is undefined where E0 = 0 (a surface facing away from the light, or behind
        // it): every method reports 1 there, so visibility metrics measure shadows only.
        let visibility = visibility_index.zip(e0_index).map(|(v, e)| {
            let v: &[[f32; 4]] = bytemuck::cast_slice(&images[v]);
            let e: &[[f32; 4]] = bytemuck::cast_slice(&images[e]);
            v.iter().zip(e).map(|(v, e)| if e[0] == 0.0 && e[1] == 0.0 && e[2] == 0.0 { [1.0; 3] } else { [v[0], v[1], v[2]] }).collect()
        });
        let depth = depth_index.map(|i| bytemuck::cast_slice::<u8, f32>(&images[i]).to_vec());
        timings.phase("readback", start);
        for (label, ms) in gpu_times {
            timings.add_gpu(label, ms);
        }
        Ok(FrameOutput { width: spec.width, height: spec.height, color, visibility, depth, counters })
    }

    fn write_constants(&self, spec: &FrameSpec, projection: &LightProjection) {
        let camera = &spec.camera;
        let light = &spec.light;
        let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
        let uniforms = FrameUniforms {
            view_proj: camera.view_proj(spec.width as f32 / spec.height as f32).to_cols_array_2d(),
            light_view_proj: projection.view_proj.to_cols_array_2d(),
            eye: v4(camera.eye, 1.0),
            view_dir: v4(camera.forward(), 0.0),
            light_center: v4(light.center, light.intensity),
            light_n: v4(light.n, light.size_m.x),
            light_u: v4(light.u, light.size_m.y),
            light_r: v4(light.r, 0.0),
            light_proj: [projection.tan_half, 0.0, projection.near, projection.far],
            ambient: v4(spec.ambient, 0.0),
            sizes: [spec.width, spec.height, spec.shadow_resolution, spec.cells.len() as u32],
        };
        self.gpu.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        let cells: Vec<LightCellGpu> = spec.cells.iter().map(cell_to_gpu).collect();
        if !cells.is_empty() {
            self.gpu.queue.write_buffer(&self.cells, 0, bytemuck::cast_slice(&cells));
        }
    }

    fn draw_bind_group(&self, scene: &GpuScene) -> wgpu::BindGroup {
        self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Renderer::draw_bind_group"),
            layout: &self.layouts.draw,
            entries: &layout::entries(&[self.uniforms.as_entire_binding(), scene.materials.as_entire_binding()]),
        })
    }

    fn record_shadow_map(&mut self, encoder: &mut wgpu::CommandEncoder, scene: &GpuScene, targets: &FrameTargets) {
        let device = &self.gpu.device;
        let draw_layout = &self.layouts.draw;
        let pipeline = self.pipelines.render(PipelineKey::new("shadow_map"), || {
            let module = shaders::module(device, "shadow_map.wgsl");
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ShadowMap::pipeline_layout"),
                bind_group_layouts: &[Some(draw_layout)],
                immediate_size: 0,
            });
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("ShadowMap::pipeline"),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(vertex_layout())],
                },
                primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                depth_stencil: Some(depth_state()),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(SHADOW_DEPTH_FORMAT.into()), Some(ID_FORMAT.into()), Some(POSITION_FORMAT.into())],
                }),
                multiview_mask: None,
                cache: None,
            })
        });
        let bind_group = self.draw_bind_group(scene);
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("ShadowMap::pass"),
            color_attachments: &[
                Some(clear_attachment(&targets.shadow_depth.view, f64::from(f32::MAX))),
                Some(clear_attachment(&targets.shadow_id.view, f64::from(u32::MAX))),
                Some(clear_attachment(&targets.shadow_position.view, 0.0)),
            ],
            depth_stencil_attachment: Some(depth_attachment(&targets.shadow_depth_buffer.view)),
            timestamp_writes: self.timer.render_scope("shadow_map"),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.set_vertex_buffer(0, scene.vertex_buffer.slice(..));
        pass.set_index_buffer(scene.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..scene.index_count, 0, 0..1);
    }

    fn record_gbuffer(&mut self, encoder: &mut wgpu::CommandEncoder, scene: &GpuScene, targets: &FrameTargets) {
        let device = &self.gpu.device;
        let (draw_layout, material_layout) = (&self.layouts.draw, &self.layouts.material);
        let pipeline = self.pipelines.render(PipelineKey::new("gbuffer"), || {
            let module = shaders::module(device, "gbuffer.wgsl");
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("GBuffer::pipeline_layout"),
                bind_group_layouts: &[Some(draw_layout), Some(material_layout)],
                immediate_size: 0,
            });
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("GBuffer::pipeline"),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(vertex_layout())],
                },
                primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                depth_stencil: Some(depth_state()),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[
                        Some(POSITION_FORMAT.into()),
                        Some(NORMAL_FORMAT.into()),
                        Some(ALBEDO_FORMAT.into()),
                        Some(ID_FORMAT.into()),
                    ],
                }),
                multiview_mask: None,
                cache: None,
            })
        });
        let bind_group = self.draw_bind_group(scene);
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("GBuffer::pass"),
            color_attachments: &[
                Some(clear_attachment(&targets.position.view, 0.0)),
                Some(clear_attachment(&targets.normal.view, 0.0)),
                Some(clear_attachment(&targets.albedo.view, 0.0)),
                Some(clear_attachment(&targets.object_id.view, f64::from(u32::MAX))),
            ],
            depth_stencil_attachment: Some(depth_attachment(&targets.depth_buffer.view)),
            timestamp_writes: self.timer.render_scope("gbuffer"),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.set_vertex_buffer(0, scene.vertex_buffer.slice(..));
        pass.set_index_buffer(scene.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
        for draw in &scene.draws {
            pass.set_bind_group(1, &scene.material_bind_groups[draw.material as usize], &[]);
            pass.draw_indexed(draw.first_index..draw.first_index + draw.index_count, 0, 0..1);
        }
    }

    fn frame_inputs(&self, targets: &FrameTargets) -> FrameInputs {
        let view = wgpu::BindingResource::TextureView;
        let bind_group = self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Renderer::frame_inputs"),
            layout: &self.layouts.inputs,
            entries: &layout::entries(&[
                self.uniforms.as_entire_binding(),
                view(&targets.position.view),
                view(&targets.normal.view),
                view(&targets.albedo.view),
                view(&targets.object_id.view),
                view(&targets.shadow_depth.view),
                view(&targets.shadow_id.view),
                self.cells.as_entire_binding(),
                view(&targets.shadow_position.view),
            ]),
        });
        FrameInputs { layout: self.layouts.inputs.clone(), bind_group }
    }

    fn screen_pipeline(
        &mut self,
        name: &'static str,
        shader: &'static str,
        io_layout: &wgpu::BindGroupLayout,
    ) -> Arc<wgpu::ComputePipeline> {
        let device = &self.gpu.device;
        let inputs_layout = &self.layouts.inputs;
        self.pipelines.compute(PipelineKey::new(name), || screen_compute_pipeline(device, inputs_layout, name, shader, io_layout))
    }

    fn record_e0(&mut self, encoder: &mut wgpu::CommandEncoder, inputs: &FrameInputs, targets: &FrameTargets, spec: &FrameSpec) {
        let io_layout = self.layouts.e0_output.clone();
        let pipeline = self.screen_pipeline("e0", "e0.wgsl", &io_layout);
        let io = self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("E0::outputs"),
            layout: &io_layout,
            entries: &layout::entries(&[wgpu::BindingResource::TextureView(&targets.e0.view)]),
        });
        self.dispatch(encoder, "e0", &pipeline, inputs, &io, spec);
    }

    fn record_composite(&mut self, encoder: &mut wgpu::CommandEncoder, inputs: &FrameInputs, targets: &FrameTargets, spec: &FrameSpec) {
        let io_layout = self.layouts.composite_io.clone();
        let pipeline = self.screen_pipeline("composite", "composite.wgsl", &io_layout);
        let view = wgpu::BindingResource::TextureView;
        let io = self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Composite::io"),
            layout: &io_layout,
            entries: &layout::entries(&[
                view(&targets.e0.view),
                view(&targets.visibility.view),
                view(&targets.color.view),
                view(&targets.depth.view),
            ]),
        });
        self.dispatch(encoder, "composite", &pipeline, inputs, &io, spec);
    }

    fn dispatch(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        label: &'static str,
        pipeline: &wgpu::ComputePipeline,
        inputs: &FrameInputs,
        io: &wgpu::BindGroup,
        spec: &FrameSpec,
    ) {
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: self.timer.compute_scope(label) });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &inputs.bind_group, &[]);
        pass.set_bind_group(1, io, &[]);
        pass.dispatch_workgroups(spec.width.div_ceil(8), spec.height.div_ceil(8), 1);
    }
}

/// A compute pipeline over the screen (8×8 workgroups, entry `main`): group 0 is the frame
/// inputs (`shaders/common/frame_inputs.wgsl`), group 1 the pass's own bindings.
pub fn screen_compute_pipeline(
    device: &wgpu::Device,
    inputs_layout: &wgpu::BindGroupLayout,
    label: &'static str,
    shader: &str,
    io_layout: &wgpu::BindGroupLayout,
) -> wgpu::ComputePipeline {
    let module = shaders::module(device, shader);
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(inputs_layout), Some(io_layout)],
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

fn cell_to_gpu(cell: &LightCell) -> LightCellGpu {
    LightCellGpu { corners: cell.corners.map(|c| [c.x, c.y, c.z, 1.0]), radiance: [cell.radiance.x, cell.radiance.y, cell.radiance.z, 0.0] }
}

fn vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    const ATTRIBUTES: [wgpu::VertexAttribute; 5] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Uint32, 4 => Uint32];
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &ATTRIBUTES,
    }
}

fn depth_state() -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: DEPTH_BUFFER_FORMAT,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::Less),
        stencil: Default::default(),
        bias: Default::default(),
    }
}

fn clear_attachment(view: &wgpu::TextureView, value: f64) -> wgpu::RenderPassColorAttachment<'_> {
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

fn depth_attachment(view: &wgpu::TextureView) -> wgpu::RenderPassDepthStencilAttachment<'_> {
    wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
        stencil_ops: None,
    }
}
