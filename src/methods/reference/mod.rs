//! Method `reference`: the physically based visibility of contract §1, `Vref = E/E0` per
//! channel, estimated from many point samples on the light. The ground truth every other
//! method is measured against.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#reference.

use glam::{Mat4, UVec2, Vec2, Vec3, Vec4};

use bytemuck::Zeroable as _;

mod cpu;

use super::{Cap, Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::{PipelineKey, TextureKey};
use crate::light::{AreaLight, LightImage};
use crate::render::convex::{map_bounds, ConvexSolid};
use crate::render::{LightProjection, PixelListBuffers};
use crate::render::{ScenePipeline, DEPTH_BUFFER_FORMAT};

pub struct Reference;

const SAMPLES: Param<u32> =
    Param::integer("samples", 256, 1, 4096, "light samples (stratified, jittered); noise falls as 1/√samples").capped(Cap::Samples);
const RESOLUTION: Param<u32> = Param::integer("resolution", 1024, 64, 4096, "side of each sample's depth map, texels");
const BIAS_TEXELS: Param<f32> =
    Param::float("bias_texels", 1.0, 0.0, 64.0, "constant bias of the visibility test, in texels of the sample's map");
const SLOPE_BIAS_TEXELS: Param<f32> =
    Param::float("slope_bias_texels", 1.0, 0.0, 64.0, "slope-scaled bias, texels × tanθ at the receiver (θ to the light's centre)");
const SEED: Param<u32> = Param::integer("seed", 1, 0, 4_294_967_295, "seed of the jitter within strata");
const CROP: Param<bool> = Param::boolean(
    "crop",
    true,
    "draw each sample's map only over the texels where the frame's receivers can fall (the same maps there: less to clear and draw)",
);

const ENGINE: Param<&str> = Param::choice(
    "engine",
    "auto",
    &["auto", "gpu", "cpu"],
    "where the maps are drawn and tested: the device (gpu), the CPU's cores (cpu: the same maps and tests, ~2.5× as fast on a software adapter), or cpu on a software adapter and gpu on a GPU (auto)",
);

const PARAMS: &[ParamSpec] = &[SAMPLES.spec, RESOLUTION.spec, BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec, SEED.spec, CROP.spec, ENGINE.spec];

/// The projection a sample's depth map is drawn with: the angle `fit` gives that sample and the
/// near plane every map shares, reversed-Z with the far plane at infinity, so the stored depth
/// is `near / view depth` (`sample_depth.wgsl`) and float depth keeps the same relative
/// precision at every distance.
fn reversed_projection(tan_half: f32, near: f32) -> Mat4 {
    Mat4::perspective_infinite_reverse_rh(2.0 * tan_half.atan(), 1.0, near)
}

/// The rotation into every sample's view coordinates: each frustum looks along the light
/// normal with the image's up, from its own sample point.
fn sample_rotation(light: &AreaLight) -> Mat4 {
    Mat4::look_to_rh(Vec3::ZERO, light.n, light.u)
}

/// Samples recorded between submissions at least: the frame is submitted, progress reported
/// and cancellation checked after each batch that completes another 16 (every batch where
/// a batch holds 16 or more maps, every other one of 8 at 4096²).
const BATCH: u64 = 16;

/// Memory the depth maps of one accumulate batch may take: 32 maps at the default 1024² and at
/// 2048², eight at 4096². Each batch but the last stores every pixel's sums and each but the
/// first reads them, and on lavapipe a pixel's stores cost about as much as a sample's test,
/// so fewer, larger batches are cheaper.
const BATCH_MAP_BYTES: u64 = 512 << 20;

/// The most samples one accumulate pass reads; mirrors `MAX_SAMPLES` in `accumulate.wgsl`
/// (checked by a test below).
const BATCH_SAMPLES: usize = 32;

/// Depth maps drawn before one accumulate pass reads them all: more per pass reads the
/// G-buffer and updates the sums less often, fewer keeps the maps' memory bounded.
fn batch_layers(resolution: u32) -> u32 {
    let map_bytes = u64::from(resolution) * u64::from(resolution) * 4;
    (BATCH_MAP_BYTES / map_bytes).clamp(1, BATCH_SAMPLES as u64) as u32
}

/// One accumulate pass's samples, laid out as `Batch` in `accumulate.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BatchUniforms {
    rotation: [[f32; 4]; 3],
    resolution: u32,
    bias_texels: f32,
    slope_bias_texels: f32,
    plane: f32,
    near: f32,
    pad: [u32; 3],
    samples: [BatchSample; BATCH_SAMPLES],
}

/// One light sample as the accumulate pass reads it (`BatchSample` in `accumulate.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BatchSample {
    origin: [f32; 4],
    radiance: [f32; 4],
}

/// Pixels of a row per listed segment; mirrors `SEGMENT` in `accumulate.wgsl` (checked by a
/// test below).
const SEGMENT: u32 = 8;

/// Texels of margin around where the receivers fall in a sample's map (`map_bounds`): the
/// accumulate pass finds a receiver's texel by arithmetic of its own, and a G-buffer position
/// may stray from the scene's bounds by a rounding error.
const CROP_MARGIN_TEXELS: f32 = 2.0;

/// Crops are whole multiples of this many texels a side, so that frames of one scene and size
/// reuse the pool's layers instead of allocating a new size each (llvmpipe's tiles are 64²).
const CROP_GRANULE: u32 = 64;

/// The largest crop drawn, as a fraction of the whole map's area; a larger one draws the
/// whole map. A crop changes the rounding of where texel centres fall in x and y, so a few
/// receivers on an edge seen edge-on may see a sample the other way (0.02 % of a 1080p
/// `terrain` frame); it must save enough to be worth that, and only a crop of at most a
/// quarter of the map saved much of the maps' time (docs/methods.md, `reference`).
const MAX_CROP_FRACTION: f32 = 0.25;

/// Which part of each sample's map is drawn: a rectangle of `size` texels of the whole
/// `resolution`² map, at each sample's `origins` (its top-left texel in the whole map; `None`
/// where no receiver of the frame falls in the map). Only texels a receiver can fall in are
/// read, so drawing the rest — clearing and filling it — buys nothing. Within the crop every
/// texel sees the same scene at the same depth as in the whole map: the same frustum, shifted
/// and scaled in x and y only, which leaves the depth as it was (the clip z and w rows are
/// untouched). Only rounding differs: a texel centre on a triangle's edge may fall the other
/// side of it.
#[derive(Debug, Clone, PartialEq)]
struct MapCrop {
    size: UVec2,
    origins: Vec<Option<UVec2>>,
}

impl MapCrop {
    /// Every map whole.
    fn whole(samples: usize, resolution: u32) -> Self {
        Self { size: UVec2::splat(resolution), origins: vec![Some(UVec2::ZERO); samples] }
    }

    /// The smallest crop, whole multiples of `CROP_GRANULE` a side, that holds every sample's
    /// receivers (`bounds`, in texels of its whole map) with a margin; the whole map where
    /// that is more than `MAX_CROP_FRACTION` of it.
    fn fit(bounds: Vec<Option<(Vec2, Vec2)>>, resolution: u32) -> Self {
        let whole = Vec2::splat(resolution as f32);
        let rects: Vec<Option<(UVec2, UVec2)>> = bounds
            .into_iter()
            .map(|bounds| {
                let (lo, hi) = bounds?;
                let lo = (lo - CROP_MARGIN_TEXELS).floor().clamp(Vec2::ZERO, whole);
                let hi = (hi + CROP_MARGIN_TEXELS).ceil().clamp(Vec2::ZERO, whole);
                (lo.x < hi.x && lo.y < hi.y).then(|| (lo.as_uvec2(), hi.as_uvec2()))
            })
            .collect();
        let extent = rects.iter().flatten().fold(UVec2::ONE, |extent, (lo, hi)| extent.max(*hi - *lo));
        let size =
            UVec2::new(extent.x.next_multiple_of(CROP_GRANULE), extent.y.next_multiple_of(CROP_GRANULE)).min(UVec2::splat(resolution));
        if size.as_vec2().element_product() > MAX_CROP_FRACTION * whole.element_product() {
            return Self::whole(rects.len(), resolution);
        }
        let origins = rects.iter().map(|rect| rect.map(|(lo, _)| lo.min(UVec2::splat(resolution) - size))).collect();
        Self { size, origins }
    }

    /// The projection that draws a crop of the map `view_proj` draws: x and y scaled by
    /// resolution / size and shifted so that whole-map texel `origin + i` lands on crop
    /// texel `i`; `view_proj` itself for a whole map.
    fn layer_view_proj(&self, origin: Option<UVec2>, resolution: u32, view_proj: Mat4) -> Mat4 {
        let (Some(origin), false) = (origin, self.size == UVec2::splat(resolution)) else { return view_proj };
        let (whole, crop, o) = (resolution as f32, self.size.as_vec2(), origin.as_vec2());
        Mat4::from_cols(
            Vec4::new(whole / crop.x, 0.0, 0.0, 0.0),
            Vec4::new(0.0, whole / crop.y, 0.0, 0.0),
            Vec4::Z,
            Vec4::new((whole - 2.0 * o.x) / crop.x - 1.0, 1.0 - (whole - 2.0 * o.y) / crop.y, 0.0, 1.0),
        ) * view_proj
    }
}

/// A point on the light and its weight: `L(y)` times the area of its stratum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    pub position: Vec3,
    pub weight: Vec3,
}

/// Stratified jittered samples over the light, skipping those that land on black texels.
/// Returns the samples and how many strata there were.
pub fn light_samples(light: &AreaLight, image: &LightImage, requested: u32, seed: u64) -> (Vec<LightSample>, u32) {
    let aspect = light.size_m.x / light.size_m.y;
    let gx = ((requested as f32 * aspect).sqrt().round() as u32).clamp(1, requested);
    let gy = requested.div_ceil(gx).max(1);
    let stratum_area = light.area_m2() / (gx * gy) as f32;
    let mut rng = SplitMix64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15).wrapping_add(1));
    let mut samples = Vec::with_capacity((gx * gy) as usize);
    for j in 0..gy {
        for i in 0..gx {
            let s = (i as f32 + rng.next_f32()) / gx as f32;
            let t = (j as f32 + rng.next_f32()) / gy as f32;
            let (ti, tj) = image.texel_at(s, t);
            let emission = image.emission(ti, tj);
            if emission.max_element() <= 0.0 {
                continue;
            }
            samples.push(LightSample { position: light.image_point(s, t), weight: emission * light.intensity * stratum_area });
        }
    }
    (samples, gx * gy)
}

/// splitmix64: a tiny, well-mixed generator whose stream never changes between versions.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }
}

impl ShadowMethod for Reference {
    fn name(&self) -> &'static str {
        "reference"
    }

    fn summary(&self) -> &'static str {
        "ground truth: many stratified light samples, a depth map each, per-channel ratio E/E0"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    /// A depth map of its own from every sample, none from the light's centre.
    fn reads_shadow_map(&self) -> bool {
        false
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let plan = SamplePlan::new(ctx, params);
        let on_cpu = match params.get(&ENGINE) {
            "cpu" => true,
            "gpu" => false,
            _ => ctx.gpu.software,
        };
        if on_cpu {
            return record_on_cpu(ctx, params, &plan);
        }
        let (view_projs, slots) = plan.slots();
        let layers = batch_layers(plan.resolution).min(slots.len().max(1) as u32);
        let batches = plan.batches(&slots, layers, params);
        let maps = DepthMaps::new(ctx, plan.crop.size, layers, &view_projs);
        let accumulation = Accumulation::new(ctx, &plan, &batches);
        let total = plan.samples.len() as u64;
        let mut before = 0;
        for (b, &(count, _)) in batches.iter().enumerate() {
            let first = before as usize;
            maps.draw(ctx, first, &plan.crop.origins[first..first + count as usize]);
            accumulation.record(ctx, &maps, b, count, b + 1 == batches.len());
            let done = before + u64::from(count);
            let flush = done / BATCH > before / BATCH || done == total;
            before = done;
            if flush {
                ctx.flush()?;
                ctx.supervisor.progress(done, total);
                // Cancelled: the renderer discards this frame, so the remaining batches
                // would only keep the device from the next job.
                if ctx.supervisor.cancelled() {
                    break;
                }
            }
        }
        let segments_tested = ctx.read_counters(&accumulation.segments_count)?[0];
        let mut counters = plan.counters(segments_tested);
        counters.insert("engine_cpu".to_owned(), 0.0);
        Ok(counters)
    }
}

/// Engine `cpu` (`cpu.rs`): the G-buffer read back, the same maps and tests on the CPU's
/// cores, and the visibility written to the frame's buffer.
fn record_on_cpu(ctx: &mut MethodContext<'_>, params: &Params, plan: &SamplePlan) -> JobResult<Counters> {
    let started = std::time::Instant::now();
    let constants = cpu::TestConstants {
        rotation: plan.rotation,
        plane: plan.plane,
        near: plan.near,
        resolution: plan.resolution,
        bias_texels: params.get(&BIAS_TEXELS),
        slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS),
        light_center: ctx.spec.light.center,
    };
    let receivers = ctx.read_gbuffer(|gbuffer| cpu::Receivers::new(gbuffer, SEGMENT, &constants))?;
    // Each sample as the GPU engine's accumulate pass reads it, with its crop's projection.
    let (view_projs, slots) = plan.slots();
    let samples: Vec<cpu::CpuSample> = slots
        .iter()
        .zip(&view_projs)
        .zip(&plan.crop.origins)
        .map(|((slot, view_proj), origin)| cpu::CpuSample {
            view_proj: Mat4::from_cols_array_2d(view_proj),
            origin: [slot.origin[0], slot.origin[1]],
            texels_per_tan: slot.radiance[3],
            crop_origin: *origin,
            weight: Vec3::from_slice(&slot.radiance[..3]),
        })
        .collect();
    let channels = plan.channels() as usize;
    let read_ms = started.elapsed().as_secs_f64() * 1e3;
    let total = samples.len() as u64;
    let supervisor = ctx.supervisor;
    let mut before = 0;
    let (sums, spent) =
        cpu::estimate(&receivers, &samples, &constants, (ctx.scene.positions(), ctx.scene.indices()), channels, plan.crop.size, |done| {
            // Progress as often as the GPU engine reports it: each time another `BATCH` are done.
            let done = done as u64;
            if done / BATCH > before / BATCH || done == total {
                supervisor.progress(done, total);
            }
            before = done;
            // Cancelled: the renderer discards this frame.
            !supervisor.cancelled()
        });
    let written = std::time::Instant::now();
    let mut visibility = vec![0u8; ctx.width as usize * ctx.height as usize * 16];
    cpu::write_visibility(&receivers, &sums, channels, ctx.width, &mut visibility);
    ctx.gpu.queue.write_buffer(ctx.visibility, 0, &visibility);
    let write_ms = written.elapsed().as_secs_f64() * 1e3;
    ctx.timer.cpu_pass("method", "reference_cpu_receivers", read_ms);
    ctx.timer.cpu_pass("method", "reference_cpu_maps", spent.maps_ms);
    ctx.timer.cpu_pass("method", "reference_cpu_tests", spent.tests_ms);
    ctx.timer.cpu_pass("method", "reference_cpu_visibility", write_ms);
    let mut counters = plan.counters(receivers.segments);
    counters.extend([("engine_cpu".to_owned(), 1.0), ("cpu_threads".to_owned(), spent.round as f64)]);
    Ok(counters)
}

/// A frame's light samples and how each one's map is drawn and read.
struct SamplePlan {
    samples: Vec<LightSample>,
    /// Strata of the light, black ones included (`samples_skipped_black`).
    strata: u32,
    resolution: u32,
    /// Into every sample's view coordinates (`sample_rotation`).
    rotation: Mat4,
    /// The near plane every map shares.
    near: f32,
    /// Every sample point's z in view coordinates: they all lie on the light's plane.
    plane: f32,
    /// Per sample, its whole map's view-projection and its texels per unit of tan from the
    /// map's centre.
    frusta: Vec<(Mat4, f32)>,
    crop: MapCrop,
}

impl SamplePlan {
    fn new(ctx: &MethodContext<'_>, params: &Params) -> Self {
        let spec = ctx.spec;
        let resolution = params.get(&RESOLUTION);
        let (samples, strata) = light_samples(&spec.light, &spec.light_image, params.get(&SAMPLES), u64::from(params.get(&SEED)));
        let corners = ctx.scene.shadow_fit_points(&spec.light);
        let rotation = sample_rotation(&spec.light);
        // Each sample's frustum: its angle fitted to the scene from its point, and one near
        // plane for every map (the nearest any fit allows), so that the accumulate pass reads
        // it once per pixel, not per sample.
        let fits: Vec<LightProjection> =
            samples.iter().map(|sample| LightProjection::fit(&AreaLight { center: sample.position, ..spec.light }, &corners)).collect();
        let near = fits.iter().map(|fit| fit.near).reduce(f32::min).unwrap_or(1.0);
        let plane = rotation.transform_point3(spec.light.center).z;
        let frusta: Vec<(Mat4, f32)> = samples
            .iter()
            .zip(&fits)
            .map(|(sample, fit)| {
                let view = rotation * Mat4::from_translation(-sample.position);
                let proj = reversed_projection(fit.tan_half, near);
                (proj * view, proj.y_axis.y * resolution as f32 * 0.5)
            })
            .collect();
        let crop = if params.get(&CROP) {
            // Every receiver of the frame (a G-buffer position) lies in what the camera sees of
            // the scene's bounds.
            let receivers = ConvexSolid::frustum(spec.camera.view_proj(ctx.width as f32 / ctx.height as f32))
                .intersect(&ConvexSolid::cuboid(ctx.scene.bounds_min, ctx.scene.bounds_max));
            MapCrop::fit(frusta.iter().map(|(view_proj, ..)| map_bounds(&receivers, *view_proj, resolution)).collect(), resolution)
        } else {
            MapCrop::whole(samples.len(), resolution)
        };
        Self { samples, strata, resolution, rotation, near, plane, frusta, crop }
    }

    /// Per sample: its map's projection (the depth pass) and what the accumulate pass needs.
    fn slots(&self) -> (Vec<[[f32; 4]; 4]>, Vec<BatchSample>) {
        self.samples
            .iter()
            .zip(&self.frusta)
            .zip(&self.crop.origins)
            .map(|((sample, (view_proj, texels_per_tan)), origin)| {
                // The crop's first texel, x and y in one word: indices under 2¹² leave the float
                // exponent short of all ones, so the word is never a NaN to be canonicalised.
                let crop_origin = origin.map_or(0, |o| o.x | o.y << 16);
                let view = self.rotation.transform_point3(sample.position);
                let slot = BatchSample {
                    origin: [view.x, view.y, f32::from_bits(crop_origin), 0.0],
                    radiance: sample.weight.extend(*texels_per_tan).to_array(),
                };
                (self.crop.layer_view_proj(*origin, self.resolution, *view_proj).to_cols_array_2d(), slot)
            })
            .unzip()
    }

    /// The accumulate passes' uniforms, `layers` samples a pass (the last may hold fewer),
    /// each with its count of samples. No samples (a black light): one empty batch, whose
    /// ratio is 1 everywhere.
    fn batches(&self, slots: &[BatchSample], layers: u32, params: &Params) -> Vec<(u32, BatchUniforms)> {
        let chunks: Vec<&[BatchSample]> = if slots.is_empty() { vec![&[]] } else { slots.chunks(layers as usize).collect() };
        chunks
            .into_iter()
            .map(|chunk| {
                let mut batch = BatchUniforms::zeroed();
                batch.rotation = [0, 1, 2].map(|i| self.rotation.row(i).to_array());
                batch.resolution = self.resolution;
                batch.bias_texels = params.get(&BIAS_TEXELS);
                batch.slope_bias_texels = params.get(&SLOPE_BIAS_TEXELS);
                batch.plane = self.plane;
                batch.near = self.near;
                batch.samples[..chunk.len()].copy_from_slice(chunk);
                (chunk.len() as u32, batch)
            })
            .collect()
    }

    /// The counters either engine reports: samples taken and left out, the row segments
    /// tested, the maps' resolution and the part of each map drawn.
    fn counters(&self, segments_tested: u32) -> Counters {
        let total = self.samples.len() as f64;
        Counters::from([
            ("samples".to_owned(), total),
            ("segments_tested".to_owned(), f64::from(segments_tested)),
            ("samples_skipped_black".to_owned(), f64::from(self.strata) - total),
            ("resolution".to_owned(), f64::from(self.resolution)),
            ("map_crop_fraction".to_owned(), f64::from(self.crop.size.element_product()) / f64::from(self.resolution).powi(2)),
        ])
    }

    /// Channels of the sums: one where every sample's weight is gray (its three sums would be
    /// equal), else three.
    fn channels(&self) -> u32 {
        if self.samples.iter().all(|s| s.weight.x == s.weight.y && s.weight.x == s.weight.z) {
            1
        } else {
            3
        }
    }
}

/// A batch's depth maps: the depth buffers themselves (`sample_depth.wgsl`), one layer each of
/// a pooled array the size of the crop, drawn with every sample's projection.
struct DepthMaps {
    /// Where each layer is drawn.
    layer_views: Vec<wgpu::TextureView>,
    /// The whole array, as the accumulate pass reads it.
    array_view: wgpu::TextureView,
    pipeline: std::sync::Arc<wgpu::RenderPipeline>,
    /// Every sample's projection, one slot each (`layout::uniform_slots`).
    projections: wgpu::BindGroup,
}

impl DepthMaps {
    fn new(ctx: &mut MethodContext<'_>, size: UVec2, layers: u32, view_projs: &[[[f32; 4]; 4]]) -> Self {
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

    /// Draws a batch's maps: samples `first..` of the frame, whose crop origins are `origins`
    /// (`None`: no receiver of the frame falls in that map, cleared and left empty), into
    /// layers `0..`. Timed together where timestamps can be written between passes (a scope per
    /// map would take the timer's queries at 256 samples). A render pass each, though lavapipe
    /// begins every pass by waiting until the one before is rasterised: a multiview pass saved
    /// little and needs a guard against a lavapipe bug, and a batch in one pass (an atlas) would round each map's vertices
    /// differently (`docs/performance-log.md`).
    fn draw(&self, ctx: &mut MethodContext<'_>, first: usize, origins: &[Option<UVec2>]) {
        let scene = ctx.scene;
        ctx.timer.time_encoder(ctx.encoder, "method", "reference_maps", |encoder| {
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
                pass.draw_indexed(0..scene.index_count, 0, 0..1);
            }
        });
    }
}

/// What every batch's accumulate pass binds besides its maps, and what picks its pipeline.
struct Accumulation {
    /// The batches' uniforms, a slot each.
    batches: wgpu::Buffer,
    /// Every covered pixel's two sums, per channel: the first batch writes them and the last
    /// reads them (a single batch needs none).
    sums: wgpu::Buffer,
    /// The row segments that hold a receiver, and the dispatch over them.
    segments: PixelListBuffers,
    /// How many were listed, for the counter `segments_tested`.
    segments_count: wgpu::Buffer,
    channels: u32,
    cropped: bool,
}

impl Accumulation {
    /// Takes the sums from the pool and lists the segments (recorded here, before the first
    /// batch's maps).
    fn new(ctx: &mut MethodContext<'_>, plan: &SamplePlan, batches: &[(u32, BatchUniforms)]) -> Self {
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
    fn record(&self, ctx: &mut MethodContext<'_>, maps: &DepthMaps, b: usize, count: u32, last: bool) {
        // One pipeline per batch size (`SAMPLES` in accumulate.wgsl: all but the last batch
        // are full), channels of the sums, whether it is the first or last, and whether the
        // maps are cropped.
        let first = b == 0;
        let pipeline = ctx.screen_specialized(
            PipelineKey {
                name: "reference.accumulate",
                variant: count | self.channels << 8 | u32::from(first) << 16 | u32::from(last) << 17 | u32::from(self.cropped) << 18,
            },
            ("methods/reference/accumulate.wgsl", "main"),
            &[
                layout::uniform_dynamic(0),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
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
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, "method", "reference_accumulate");
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        pass.set_bind_group(1, &group, &[layout::slot_offset_of::<BatchUniforms>(b)]);
        pass.dispatch_workgroups_indirect(&self.segments.groups, 0);
    }
}

/// Lists the frame's row segments that hold a covered pixel (`list_segments` in
/// accumulate.wgsl, which writes the others' visibility) and sizes the batches' dispatch over
/// them: recorded once, before the first batch.
fn list_segments(ctx: &mut MethodContext<'_>) -> (PixelListBuffers, wgpu::Buffer) {
    let segments = u64::from(ctx.width.div_ceil(SEGMENT)) * u64::from(ctx.height);
    let list = PixelListBuffers::new(&ctx.gpu.device, ctx.encoder, "Reference::segments", segments);
    let shader = "methods/reference/accumulate.wgsl";
    let lister = ctx.screen_entry(
        PipelineKey::new("reference.list_segments"),
        shader,
        "list_segments",
        &[layout::storage_read_write(3), layout::storage_read_write(4)],
    );
    let sizer = ctx.screen_entry(
        PipelineKey::new("reference.segments_size"),
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
    let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, "method", "reference_list");
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
fn depth_pipeline(ctx: &mut MethodContext<'_>) -> std::sync::Arc<wgpu::RenderPipeline> {
    let device = &ctx.gpu.device;
    ctx.pipelines.render(PipelineKey::new("reference.sample_depth"), || {
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
mod tests;
