//! The interface between the frame and the shadow methods (contract §2): a method is a
//! `ShadowMethod` that records passes into the frame's command encoder through a
//! `MethodContext` — the frame's inputs, the visibility target it fills, pools, the timer —
//! and reports its counters. The renderer knows methods only through this trait; the methods'
//! registry lives above it, with the methods.

use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::Arc;

use crate::error::JobResult;
use crate::gpu::pool::{
    BufferKey, BufferPool, DerivedResources, PipelineKey, PipelinePool, PooledBuffer, PooledTexture, TextureKey, TexturePool,
};
use crate::gpu::scene::GpuScene;
use crate::gpu::timing::GpuTimer;
use crate::gpu::GpuContext;
use crate::params::{ParamSpec, Params};
use crate::render::{FrameInputs, FrameSpec, LightProjection};
use crate::supervise::Supervisor;
use crate::timing::PhaseName;

/// A method's pooled buffers and textures for one frame (`MethodContext::scratch_buffer`).
#[derive(Default)]
pub struct Scratch {
    buffers: Vec<PooledBuffer>,
    textures: Vec<PooledTexture>,
}

impl Scratch {
    /// A buffer of `key` from `pool`, held for the frame: it goes back to the pool with the
    /// rest. It holds whatever an earlier frame left in it.
    pub fn buffer(&mut self, pool: &mut BufferPool, device: &wgpu::Device, key: BufferKey) -> wgpu::Buffer {
        let pooled = pool.alloc(device, key);
        let buffer = pooled.buffer.clone();
        self.buffers.push(pooled);
        buffer
    }

    /// Gives the last `count` buffers handed out back to `pool` now: only once nothing recorded
    /// uses them any more (read back and unmapped), so that a frame worked on in bands holds
    /// one band's copies at a time.
    fn release_last_buffers(&mut self, count: usize, pool: &mut BufferPool) {
        for buffer in self.buffers.drain(self.buffers.len().saturating_sub(count)..) {
            pool.release(buffer);
        }
    }

    /// Gives everything back to the pools; only once the passes using it have run.
    pub fn release(self, buffers: &mut BufferPool, textures: &mut TexturePool) {
        for buffer in self.buffers {
            buffers.release(buffer);
        }
        for texture in self.textures {
            textures.release(texture);
        }
    }
}

/// Method-specific counters (JFA rounds, searches skipped …), reported with the timings.
pub type Counters = BTreeMap<String, f64>;

/// The key of a counter another module reads (a table, a test, the bench): declared once
/// beside the code that writes it, so that writer and reader cannot drift apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CounterKey(pub &'static str);

impl CounterKey {
    pub const fn name(self) -> &'static str {
        self.0
    }

    /// The counter's value in `counters`, if it was written.
    pub fn get(self, counters: &Counters) -> Option<f64> {
        counters.get(self.0).copied()
    }

    pub fn set(self, counters: &mut Counters, value: f64) {
        counters.insert(self.0.to_owned(), value);
    }
}

/// The mean estimated error |V − Vref| over the pixels a method finds in penumbra. A method
/// that writes it has written its estimate per pixel in the visibility target's fourth
/// component (the others leave 1 there); outputs that carry the visibility then carry it too
/// (EXR layer `error`).
pub const ERROR_ESTIMATE: CounterKey = CounterKey("error_estimate_penumbra");

/// Records the copy of `rows` of `texture` into `buffer`, rows `pitch` bytes apart from its
/// start (`MethodContext::rows_buffer`).
fn copy_rows(encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture, buffer: &wgpu::Buffer, pitch: u32, rows: &Range<u32>) {
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo { origin: wgpu::Origin3d { x: 0, y: rows.start, z: 0 }, ..texture.as_image_copy() },
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(pitch), rows_per_image: None },
        },
        wgpu::Extent3d { width: texture.width(), height: rows.len() as u32, depth_or_array_layers: 1 },
    );
}

/// A few rows of the G-buffer on the CPU (`MethodContext::read_surfaces`), as copied into
/// buffers: rows `*_pitch` bytes apart from the top-left, read in place.
struct GBufferView<'a> {
    positions: &'a [u8],
    normals: &'a [u8],
    position_pitch: usize,
    normal_pitch: usize,
}

impl GBufferView<'_> {
    /// Pixel (x, y)'s world position (`Rgba32Float`).
    fn position(&self, x: u32, y: u32) -> glam::Vec3 {
        let at = y as usize * self.position_pitch + x as usize * 16;
        let word = |i: usize| f32::from_le_bytes(self.positions[at + 4 * i..at + 4 * i + 4].try_into().expect("four bytes"));
        glam::Vec3::new(word(0), word(1), word(2))
    }

    /// Pixel (x, y)'s unit normal facing the eye (`Rgba16Float`), `None` where no surface
    /// covers the pixel (w ≤ 0.5).
    fn normal(&self, x: u32, y: u32) -> Option<glam::Vec3> {
        let at = y as usize * self.normal_pitch + x as usize * 8;
        let half = |i: usize| half::f16::from_le_bytes([self.normals[at + 2 * i], self.normals[at + 2 * i + 1]]).to_f32();
        (half(3) > 0.5).then(|| glam::Vec3::new(half(0), half(1), half(2)))
    }
}

/// The surface each pixel of some rows of the frame shows, decoded from the G-buffer into the
/// CPU's memory (`MethodContext::read_surfaces`), for the methods that work on the CPU: world
/// position and unit normal facing the eye, the normal zero where no surface covers the pixel.
pub struct Surfaces {
    pub width: u32,
    pub height: u32,
    /// Row after row, from the rows' first.
    pub positions: Vec<glam::Vec3>,
    pub normals: Vec<glam::Vec3>,
}

impl Surfaces {
    /// Surfaces made by hand: `at(x, y)` gives a pixel's position and normal (zero: none).
    #[cfg(test)]
    pub fn from_fn(width: u32, height: u32, at: impl Fn(u32, u32) -> (glam::Vec3, glam::Vec3)) -> Self {
        let (positions, normals) = (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| at(x, y)).unzip();
        Self { width, height, positions, normals }
    }

    /// Pixel (x, y)'s world position.
    pub fn position(&self, x: u32, y: u32) -> glam::Vec3 {
        self.positions[(y * self.width + x) as usize]
    }

    /// Pixel (x, y)'s unit normal facing the eye, `None` where no surface covers the pixel.
    pub fn normal(&self, x: u32, y: u32) -> Option<glam::Vec3> {
        let normal = self.normals[(y * self.width + x) as usize];
        (normal != glam::Vec3::ZERO).then_some(normal)
    }
}

/// Rows of the G-buffer `MethodContext::read_surfaces` reads back at a time: 24 bytes a pixel
/// in pooled buffers of this many rows (6 MB at 1920 wide), not of the frame's — a buffer that
/// the pool keeps would add its bytes to the CPU methods' working memory for the whole frame.
const SURFACE_ROWS: u32 = 128;

/// What a method gets to record its passes.
pub struct MethodContext<'a> {
    pub gpu: &'a GpuContext,
    pub pipelines: &'a mut PipelinePool,
    /// Resources derived from the job's inputs and kept for later jobs (look-up tables).
    pub derived: &'a mut DerivedResources,
    /// The renderer's pools, which `scratch_buffer` and `scratch_texture` draw from.
    pub buffers: &'a mut BufferPool,
    pub textures: &'a mut TexturePool,
    /// What they handed out this frame; the renderer gives it back to the pools once the
    /// method's passes have run.
    pub scratch: Scratch,
    /// Group 0 of every screen-space pass: frame constants, G-buffer, shadow map.
    pub inputs: &'a FrameInputs,
    /// The shadow map's linear depth (`R32Float`, bound in `inputs` too), for methods that
    /// copy it into a buffer.
    pub shadow_depth: &'a wgpu::Texture,
    /// The G-buffer's world positions (`Rgba32Float`) and normals (`Rgba16Float`, w > 0.5
    /// where a surface covers the pixel), bound in `inputs` too, for `read_gbuffer`.
    pub gbuffer_position: &'a wgpu::Texture,
    pub gbuffer_normal: &'a wgpu::Texture,
    /// Where the method writes its visibility: `array<vec4<f32>>`, one per pixel row-major,
    /// rgb = V per channel (`render::targets` says why a buffer).
    pub visibility: &'a wgpu::Buffer,
    /// The unshadowed irradiance E0 per channel (laid out as `visibility`), already computed:
    /// a method that works out blocked irradiance rather than a fraction divides by it.
    pub e0: &'a wgpu::Buffer,
    pub width: u32,
    pub height: u32,
    pub encoder: &'a mut wgpu::CommandEncoder,
    pub timer: &'a mut GpuTimer,
    /// The scene, for methods that draw it again (from light samples, as wedges …).
    pub scene: &'a GpuScene,
    /// The whole frame: light, light image, camera, sizes.
    pub spec: &'a FrameSpec,
    /// The shadow map's projection from the light centre, as the frame rendered it.
    pub projection: &'a LightProjection,
    /// Hears the progress of long methods (steps done, steps in all); a long method asks it
    /// between batches whether to stop (`Supervisor::cancelled`).
    pub supervisor: &'a dyn Supervisor,
    /// What the method found in this scene that it cannot render faithfully, for the job's
    /// `warnings` (contract §2: detect it and say so, never fail silently).
    pub warnings: Vec<String>,
    /// The most bytes a method working on the CPU may hold for its per-pixel work at once
    /// (`--max-cpu-working-bytes`): a frame that needs more is worked on in bands of rows.
    pub cpu_working_bytes: u64,
}

impl MethodContext<'_> {
    /// Submits what has been recorded so far and waits for it, leaving a fresh encoder:
    /// for methods that run many passes and report progress between them.
    pub fn flush(&mut self) -> JobResult<()> {
        let fresh = self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("MethodContext::encoder") });
        let done = std::mem::replace(self.encoder, fresh);
        Ok(self.gpu.submit_and_wait(done)?)
    }

    /// A screen-space compute pipeline from the pool, labelled `label`: group 0 the frame
    /// inputs, group 1 the bindings listed in `io` (bind groups for it come from
    /// `get_bind_group_layout(1)`).
    pub fn screen_pipeline(
        &mut self,
        label: &'static str,
        shader: &'static str,
        io: &[wgpu::BindGroupLayoutEntry],
    ) -> Arc<wgpu::ComputePipeline> {
        self.screen_entry(label, shader, "main", io)
    }

    /// `screen_pipeline` with another entry point than `main`.
    pub fn screen_entry(
        &mut self,
        label: &'static str,
        shader: &'static str,
        entry: &'static str,
        io: &[wgpu::BindGroupLayoutEntry],
    ) -> Arc<wgpu::ComputePipeline> {
        self.screen_specialized(label, (shader, entry), io, &[])
    }

    /// `screen_entry` with values for the shader's pipeline-overridable constants: a pipeline
    /// per set of values (the key holds them).
    pub fn screen_specialized(
        &mut self,
        label: &'static str,
        (shader, entry): (&'static str, &'static str),
        io: &[wgpu::BindGroupLayoutEntry],
        constants: &[(&'static str, f64)],
    ) -> Arc<wgpu::ComputePipeline> {
        let device = &self.gpu.device;
        let inputs_layout = &self.inputs.layout;
        self.pipelines.compute(PipelineKey::compute(label, (shader, entry), constants), || {
            let io_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: io });
            crate::render::screen_compute_pipeline(device, inputs_layout, label, (shader, entry), &io_layout, constants)
        })
    }

    /// A storage buffer for this frame only, from the renderer's pool: a steady stream of jobs
    /// reuses the same memory instead of allocating it anew — on lavapipe every page of a new
    /// buffer is a page fault the first time a pass touches it, a large share of a frame for
    /// `jfa-l`'s records at 2048². It holds whatever an earlier frame left: a method clears,
    /// or writes in full, what must start empty.
    pub fn scratch_buffer(&mut self, label: &'static str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.scratch.buffer(self.buffers, &self.gpu.device, BufferKey { label, size, usage })
    }

    /// A pixel list of at most `capacity` pixels from the pools, for this frame only
    /// (`PixelListBuffers`); labelled `owner`.
    pub fn pixel_list(&mut self, owner: &'static str, capacity: u64) -> crate::render::PixelListBuffers {
        self.pixel_list_of(owner, capacity, 4)
    }

    /// `pixel_list` of `entry_bytes`-sized entries.
    pub fn pixel_list_of(&mut self, owner: &'static str, capacity: u64, entry_bytes: u64) -> crate::render::PixelListBuffers {
        crate::render::PixelListBuffers::new(
            self.buffers,
            &mut self.scratch,
            &self.gpu.device,
            self.encoder,
            (owner, capacity, entry_bytes),
        )
    }

    /// `scratch_buffer` for a texture (`key.layers` layers), with what an earlier frame left in it.
    pub fn scratch_texture(&mut self, key: TextureKey) -> wgpu::Texture {
        let pooled = self.textures.alloc(&self.gpu.device, key);
        let texture = pooled.texture.clone();
        self.scratch.textures.push(pooled);
        texture
    }

    /// The shadow map's depths copied into a pooled storage buffer, row after row, and the
    /// texels from one row to the next (rows padded to the copy alignment); the copy is timed
    /// as pass `pass` of the method. On lavapipe a storage-buffer load is a plain gather where
    /// a texel fetch is not, and the copy is a memcpy (cheaper than a compute pass reading
    /// every texel).
    pub fn shadow_depth_copy(&mut self, label: &'static str, pass: &'static str) -> (wgpu::Buffer, u32) {
        let texture = self.shadow_depth;
        let rows = 0..texture.height();
        let (buffer, pitch) = self.rows_buffer(label, texture, 4, rows.len() as u32, wgpu::BufferUsages::STORAGE);
        self.timer.time_encoder(self.encoder, PhaseName::Method, pass, |encoder| copy_rows(encoder, texture, &buffer, pitch, &rows));
        (buffer, pitch / 4)
    }

    /// A pooled buffer (`usage`, and the copy's destination) for `texture`'s rows of
    /// `bytes_per_texel`-byte texels, padded to the copy alignment, and that pitch in bytes.
    /// The copy writes all of it.
    fn rows_buffer(
        &mut self,
        label: &'static str,
        texture: &wgpu::Texture,
        bytes_per_texel: u32,
        rows: u32,
        usage: wgpu::BufferUsages,
    ) -> (wgpu::Buffer, u32) {
        let pitch = (bytes_per_texel * texture.width()).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = self.scratch_buffer(label, u64::from(pitch) * u64::from(rows), usage | wgpu::BufferUsages::COPY_DST);
        (buffer, pitch)
    }

    /// The G-buffer's surfaces on the frame's `rows` (a band of a frame worked on in bands, or
    /// all of them), decoded on the CPU's cores once what was recorded so far has run: for work
    /// done on the CPU. Read back `SURFACE_ROWS` rows at a time through pooled buffers (on
    /// lavapipe a fresh one costs a page fault a page the first time it is written).
    pub fn read_surfaces(&mut self, rows: Range<u32>) -> JobResult<Surfaces> {
        use rayon::prelude::*;
        let (width, height) = (self.width, rows.len() as u32);
        let pixels = width as usize * height as usize;
        let (mut positions, mut normals) = (vec![glam::Vec3::ZERO; pixels], vec![glam::Vec3::ZERO; pixels]);
        let chunk_pixels = SURFACE_ROWS as usize * width as usize;
        let chunks = positions.chunks_mut(chunk_pixels).zip(normals.chunks_mut(chunk_pixels));
        for ((positions, normals), first) in chunks.zip(rows.clone().step_by(SURFACE_ROWS as usize)) {
            let chunk = first..(first + SURFACE_ROWS).min(rows.end);
            self.read_gbuffer_rows(chunk, |gbuffer| {
                let rows = positions.par_chunks_mut(width as usize).zip(normals.par_chunks_mut(width as usize));
                rows.enumerate().for_each(|(y, (positions, normals))| {
                    for (x, (position, normal)) in positions.iter_mut().zip(normals).enumerate() {
                        *position = gbuffer.position(x as u32, y as u32);
                        *normal = gbuffer.normal(x as u32, y as u32).unwrap_or(glam::Vec3::ZERO);
                    }
                });
            })?;
        }
        Ok(Surfaces { width, height, positions, normals })
    }

    /// Hands `read` the G-buffer's `rows` on the CPU, read where they lie: the view's row 0 is
    /// the frame's row `rows.start`.
    fn read_gbuffer_rows<R>(&mut self, rows: Range<u32>, read: impl FnOnce(&GBufferView<'_>) -> R) -> JobResult<R> {
        let (position_texture, normal_texture) = (self.gbuffer_position, self.gbuffer_normal);
        let count = rows.len() as u32;
        let (positions, position_pitch) =
            self.rows_buffer("MethodContext::gbuffer_positions", position_texture, 16, count, wgpu::BufferUsages::MAP_READ);
        let (normals, normal_pitch) =
            self.rows_buffer("MethodContext::gbuffer_normals", normal_texture, 8, count, wgpu::BufferUsages::MAP_READ);
        copy_rows(self.encoder, position_texture, &positions, position_pitch, &rows);
        copy_rows(self.encoder, normal_texture, &normals, normal_pitch, &rows);
        self.flush()?;
        self.gpu.map_for_reading(&[positions.slice(..), normals.slice(..)])?;
        let map_error = |e: wgpu::MapRangeError| crate::gpu::GpuError::Map(e.to_string());
        let result = {
            let (position_bytes, normal_bytes) =
                (positions.slice(..).get_mapped_range().map_err(map_error)?, normals.slice(..).get_mapped_range().map_err(map_error)?);
            read(&GBufferView {
                positions: &position_bytes,
                normals: &normal_bytes,
                position_pitch: position_pitch as usize,
                normal_pitch: normal_pitch as usize,
            })
        };
        positions.unmap();
        normals.unmap();
        // Both were read and let go: the next rows may have them.
        self.scratch.release_last_buffers(2, self.buffers);
        Ok(result)
    }

    /// A uniform buffer holding `value` (laid out as its WGSL struct).
    pub fn uniforms<T: bytemuck::Pod>(&self, label: &'static str, value: &T) -> wgpu::Buffer {
        use wgpu::util::DeviceExt as _;
        self.gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::bytes_of(value),
            usage: wgpu::BufferUsages::UNIFORM,
        })
    }

    /// `words` zeroed u32 counters the shaders add to atomically, to be read back with
    /// `read_counters`.
    pub fn counters(&self, label: &'static str, words: usize) -> wgpu::Buffer {
        use wgpu::util::DeviceExt as _;
        self.gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &vec![0u8; words * 4],
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        })
    }

    /// Runs what has been recorded and reads `counters` back.
    pub fn read_counters(&mut self, counters: &wgpu::Buffer) -> JobResult<Vec<u32>> {
        self.flush()?;
        Ok(bytemuck::cast_slice(&crate::gpu::readback::read_buffer(self.gpu, counters)?).to_vec())
    }

    /// Group 1 of a screen pipeline: `resources` at bindings 0, 1, 2, … in order.
    pub fn bind(&self, label: &'static str, pipeline: &wgpu::ComputePipeline, resources: &[wgpu::BindingResource<'_>]) -> wgpu::BindGroup {
        self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &pipeline.get_bind_group_layout(1),
            entries: &crate::gpu::layout::entries(resources),
        })
    }

    /// One compute pass over the output (8×8 workgroups), timed as the method phase: the
    /// frame inputs in group 0, `group` in group 1.
    pub fn dispatch_screen(&mut self, label: &'static str, pipeline: &wgpu::ComputePipeline, group: &wgpu::BindGroup) {
        let (gx, gy) = self.dispatch_size();
        let mut pass = self.timer.begin_compute_pass(self.encoder, PhaseName::Method, label);
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.inputs.bind_group, &[]);
        pass.set_bind_group(1, group, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
    }

    /// A table derived from the light's image and size (`light::tables`) as a read-only
    /// storage buffer, built on the CPU the first time a light is seen and kept for later jobs
    /// under `name` (storage rather than a texture: lavapipe charges a texel fetch several
    /// times a buffer read).
    pub fn light_table(
        &mut self,
        name: &'static str,
        build: impl FnOnce(&crate::light::AreaLight, &crate::light::LightImage) -> Vec<[f32; 4]>,
    ) -> Arc<wgpu::Buffer> {
        use std::hash::{Hash, Hasher};
        use wgpu::util::DeviceExt as _;
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        self.spec.light_image.fingerprint().hash(&mut hasher);
        self.spec.light.size_m.to_array().map(f32::to_bits).hash(&mut hasher);
        let key = crate::gpu::pool::DerivedKey { name, fingerprint: hasher.finish() };
        let (gpu, spec) = (self.gpu, self.spec);
        self.derived.get_or_create(key, || {
            let table = build(&spec.light, &spec.light_image);
            gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(name),
                contents: bytemuck::cast_slice(&table),
                usage: wgpu::BufferUsages::STORAGE,
            })
        })
    }

    /// Workgroup counts covering the output with 8×8 workgroups.
    pub fn dispatch_size(&self) -> (u32, u32) {
        (self.width.div_ceil(8), self.height.div_ceil(8))
    }
}

pub trait ShadowMethod: Send + Sync {
    /// The job name (`method.name`).
    fn name(&self) -> &'static str;
    /// One line for `GET /v1/methods`: what it is and where it comes from.
    fn summary(&self) -> &'static str;
    /// Parameters with their defaults and ranges.
    fn params(&self) -> &'static [ParamSpec];
    /// Records the passes that fill `ctx.visibility`.
    /// Fails the job on a GPU error (a failed map or poll), never panics.
    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters>;
    /// Whether the method reads the shadow map from the light's centre at all (`shadow_depth`,
    /// `MethodContext::shadow_depth`). One that does not — `wedges` works on the triangles,
    /// `reference` draws a map per sample — says so, and the frame skips the pass (its phase
    /// then takes no time).
    fn reads_shadow_map(&self) -> bool {
        true
    }
    /// Whether the method reads what the shadow map sees besides its depth — object ids
    /// (`shadow_id`; world positions come from the depth, `shadow_point`). A method that does
    /// says so; for the others the shadow-map pass writes depth alone: at 2048² the ids are
    /// 16 MB of clears and writes a frame, half the pass on lavapipe.
    fn reads_light_surfaces(&self) -> bool {
        false
    }
    /// Whether the method reads the G-buffer's object ids (`gbuf_id`). A method that does says
    /// so; for the others the G-buffer pass draws without that target, a tenth of the pass on
    /// lavapipe.
    fn reads_object_ids(&self) -> bool {
        false
    }
}
