//! The renderer's own passes, recorded into a phase's encoder: the light-space shadow map
//! and the eye-space G-buffer (the scene drawn through `draw::ScenePipeline`), then the
//! screen-space E0 and composite compute passes over the frame inputs.

use std::sync::Arc;

use super::draw::{begin_scene_pass, clear_attachment, ScenePipeline};
use super::targets::{FrameTargets, ALBEDO_FORMAT, ID_FORMAT, NORMAL_FORMAT, POSITION_FORMAT, SHADOW_DEPTH_FORMAT};
use super::{FrameInputs, FrameSpec, PixelListBuffers, Renderer};
use crate::gpu::layout;
use crate::gpu::pool::{BufferKey, PipelineKey};
use crate::gpu::scene::GpuScene;
use crate::gpu::shaders;
use crate::render::method::Scratch;
use crate::timing::PhaseName;

/// Pixels per side of the blocks whose corners E0 is summed at exactly (`shaders/e0/`).
pub const E0_BLOCK: u32 = 8;

/// How the E0 pass evaluates the light's cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum E0Mode {
    /// Exact at block corners, interpolated inside blocks where the error estimate allows.
    #[default]
    Interpolated,
    /// Exact at every pixel: the yardstick `penumbra bench` measures the interpolation with.
    Exact,
}
/// Lights of at most this many cells get the exact sum at every pixel: the corners and their
/// check cost more than they save.
pub const E0_EXACT_CELLS: usize = 2;
/// Bytes of one block corner's record (`Corner` in `shaders/e0/common.wgsl`).
const E0_CORNER_BYTES: u64 = 5 * 16;

impl Renderer {
    fn draw_bind_group(&self, scene: &GpuScene) -> wgpu::BindGroup {
        self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Renderer::draw_bind_group"),
            layout: &self.layouts.draw,
            entries: &layout::entries(&[self.uniforms.as_entire_binding(), scene.materials.as_entire_binding()]),
        })
    }

    /// The shadow map from the light's centre: depth, and with `surfaces` the object ids too
    /// (`ShadowMethod::reads_light_surfaces`; the world positions are the depth's texel rays,
    /// `shadow_point` in common/shadow.wgsl).
    pub(super) fn record_shadow_map(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        targets: &FrameTargets,
        surfaces: bool,
    ) {
        let device = &self.gpu.device;
        let draw_layout = &self.layouts.draw;
        let (fragment, targets_written): (_, &[wgpu::TextureFormat]) =
            if surfaces { ("fs_main", &[SHADOW_DEPTH_FORMAT, ID_FORMAT]) } else { ("fs_depth", &[SHADOW_DEPTH_FORMAT]) };
        let key = PipelineKey::render("shadow_map", "shadow_map.wgsl", Some(fragment), targets_written);
        let pipeline = self.pipelines.render(key, || {
            let targets = targets_written;
            let pipeline = ScenePipeline {
                label: "ShadowMap::pipeline",
                shader: "shadow_map.wgsl",
                fragment: Some(fragment),
                bind_group_layouts: &[draw_layout],
                targets,
                depth_compare: wgpu::CompareFunction::Less,
            };
            pipeline.build(device)
        });
        let bind_group = self.draw_bind_group(scene);
        let all = [
            Some(clear_attachment(&targets.shadow_depth.view, f64::from(f32::MAX))),
            Some(clear_attachment(&targets.shadow_id.view, f64::from(u32::MAX))),
        ];
        let colors = if surfaces { &all[..] } else { &all[..1] };
        let timestamps = self.timer.render_scope(PhaseName::ShadowMap, "ShadowMap::pass");
        let mut pass = begin_scene_pass(
            encoder,
            "ShadowMap::pass",
            colors,
            &targets.shadow_depth_buffer.view,
            timestamps,
            (&pipeline, &bind_group),
            scene,
        );
        pass.draw_indexed(0..scene.index_count, 0, 0..1);
    }

    pub(super) fn record_gbuffer(&mut self, encoder: &mut wgpu::CommandEncoder, scene: &GpuScene, targets: &FrameTargets, ids: bool) {
        let device = &self.gpu.device;
        let (draw_layout, material_layout) = (&self.layouts.draw, &self.layouts.material);
        // Two fragment entry points: materials with a texture, and those without (no sample).
        // With `ids` (`ShadowMethod::reads_object_ids`) the object-id target too; without, the
        // fragment's id output has no attachment and is dropped.
        let formats: &[wgpu::TextureFormat] = if ids {
            &[POSITION_FORMAT, NORMAL_FORMAT, ALBEDO_FORMAT, NORMAL_FORMAT, ID_FORMAT]
        } else {
            &[POSITION_FORMAT, NORMAL_FORMAT, ALBEDO_FORMAT, NORMAL_FORMAT]
        };
        let mut pipeline = |name: &'static str, fragment: &'static str| {
            self.pipelines.render(PipelineKey::render(name, "gbuffer.wgsl", Some(fragment), formats), || {
                let pipeline = ScenePipeline {
                    label: "GBuffer::pipeline",
                    shader: "gbuffer.wgsl",
                    fragment: Some(fragment),
                    bind_group_layouts: &[draw_layout, material_layout],
                    targets: formats,
                    depth_compare: wgpu::CompareFunction::Less,
                };
                pipeline.build(device)
            })
        };
        let textured = pipeline("gbuffer", "fs_main");
        let untextured = pipeline("gbuffer.untextured", "fs_untextured");
        let bind_group = self.draw_bind_group(scene);
        let colors = [
            Some(clear_attachment(&targets.position.view, 0.0)),
            Some(clear_attachment(&targets.normal.view, 0.0)),
            Some(clear_attachment(&targets.albedo.view, 0.0)),
            Some(clear_attachment(&targets.shading.view, 0.0)),
            Some(clear_attachment(&targets.object_id.view, f64::from(u32::MAX))),
        ];
        let colors = &colors[..formats.len()];
        let timestamps = self.timer.render_scope(PhaseName::Gbuffer, "GBuffer::pass");
        let mut pass =
            begin_scene_pass(encoder, "GBuffer::pass", colors, &targets.depth_buffer.view, timestamps, (&textured, &bind_group), scene);
        for draw in &scene.draws {
            let material = draw.material as usize;
            pass.set_pipeline(if scene.textured[material] { &textured } else { &untextured });
            pass.set_bind_group(1, &scene.material_bind_groups[material], &[]);
            pass.draw_indexed(draw.first_index..draw.first_index + draw.index_count, 0, 0..1);
        }
    }

    fn screen_pipeline(
        &mut self,
        name: &'static str,
        shader: &'static str,
        io_layout: &wgpu::BindGroupLayout,
    ) -> Arc<wgpu::ComputePipeline> {
        let device = &self.gpu.device;
        let inputs_layout = &self.layouts.inputs;
        self.pipelines.compute(PipelineKey::compute(name, (shader, "main"), &[]), || {
            screen_compute_pipeline(device, inputs_layout, name, (shader, "main"), io_layout, &[])
        })
    }

    /// E0 (`shaders/e0/`). Under a light of more than `E0_EXACT_CELLS` cells: the exact
    /// sum at the corners of `E0_BLOCK`-pixel blocks; per block, the interpolation's error at
    /// its centre, and each of its pixels interpolated where the error estimate allows and
    /// listed otherwise (a pixel that sees every cell of the light below its horizon takes 0,
    /// its exact sum, and is not listed); then the listed pixels summed exactly, those that
    /// see every cell above their horizon without clipping (two indirect dispatches sized on
    /// the GPU).
    /// Otherwise (or with `E0Mode::Exact`) the exact sum everywhere, in one pass.
    ///
    /// Returns, where the interpolation ran, a buffer that will hold the two lists' counts:
    /// the pixels the interpolation refused, which the frame reports as the counter
    /// `e0_pixels_summed_exactly` (what E0 cost; `penumbra bench` reports the share it kept).
    pub(super) fn record_e0(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &FrameInputs,
        targets: &FrameTargets,
        spec: &FrameSpec,
        scratch: &mut Scratch,
    ) -> Option<wgpu::Buffer> {
        let io_layout = self.layouts.e0_output.clone();
        let device = &self.gpu.device;
        let inputs_layout = &self.layouts.inputs;
        let grid = spec.full_grid();
        let constants = [spec.acute_edges_constant(), ("GRID", f64::from(u8::from(grid)))];
        let mut entry = |name: &'static str, entry: &'static str| {
            // Each entry point's file (`shaders/e0/`).
            let file = match entry {
                "block_corners" => "e0/corners.wgsl",
                "interpolate_blocks" => "e0/interpolate.wgsl",
                _ => "e0/exact.wgsl",
            };
            self.pipelines.compute(PipelineKey::compute(name, (file, entry), &constants), || {
                screen_compute_pipeline(device, inputs_layout, name, (file, entry), &io_layout, &constants)
            })
        };
        let interpolate = self.e0_mode == E0Mode::Interpolated && spec.cells.len() > E0_EXACT_CELLS;
        let corners = if interpolate { (spec.width - 1) / E0_BLOCK + 2 } else { 1 };
        let rows = if interpolate { (spec.height - 1) / E0_BLOCK + 2 } else { 1 };
        let pixels = if interpolate { u64::from(spec.width) * u64::from(spec.height) } else { 0 };
        let buffer = |label, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE | usage,
                mapped_at_creation: false,
            })
        };
        // From the pool: every corner the interpolation reads is written first.
        let corner_bytes = u64::from(corners * rows) * E0_CORNER_BYTES;
        let records = scratch.buffer(
            &mut self.buffers,
            device,
            BufferKey { label: "E0::corners", size: corner_bytes, usage: wgpu::BufferUsages::STORAGE },
        );
        // The pixels summed exactly, by whether they see every cell above their horizon (at
        // most every pixel).
        let above = PixelListBuffers::new(&mut self.buffers, scratch, device, encoder, ("E0::above", pixels, 4));
        let clipped = PixelListBuffers::new(&mut self.buffers, scratch, device, encoder, ("E0::clipped", pixels, 4));
        let bind = |above_groups: &wgpu::Buffer, clipped_groups: &wgpu::Buffer| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("E0::outputs"),
                layout: &io_layout,
                entries: &layout::entries(&[
                    targets.e0.buffer.as_entire_binding(),
                    records.as_entire_binding(),
                    above.list.as_entire_binding(),
                    above_groups.as_entire_binding(),
                    clipped.list.as_entire_binding(),
                    clipped_groups.as_entire_binding(),
                ]),
            })
        };
        let (io, listed_io) = (bind(&above.groups, &clipped.groups), bind(&above.stand_in, &clipped.stand_in));
        let mut pass = self.timer.begin_compute_pass(encoder, PhaseName::E0, "e0");
        pass.set_bind_group(0, &inputs.bind_group, &[]);
        pass.set_bind_group(1, &io, &[]);
        if !interpolate {
            pass.set_pipeline(&entry("e0_exact", "exact"));
            // 8×8 invocations of 2×2 pixels each.
            pass.dispatch_workgroups(spec.width.div_ceil(16), spec.height.div_ceil(16), 1);
            return None;
        }
        let steps = [
            ("e0_corners", "block_corners", (corners.div_ceil(8), rows.div_ceil(8))),
            // One invocation per block, 64 blocks of a row per workgroup.
            ("e0_interpolate", "interpolate_blocks", ((corners - 1).div_ceil(64), rows - 1)),
            ("e0_exact_sizes", "exact_sizes", (1, 1)),
        ];
        for (name, entry_point, (x, y)) in steps {
            pass.set_pipeline(&entry(name, entry_point));
            pass.dispatch_workgroups(x, y, 1);
            self.timer.mark(&mut pass, name);
        }
        pass.set_bind_group(1, &listed_io, &[]);
        for (name, entry_point, list) in [("e0_exact_above", "exact_above", &above), ("e0_exact_clipped", "exact_clipped", &clipped)] {
            pass.set_pipeline(&entry(name, entry_point));
            list.walk(&mut pass, &mut self.timer, name);
        }
        drop(pass);
        // Each list's count is its first word.
        let counts = buffer("E0::listed", 8, wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC);
        encoder.copy_buffer_to_buffer(&above.list, 0, &counts, 0, 4);
        encoder.copy_buffer_to_buffer(&clipped.list, 0, &counts, 4, 4);
        Some(counts)
    }

    /// The composite: linear colour and depth (`main`), or the PNG's 8-bit sRGB pixels into
    /// `srgb8` (`srgb8`) when only those are read back.
    pub(super) fn record_composite(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &FrameInputs,
        targets: &FrameTargets,
        spec: &FrameSpec,
        srgb8: Option<&wgpu::Buffer>,
    ) {
        let io_layout = self.layouts.composite_io.clone();
        let pipeline = match srgb8 {
            None => self.screen_pipeline("composite", "composite.wgsl", &io_layout),
            Some(_) => {
                let (device, inputs_layout) = (&self.gpu.device, &self.layouts.inputs);
                self.pipelines.compute(PipelineKey::compute("composite_srgb8", ("composite.wgsl", "srgb8"), &[]), || {
                    screen_compute_pipeline(device, inputs_layout, "composite_srgb8", ("composite.wgsl", "srgb8"), &io_layout, &[])
                })
            }
        };
        let unused = srgb8.is_none().then(|| {
            self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Composite::unused_srgb8"),
                size: 4,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        });
        let io = self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Composite::io"),
            layout: &io_layout,
            entries: &layout::entries(&[
                targets.e0.buffer.as_entire_binding(),
                targets.visibility.buffer.as_entire_binding(),
                targets.color.buffer.as_entire_binding(),
                targets.depth.buffer.as_entire_binding(),
                srgb8.or(unused.as_ref()).expect("one of the two").as_entire_binding(),
            ]),
        });
        self.dispatch(encoder, PhaseName::Composite, &pipeline, inputs, &io, spec);
    }

    fn dispatch(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        phase: PhaseName,
        pipeline: &wgpu::ComputePipeline,
        inputs: &FrameInputs,
        io: &wgpu::BindGroup,
        spec: &FrameSpec,
    ) {
        let mut pass = self.timer.begin_compute_pass(encoder, phase, phase.as_str());
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &inputs.bind_group, &[]);
        pass.set_bind_group(1, io, &[]);
        pass.dispatch_workgroups(spec.width.div_ceil(8), spec.height.div_ceil(8), 1);
    }
}

/// A compute pipeline over the screen (8×8 workgroups) of `shader`'s `entry`, with values for
/// its pipeline-overridable constants: group 0 is the frame inputs
/// (`shaders/common/frame_inputs.wgsl`), group 1 the pass's own bindings.
pub fn screen_compute_pipeline(
    device: &wgpu::Device,
    inputs_layout: &wgpu::BindGroupLayout,
    label: &'static str,
    (shader, entry): (&str, &str),
    io_layout: &wgpu::BindGroupLayout,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    shaders::compute_pipeline(device, label, (shader, entry), &[inputs_layout, io_layout], constants)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_e0_block_matches_its_wgsl_mirror() {
        crate::gpu::shaders::assert_declares("e0/common.wgsl", &format!("const BLOCK: u32 = {}u;", super::E0_BLOCK));
    }
}
