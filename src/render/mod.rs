//! One frame, pass by pass: light-space shadow map → eye-space G-buffer → unshadowed
//! irradiance E0 → the method's visibility → composite → readback. The `Renderer` owns the
//! long-lived state (pipelines, target pool, timer, bind group layouts) and is reused by every
//! job; each phase is submitted and waited for on its own so its wall time is honest even on
//! adapters without timestamp queries.

pub mod convex;
mod draw;
pub mod frame;
mod inputs;
pub mod method;
mod passes;
mod pixel_list;
mod targets;

use std::sync::Arc;
use std::time::Instant;

use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::{BufferPool, DerivedResources, PipelinePool, ReadbackPool, TexturePool};
use crate::gpu::readback::Readback;
use crate::gpu::scene::GpuScene;
use crate::gpu::timing::{GpuTimer, PassTime};
use crate::gpu::GpuContext;
use crate::light::E0_GRID;
use crate::render::method::{CounterKey, Counters, MethodContext, Scratch};
use crate::supervise::{cancelled_error, Supervisor};
use crate::timing::PhaseName;
use crate::timing::Timings;
pub use draw::{vertex_layout, ScenePipeline, DEPTH_BUFFER_FORMAT};
pub use frame::{resolve_view, Camera, ExtraImages, FrameSpec, LightProjection, Staging};
pub use inputs::FrameInputs;
use inputs::{FrameUniforms, LightCellGpu};
pub use passes::{screen_compute_pipeline, E0Mode};
pub use pixel_list::{list_grid, PixelListBuffers};
use targets::FrameTargets;

/// The frame's counter of the pixels E0 summed exactly because its interpolation refused
/// them (present where the interpolation ran: lights of more than `E0_EXACT_CELLS` cells).
pub const E0_SUMMED_EXACTLY: CounterKey = CounterKey("e0_pixels_summed_exactly");

/// What a frame produces on the CPU. Pixels are row-major from the top-left.
pub struct FrameOutput {
    pub width: u32,
    pub height: u32,
    /// Linear radiance and coverage alpha, RGBA; empty when only `srgb8` was read back.
    pub color: Vec<[f32; 4]>,
    /// The PNG's pixels, 8-bit sRGB RGBA after exposure, made on the GPU when the linear
    /// colour was not asked for (`ExtraImages::float_color`).
    pub srgb8: Option<Vec<u8>>,
    /// Per-channel visibility V (EXR and comparisons), 1 wherever E0 = 0.
    pub visibility: Option<Vec<[f32; 3]>>,
    /// The method's estimate of its error per pixel, with the visibility, where it makes one
    /// (a method that sets `method::ERROR_ESTIMATE`); 0 wherever E0 = 0.
    pub error_estimate: Option<Vec<f32>>,
    /// View depth in metres, +∞ for background (EXR only).
    pub depth: Option<Vec<f32>>,
    /// The unshadowed irradiance E0, whenever the visibility is read back.
    pub e0: Option<Vec<[f32; 3]>>,
    /// The method's counters, and `E0_SUMMED_EXACTLY` where E0 was interpolated.
    pub counters: Counters,
    /// The scene's warnings (`Scene::warnings`) and the method's, for the job's answer.
    pub warnings: Vec<String>,
    /// The camera, light and floor it was rendered with, for the job's answer.
    pub staging: Staging,
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

pub struct Renderer {
    gpu: Arc<GpuContext>,
    pub pipelines: PipelinePool,
    pub textures: TexturePool,
    /// The screen-space images (`targets`), recycled like the textures.
    pub buffers: BufferPool,
    pub derived: DerivedResources,
    pub readbacks: ReadbackPool,
    timer: GpuTimer,
    layouts: Layouts,
    uniforms: wgpu::Buffer,
    cells: wgpu::Buffer,
    /// How E0 is evaluated (interpolated unless a measurement asks for the exact sum).
    pub e0_mode: E0Mode,
    /// `Limits::max_cpu_working_bytes`, for the methods that work on the CPU.
    pub cpu_working_bytes: u64,
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
                    layout::uniform(7),
                    layout::texture_float(8),
                ],
            ),
            e0_output: bgl(
                "Renderer::e0_output_layout",
                &[
                    layout::storage_read_write(0),
                    layout::storage_read_write(1),
                    layout::storage_read_write(2),
                    layout::storage_read_write(3),
                    layout::storage_read_write(4),
                    layout::storage_read_write(5),
                ],
            ),
            composite_io: bgl(
                "Renderer::composite_io_layout",
                &[
                    layout::storage_read(0),
                    layout::storage_read(1),
                    layout::storage_read_write(2),
                    layout::storage_read_write(3),
                    layout::storage_read_write(4),
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
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let timer = GpuTimer::new(&gpu);
        Self {
            gpu,
            pipelines: PipelinePool::default(),
            textures: TexturePool::default(),
            buffers: BufferPool::default(),
            derived: DerivedResources::default(),
            readbacks: ReadbackPool::default(),
            timer,
            layouts,
            uniforms,
            cells,
            e0_mode: E0Mode::default(),
            cpu_working_bytes: crate::job::Limits::default().max_cpu_working_bytes,
        }
    }

    pub fn gpu(&self) -> &Arc<GpuContext> {
        &self.gpu
    }

    /// Keeps at most `bytes` of idle targets, of idle buffers and of idle readback buffers
    /// (each) for later frames; the longest idle go first.
    pub fn set_pool_budget(&mut self, bytes: u64) {
        self.textures.set_budget(bytes);
        self.buffers.set_budget(bytes);
        self.readbacks.set_budget(bytes);
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
        let targets =
            FrameTargets::alloc(&mut self.textures, &mut self.buffers, &self.gpu.device, spec.width, spec.height, spec.shadow_resolution);
        let frame = self.render_into(&targets, scene, spec, timings, supervisor);
        // A cancelled frame gives its targets back too: the next job reuses them.
        targets.release(&mut self.textures, &mut self.buffers);
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
        let projection = LightProjection::fit(&spec.light, &scene.shadow_fit_points(&spec.light));
        self.write_constants(spec, &projection);
        let encoder = || frame_encoder(device);
        let submit = |encoder: wgpu::CommandEncoder| gpu.submit_and_wait(encoder);

        // Shadow map from the light centre, where the method reads it (its phase is timed
        // either way, so that every frame's breakdown has the same phases).
        let start = Instant::now();
        if spec.method.reads_shadow_map() {
            let mut enc = encoder();
            self.record_shadow_map(&mut enc, scene, targets, spec.method.reads_light_surfaces());
            submit(enc)?;
        }
        let start = timings.phase(PhaseName::ShadowMap, start);
        go_on()?;

        // Eye-space G-buffer.
        let mut enc = encoder();
        self.record_gbuffer(&mut enc, scene, targets, spec.method.reads_object_ids());
        submit(enc)?;
        let start = timings.phase(PhaseName::Gbuffer, start);
        go_on()?;

        let inputs = self.frame_inputs(targets);

        // Unshadowed irradiance E0.
        let mut enc = encoder();
        let mut scratch = Scratch::default();
        let e0_listed = self.record_e0(&mut enc, &inputs, targets, spec, &mut scratch);
        submit(enc)?;
        scratch.release(&mut self.buffers, &mut self.textures);
        let start = timings.phase(PhaseName::E0, start);
        go_on()?;

        // The method's visibility.
        let (counters, method_warnings) = self.record_method(targets, scene, spec, &inputs, &projection, supervisor)?;
        let start = timings.phase(PhaseName::Method, start);
        // A long method stops recording its batches once cancelled; what it left is discarded.
        go_on()?;

        // Composite: the linear colour, or straight to the PNG's 8-bit pixels.
        let srgb8_buffer = (!spec.extra_images.float_color).then(|| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Renderer::srgb8"),
                size: u64::from(spec.width) * u64::from(spec.height) * 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        });
        let mut enc = encoder();
        self.record_composite(&mut enc, &inputs, targets, spec, srgb8_buffer.as_ref());
        submit(enc)?;
        let start = timings.phase(PhaseName::Composite, start);

        // Readback of what the output format needs, and of the GPU timestamps.
        let warnings = scene.warnings.iter().cloned().chain(method_warnings).collect();
        let (frame, gpu_times) = self.read_back(targets, spec, srgb8_buffer.as_ref(), e0_listed, (counters, warnings))?;
        timings.phase(PhaseName::Readback, start);
        for time in gpu_times {
            timings.add_gpu(time.phase, time.pass, time.ms);
        }
        Ok(frame)
    }

    /// Records the method's passes (`MethodContext`), runs them, and gives the pools back
    /// the method's scratch buffers, which are free once its passes have run. Answers the
    /// method's counters and warnings.
    fn record_method(
        &mut self,
        targets: &FrameTargets,
        scene: &GpuScene,
        spec: &FrameSpec,
        inputs: &FrameInputs,
        projection: &LightProjection,
        supervisor: &dyn Supervisor,
    ) -> JobResult<(Counters, Vec<String>)> {
        let gpu = self.gpu.clone();
        let mut enc = frame_encoder(&gpu.device);
        let (counters, scratch) = {
            let mut ctx = MethodContext {
                gpu: &gpu,
                pipelines: &mut self.pipelines,
                derived: &mut self.derived,
                buffers: &mut self.buffers,
                textures: &mut self.textures,
                scratch: Scratch::default(),
                inputs,
                shadow_depth: &targets.shadow_depth.texture,
                gbuffer_position: &targets.position.texture,
                gbuffer_normal: &targets.normal.texture,
                visibility: &targets.visibility.buffer,
                e0: &targets.e0.buffer,
                width: spec.width,
                height: spec.height,
                encoder: &mut enc,
                timer: &mut self.timer,
                scene,
                spec,
                projection,
                supervisor,
                warnings: Vec::new(),
                cpu_working_bytes: self.cpu_working_bytes,
            };
            let counters = spec.method.record(&mut ctx, &spec.params);
            (counters.map(|counters| (counters, std::mem::take(&mut ctx.warnings))), std::mem::take(&mut ctx.scratch))
        };
        let counters = counters?;
        gpu.submit_and_wait(enc)?;
        scratch.release(&mut self.buffers, &mut self.textures);
        Ok(counters)
    }

    /// Copies back what the output format needs — the colour (linear, or the PNG's sRGB8
    /// pixels from `srgb8_buffer`), visibility, E0 and depth as asked, and the count of pixels
    /// E0 summed exactly (`e0_listed`, into `counters`) — and reads the passes' GPU times.
    fn read_back(
        &mut self,
        targets: &FrameTargets,
        spec: &FrameSpec,
        srgb8_buffer: Option<&wgpu::Buffer>,
        e0_listed: Option<wgpu::Buffer>,
        (mut counters, warnings): (Counters, Vec<String>),
    ) -> JobResult<(FrameOutput, Vec<PassTime>)> {
        let gpu = self.gpu.clone();
        let mut enc = frame_encoder(&gpu.device);
        let mut readback = Readback::new();
        let pool = &mut self.readbacks;
        let float_color = spec.extra_images.float_color;
        let color_index = if float_color {
            readback.copy_buffer(&gpu, pool, &mut enc, &targets.color.buffer)
        } else {
            readback.copy_buffer(&gpu, pool, &mut enc, srgb8_buffer.expect("made when the float colour is not read back"))
        };
        let visibility_index = spec.extra_images.visibility.then(|| readback.copy_buffer(&gpu, pool, &mut enc, &targets.visibility.buffer));
        let e0_index = spec.extra_images.visibility.then(|| readback.copy_buffer(&gpu, pool, &mut enc, &targets.e0.buffer));
        let depth_index = spec.extra_images.depth.then(|| readback.copy_buffer(&gpu, pool, &mut enc, &targets.depth.buffer));
        let listed_index = e0_listed.map(|listed| readback.copy_buffer(&gpu, pool, &mut enc, &listed));
        gpu.queue.submit([enc.finish()]);
        let mut images = readback.finish(&gpu, pool)?;
        let gpu_times = self.timer.read(&gpu)?;
        let (color, srgb8) = if float_color {
            (bytemuck::cast_slice(&images[color_index]).to_vec(), None)
        } else {
            // The srgb8 buffer holds exactly the frame's RGBA8 pixels: taken, not copied.
            (Vec::new(), Some(std::mem::take(&mut images[color_index])))
        };
        // V = E/E0 is undefined where E0 = 0 (a surface facing away from the light, or behind
        // it): every method reports 1 there, so visibility metrics measure shadows only.
        let e0: Option<Vec<[f32; 3]>> =
            e0_index.map(|e| bytemuck::cast_slice::<u8, [f32; 4]>(&images[e]).iter().map(|e| [e[0], e[1], e[2]]).collect());
        let visibility = visibility_index.zip(e0.as_ref()).map(|(v, e)| {
            let v: &[[f32; 4]] = bytemuck::cast_slice(&images[v]);
            v.iter().zip(e).map(|(v, e)| if *e == [0.0; 3] { [1.0; 3] } else { [v[0], v[1], v[2]] }).collect()
        });
        let error_estimate = visibility_index.zip(e0.as_ref()).filter(|_| method::ERROR_ESTIMATE.get(&counters).is_some()).map(|(v, e)| {
            let v: &[[f32; 4]] = bytemuck::cast_slice(&images[v]);
            v.iter().zip(e).map(|(v, e)| if *e == [0.0; 3] { 0.0 } else { v[3] }).collect()
        });
        let depth = depth_index.map(|i| bytemuck::cast_slice::<u8, f32>(&images[i]).to_vec());
        if let Some(i) = listed_index {
            let listed: u32 = bytemuck::cast_slice::<u8, u32>(&images[i][..8]).iter().sum();
            E0_SUMMED_EXACTLY.set(&mut counters, f64::from(listed));
        }
        let staging = spec.staging.clone();
        let frame = FrameOutput {
            width: spec.width,
            height: spec.height,
            color,
            srgb8,
            visibility,
            error_estimate,
            depth,
            e0,
            counters,
            warnings,
            staging,
        };
        Ok((frame, gpu_times))
    }
}

/// A command encoder for one phase of the frame.
fn frame_encoder(device: &wgpu::Device) -> wgpu::CommandEncoder {
    device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Renderer::encoder") })
}
