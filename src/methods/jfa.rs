//! Method `jfa-l`: soft shadows by jump flooding in light space (Rong & Tan 2006, §4), with
//! the intensity look-up of §3 made coloured (`jfa_lut`). Shaders: `shaders/methods/jfa/`.
//!
//! How it works: the shadow map (from the light centre) also stores each texel's world
//! position (§4.1 "light space coordinates"). `silhouette.wgsl` marks texels with a deeper
//! neighbour as silhouette pixels, seeded with their own position. `flood_light.wgsl` runs
//! `rounds` rounds with steps 2^(rounds−1) … 1 (§3), each texel keeping, among the occluders
//! its 8 neighbours at ±step carry, the one that gives its own surface point the least light;
//! with 6 rounds occluders travel up to 63 texels (the paper's 63-pixel penumbra). Standard
//! flooding (`flooding: "standard"`, step 1 for 2^rounds − 1 rounds, the same reach) is there
//! for the paper's flooding experiment. `final_light.wgsl` shades eye pixels: hard shadow →
//! 0, a flooded texel → the intensity recomputed from the eye point and the stored occluder,
//! else 1. Only outer penumbrae, as in the paper.

use wgpu::util::DeviceExt;

use super::jfa_lut::{intensity_lut, LUT_SIZE};
use super::{Counters, MethodContext, ParamKind, ParamSpec, Params, ShadowMethod};
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;
use crate::gpu::readback::read_buffer;

pub struct JfaL;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "rounds",
        kind: ParamKind::Integer { default: 6, min: 1, max: 13 },
        doc: "jump-flooding rounds: occluders travel up to 2^rounds − 1 texels (log2 of the resolution floods fully)",
    },
    ParamSpec {
        name: "flooding",
        kind: ParamKind::Choice { default: "jump", options: &["jump", "standard"] },
        doc: "jump flooding, or standard flooding (step 1, 2^rounds − 1 rounds) for the paper's experiment",
    },
    ParamSpec {
        name: "silhouette_relative",
        kind: ParamKind::Float { default: 0.01, min: 0.0, max: 1.0 },
        doc: "a neighbour deeper by more than depth × this marks a silhouette pixel",
    },
    ParamSpec {
        name: "bias_texels",
        kind: ParamKind::Float { default: 1.5, min: 0.0, max: 64.0 },
        doc: "constant depth bias of the hard test, texels",
    },
    ParamSpec {
        name: "slope_bias_texels",
        kind: ParamKind::Float { default: 1.0, min: 0.0, max: 64.0 },
        doc: "slope-scaled depth bias, texels × tanθ",
    },
];

/// Laid out as `JfaParams` in `shaders/methods/jfa/common.wgsl`, one 256-byte slot per pass.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    step: i32,
    silhouette_relative: f32,
    bias_texels: f32,
    slope_bias_texels: f32,
}

const SLOT: u64 = 256;
/// Bytes of one flooded record (`Record` in the shader).
const RECORD_BYTES: u64 = 32;

/// The step lengths of the flood: 2^(rounds−1) … 1, or 1 repeated for standard flooding.
pub fn steps(rounds: u32, standard: bool) -> Vec<i32> {
    if standard {
        vec![1; (1usize << rounds) - 1]
    } else {
        (0..rounds).rev().map(|k| 1 << k).collect()
    }
}

impl ShadowMethod for JfaL {
    fn name(&self) -> &'static str {
        "jfa-l"
    }

    fn summary(&self) -> &'static str {
        "Rong & Tan 2006 §4: silhouette pixels in the shadow map, jump flooding of occluders in light space, intensity by ray to the light through a (coloured) look-up texture; outer penumbra"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> Counters {
        let device = ctx.gpu.device.clone();
        let res = ctx.spec.shadow_resolution;
        let steps = steps(params.u32("rounds"), params.choice("flooding") == "standard");
        let base = Uniforms {
            step: 0,
            silhouette_relative: params.f32("silhouette_relative"),
            bias_texels: params.f32("bias_texels"),
            slope_bias_texels: params.f32("slope_bias_texels"),
        };
        // Slot 0: silhouette and final pass; slots 1…: one per round.
        let mut slots = Vec::new();
        for step in std::iter::once(0).chain(steps.iter().copied()) {
            let mut bytes = bytemuck::bytes_of(&Uniforms { step, ..base }).to_vec();
            bytes.resize(SLOT as usize, 0);
            slots.extend(bytes);
        }
        let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("JfaL::uniforms"),
            contents: &slots,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let lut: Vec<f32> = intensity_lut(&ctx.spec.light, &ctx.spec.light_image).into_iter().flatten().collect();
        let lut_view = device
            .create_texture_with_data(
                &ctx.gpu.queue,
                &wgpu::TextureDescriptor {
                    label: Some("JfaL::lut"),
                    size: wgpu::Extent3d { width: LUT_SIZE, height: LUT_SIZE, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::Rgba32Float,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                },
                wgpu::util::TextureDataOrder::LayerMajor,
                bytemuck::cast_slice(&lut),
            )
            .create_view(&Default::default());
        let records = |label| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: u64::from(res) * u64::from(res) * RECORD_BYTES,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        let (a, b) = (records("JfaL::records_a"), records("JfaL::records_b"));
        let counters = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("JfaL::counters"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let io = [
            layout::uniform_dynamic(0),
            layout::texture_float(1),
            layout::storage_read(2),
            layout::storage_read_write(3),
            layout::storage_texture(4, wgpu::TextureFormat::Rgba32Float),
            layout::storage_read_write(5),
        ];
        let silhouette = ctx.screen_pipeline(PipelineKey::new("jfa-l.silhouette"), "methods/jfa/silhouette.wgsl", &io);
        let flood = ctx.screen_pipeline(PipelineKey::new("jfa-l.flood"), "methods/jfa/flood_light.wgsl", &io);
        let finish = ctx.screen_pipeline(PipelineKey::new("jfa-l.final"), "methods/jfa/final_light.wgsl", &io);
        // Ping-pong: `a_to_b` reads a and writes b, `b_to_a` the reverse.
        let group = |src: &wgpu::Buffer, dst: &wgpu::Buffer| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("JfaL::bind_group"),
                layout: &silhouette.get_bind_group_layout(1),
                entries: &layout::entries(&[
                    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &uniforms,
                        offset: 0,
                        size: wgpu::BufferSize::new(std::mem::size_of::<Uniforms>() as u64),
                    }),
                    wgpu::BindingResource::TextureView(&lut_view),
                    src.as_entire_binding(),
                    dst.as_entire_binding(),
                    wgpu::BindingResource::TextureView(ctx.visibility),
                    counters.as_entire_binding(),
                ]),
            })
        };
        let (a_to_b, b_to_a) = (group(&a, &b), group(&b, &a));
        ctx.encoder.clear_buffer(&counters, 0, None);
        let grid = res.div_ceil(8);
        let (w, h) = ctx.dispatch_size();
        {
            let mut pass = ctx.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("JfaL::passes"),
                timestamp_writes: ctx.timer.compute_scope("method"),
            });
            pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
            // Seeds go to a.
            pass.set_pipeline(&silhouette);
            pass.set_bind_group(1, &b_to_a, &[0]);
            pass.dispatch_workgroups(grid, grid, 1);
            pass.set_pipeline(&flood);
            let mut result_in_a = true;
            for k in 0..steps.len() {
                let offset = ((k as u64 + 1) * SLOT) as u32;
                pass.set_bind_group(1, if result_in_a { &a_to_b } else { &b_to_a }, &[offset]);
                pass.dispatch_workgroups(grid, grid, 1);
                result_in_a = !result_in_a;
            }
            pass.set_pipeline(&finish);
            pass.set_bind_group(1, if result_in_a { &a_to_b } else { &b_to_a }, &[0]);
            pass.dispatch_workgroups(w, h, 1);
        }
        ctx.flush();
        let counts: Vec<u32> = bytemuck::cast_slice(&read_buffer(ctx.gpu, &counters)).to_vec();
        Counters::from([
            ("rounds".to_owned(), steps.len() as f64),
            ("max_reach_texels".to_owned(), f64::from(steps.iter().sum::<i32>())),
            ("silhouette_texels".to_owned(), f64::from(counts[0])),
            ("penumbra_pixels".to_owned(), f64::from(counts[1])),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_lengths_follow_the_paper() {
        assert_eq!(steps(6, false), vec![32, 16, 8, 4, 2, 1]);
        assert_eq!(steps(6, false).iter().sum::<i32>(), 63);
        assert_eq!(steps(3, true), vec![1; 7]);
    }
}
