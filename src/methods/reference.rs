//! Method `reference`: the physically based visibility of contract §1, `Vref = E/E0` per
//! channel, estimated from many point samples on the light. The ground truth every other
//! method is measured against.
//!
//! Samples are stratified over the light rectangle (a grid matching its aspect) and jittered
//! within each stratum; a sample that lands on a black or transparent texel has no weight and
//! costs nothing. For each sample the scene is drawn into a distance map from the sample
//! point (`sample_depth.wgsl`), copied into a layer of a plain buffer; once per batch of up to
//! eight samples every pixel adds the batch's `L·G·V` and `L·G` to two sums
//! (`accumulate.wgsl`), and `resolve.wgsl` divides them. Batching changes only the order of
//! the additions (the same samples, maps and tests); it took the 64-sample reference at 1080p
//! on lavapipe from 2.0 s to 1.3 s. Numerator and denominator share the same
//! samples, so lit and umbra pixels are exact and the noise lives only in the penumbra.
//!
//! Bias controls: the visibility test forgives `bias_texels + slope_bias_texels·tanθ` texels
//! of each sample's map, so the bias in metres shrinks as `resolution` grows; with samples
//! and resolution both growing the estimate converges to the true visibility (the analytic
//! test in `tests/render.rs` shows the error shrinking).

use glam::Vec3;

use bytemuck::Zeroable as _;

use super::{Cap, Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;
use crate::light::{AreaLight, LightImage};
use crate::render::LightProjection;
use crate::render::{ScenePipeline, DEPTH_BUFFER_FORMAT};

pub struct Reference;

const SAMPLES: Param<u32> =
    Param::integer("samples", 256, 1, 4096, "light samples (stratified, jittered); noise falls as 1/√samples").capped(Cap::Samples);
const RESOLUTION: Param<u32> = Param::integer("resolution", 1024, 64, 4096, "side of each sample's distance map, texels");
const BIAS_TEXELS: Param<f32> =
    Param::float("bias_texels", 1.0, 0.0, 64.0, "constant bias of the visibility test, in texels of the sample's map");
const SLOPE_BIAS_TEXELS: Param<f32> = Param::float("slope_bias_texels", 1.0, 0.0, 64.0, "slope-scaled bias, texels × tanθ at the receiver");
const SEED: Param<u32> = Param::integer("seed", 1, 0, 4_294_967_295, "seed of the jitter within strata");

const PARAMS: &[ParamSpec] = &[SAMPLES.spec, RESOLUTION.spec, BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec, SEED.spec];

/// The unit of a sample's distance map (its depth 1.0), metres: twice the distance to the
/// frustum's farthest corner, so every point the map can hold is nearer and a receiver just
/// past the far plane still tests as lit against an empty texel.
fn distance_unit(projection: &LightProjection) -> f32 {
    2.0 * projection.far * (1.0 + 2.0 * projection.tan_half * projection.tan_half).sqrt()
}

/// Samples recorded per submission; progress is reported between submissions.
const BATCH: u64 = 16;

/// Memory the distance maps of one accumulate batch may take: 8 maps at the default 1024²,
/// one at 4096².
const BATCH_MAP_BYTES: u64 = 64 << 20;

/// The most samples one accumulate pass reads; mirrors `BATCH` in `accumulate.wgsl`.
const BATCH_SAMPLES: usize = 8;

/// Distance maps drawn before one accumulate pass reads them all: more per pass reads the
/// G-buffer and updates the sums less often, fewer keeps the maps' memory bounded.
fn batch_layers(resolution: u32) -> u32 {
    let map_bytes = u64::from(resolution) * u64::from(resolution) * 4;
    (BATCH_MAP_BYTES / map_bytes).clamp(1, BATCH_SAMPLES as u64) as u32
}

/// One accumulate pass's samples, laid out as `Batch` in `accumulate.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BatchUniforms {
    count: u32,
    row_texels: u32,
    pad: [u32; 2],
    samples: [SampleUniforms; BATCH_SAMPLES],
}

/// One light sample, laid out as `LightSample` in `shaders/methods/reference/sample.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct SampleUniforms {
    view_proj: [[f32; 4]; 4],
    position: [f32; 4],
    radiance: [f32; 4],
    params: [f32; 4],
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
    fn reads_light_surfaces(&self) -> bool {
        false
    }

    fn name(&self) -> &'static str {
        "reference"
    }

    fn summary(&self) -> &'static str {
        "ground truth: many stratified light samples, a distance map each, per-channel ratio E/E0"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let device = ctx.gpu.device.clone();
        let spec = ctx.spec;
        let resolution = params.get(&RESOLUTION);
        let (samples, strata) = light_samples(&spec.light, &spec.light_image, params.get(&SAMPLES), u64::from(params.get(&SEED)));
        let corners = ctx.scene.shadow_fit_points(&spec.light);
        let slots: Vec<SampleUniforms> = samples
            .iter()
            .map(|sample| {
                let at_sample = AreaLight { center: sample.position, ..spec.light };
                let projection = LightProjection::fit(&at_sample, &corners);
                SampleUniforms {
                    view_proj: projection.view_proj.to_cols_array_2d(),
                    position: sample.position.extend(distance_unit(&projection)).to_array(),
                    radiance: sample.weight.extend(0.0).to_array(),
                    params: [projection.tan_half, resolution as f32, params.get(&BIAS_TEXELS), params.get(&SLOPE_BIAS_TEXELS)],
                }
            })
            .collect();
        let uniform_buffer = layout::uniform_slots(&device, "Reference::samples", &slots);
        // Each sample's map is copied into its layer of a plain buffer, in rows padded for the
        // copy, which the accumulate pass reads: a storage-buffer load on lavapipe is a plain
        // gather, a texel fetch adds format and robustness handling.
        let row_bytes = (4 * resolution).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let layer_bytes = u64::from(row_bytes) * u64::from(resolution);
        let layers = batch_layers(resolution).min(slots.len().max(1) as u32);
        let batches: Vec<BatchUniforms> = slots
            .chunks(layers as usize)
            .map(|chunk| {
                let mut batch = BatchUniforms::zeroed();
                batch.count = chunk.len() as u32;
                batch.row_texels = row_bytes / 4;
                batch.samples[..chunk.len()].copy_from_slice(chunk);
                batch
            })
            .collect();
        let batch_buffer = layout::uniform_slots(&device, "Reference::batches", &batches);
        let pixels = u64::from(ctx.width) * u64::from(ctx.height);
        let sums = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Reference::sums"),
            size: pixels * 32,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let target = |label, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: resolution, height: resolution, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        // The distance map is the depth buffer itself (`sample_depth.wgsl`).
        let distance = target("Reference::distance", DEPTH_BUFFER_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC);
        let distance_view = distance.create_view(&Default::default());
        let distances = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Reference::distances"),
            size: layer_bytes * u64::from(layers),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let (depth_pipeline, accumulate_pipeline, resolve_pipeline) = self.pipelines(ctx);
        let depth_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Reference::sample"),
            layout: &depth_pipeline.get_bind_group_layout(0),
            entries: &layout::entries(&[layout::slot_binding::<SampleUniforms>(&uniform_buffer)]),
        });
        let accumulate_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Reference::accumulate"),
            layout: &accumulate_pipeline.get_bind_group_layout(1),
            entries: &layout::entries(&[
                layout::slot_binding::<BatchUniforms>(&batch_buffer),
                distances.as_entire_binding(),
                sums.as_entire_binding(),
            ]),
        });
        let resolve_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Reference::resolve"),
            layout: &resolve_pipeline.get_bind_group_layout(1),
            entries: &layout::entries(&[sums.as_entire_binding(), ctx.visibility.as_entire_binding()]),
        });

        ctx.encoder.clear_buffer(&sums, 0, None);
        let (gx, gy) = ctx.dispatch_size();
        let total = samples.len() as u64;
        let mut before = 0;
        for (b, batch) in batches.iter().enumerate() {
            for layer in 0..batch.count {
                let k = before as usize + layer as usize;
                let mut pass = ctx.encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("Reference::sample_depth"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &distance_view,
                        depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&depth_pipeline);
                pass.set_bind_group(0, &depth_group, &[layout::slot_offset(k)]);
                pass.set_vertex_buffer(0, ctx.scene.vertex_buffer.slice(..));
                pass.set_index_buffer(ctx.scene.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..ctx.scene.index_count, 0, 0..1);
                drop(pass);
                ctx.encoder.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo { aspect: wgpu::TextureAspect::DepthOnly, ..distance.as_image_copy() },
                    wgpu::TexelCopyBufferInfo {
                        buffer: &distances,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: u64::from(layer) * layer_bytes,
                            bytes_per_row: Some(row_bytes),
                            rows_per_image: Some(resolution),
                        },
                    },
                    wgpu::Extent3d { width: resolution, height: resolution, depth_or_array_layers: 1 },
                );
            }
            {
                let mut pass = ctx
                    .encoder
                    .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("Reference::accumulate"), timestamp_writes: None });
                pass.set_pipeline(&accumulate_pipeline);
                pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
                pass.set_bind_group(1, &accumulate_group, &[layout::slot_offset_of::<BatchUniforms>(b)]);
                pass.dispatch_workgroups(gx, gy, 1);
            }
            let done = before + u64::from(batch.count);
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
        {
            let mut pass =
                ctx.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("Reference::resolve"), timestamp_writes: None });
            pass.set_pipeline(&resolve_pipeline);
            pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
            pass.set_bind_group(1, &resolve_group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        Ok(Counters::from([
            ("samples".to_owned(), total as f64),
            ("samples_skipped_black".to_owned(), f64::from(strata) - total as f64),
            ("resolution".to_owned(), f64::from(resolution)),
        ]))
    }
}

impl Reference {
    fn pipelines(
        &self,
        ctx: &mut MethodContext<'_>,
    ) -> (std::sync::Arc<wgpu::RenderPipeline>, std::sync::Arc<wgpu::ComputePipeline>, std::sync::Arc<wgpu::ComputePipeline>) {
        let device = &ctx.gpu.device;
        let bgl = |label, entries: &[wgpu::BindGroupLayoutEntry]| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries })
        };
        let depth = ctx.pipelines.render(PipelineKey::new("reference.sample_depth"), || {
            let sample_layout = bgl("Reference::sample_layout", &[layout::uniform_dynamic(0)]);
            let pipeline = ScenePipeline {
                fragment: "fs_main",
                label: "Reference::sample_depth",
                shader: "methods/reference/sample_depth.wgsl",
                bind_group_layouts: &[&sample_layout],
                targets: &[],
            };
            pipeline.build(device)
        });
        let accumulate = ctx.screen_pipeline(
            PipelineKey::new("reference.accumulate"),
            "methods/reference/accumulate.wgsl",
            &[layout::uniform_dynamic(0), layout::storage_read(1), layout::storage_read_write(2)],
        );
        let resolve = ctx.screen_pipeline(
            PipelineKey::new("reference.resolve"),
            "methods/reference/resolve.wgsl",
            &[layout::storage_read(0), layout::storage_read_write(1)],
        );
        (depth, accumulate, resolve)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn samples_are_stratified_and_skip_black() {
        let light = AreaLight::new(Vec3::Y, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 3.0).unwrap();
        let white = LightImage::builtin("white", &Default::default(), "f").unwrap();
        let (samples, strata) = light_samples(&light, &white, 200, 1);
        assert_eq!(samples.len() as u32, strata);
        assert!(strata >= 200);
        // Weights sum to L × area for a uniform light.
        let total: Vec3 = samples.iter().map(|s| s.weight).sum();
        assert!((total - Vec3::splat(3.0 * 2.0)).abs().max_element() < 1e-3);
        // The disk leaves out its corners: about 1 − π/4 of the strata.
        let disk = LightImage::builtin("disk", &Default::default(), "f").unwrap();
        let square = AreaLight { size_m: Vec2::ONE, ..light };
        let (samples, strata) = light_samples(&square, &disk, 1024, 1);
        let skipped = 1.0 - samples.len() as f32 / strata as f32;
        assert!((skipped - (1.0 - std::f32::consts::FRAC_PI_4)).abs() < 0.03, "{skipped}");
    }
}
