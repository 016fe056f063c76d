//! The frame's group 0, which every screen-space pass binds: the constants of the frame
//! (camera, light frame, sizes: `Frame` in `shaders/common/frame.wgsl`), the light's cells,
//! and the G-buffer and shadow-map targets (`shaders/common/frame_inputs.wgsl`).

use glam::Vec3;

use super::targets::FrameTargets;
use super::{FrameSpec, LightProjection, Renderer};
use crate::gpu::layout;
use crate::light::{cells_bounds, AreaLight, LightCell};

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
    cells_bounds: [f32; 4],
}

/// A light cell as `LightCell` in `shaders/common/light.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct LightCellGpu {
    rect: [f32; 4],
    radiance: [f32; 4],
}

/// Group 0 of every screen-space pass (`shaders/common/frame_inputs.wgsl`).
pub struct FrameInputs {
    pub layout: wgpu::BindGroupLayout,
    pub bind_group: wgpu::BindGroup,
}

impl Renderer {
    pub(super) fn write_constants(&self, spec: &FrameSpec, projection: &LightProjection) {
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
            ambient: v4(spec.ambient, spec.exposure.exp2()),
            sizes: [spec.width, spec.height, spec.shadow_resolution, spec.cells.len() as u32],
            cells_bounds: cells_bounds(light, &spec.cells),
        };
        self.gpu.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        let cells: Vec<LightCellGpu> = spec.cells.iter().map(|cell| cell_to_gpu(light, cell)).collect();
        if !cells.is_empty() {
            self.gpu.queue.write_buffer(&self.cells, 0, bytemuck::cast_slice(&cells));
        }
    }

    pub(super) fn frame_inputs(&self, targets: &FrameTargets) -> FrameInputs {
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
                view(&targets.shading.view),
            ]),
        });
        FrameInputs { layout: self.layouts.inputs.clone(), bind_group }
    }
}

fn cell_to_gpu(light: &AreaLight, cell: &LightCell) -> LightCellGpu {
    // Corners 0 (bottom-left) and 2 (top-right) in the light's frame (`LightCell` in
    // `shaders/common/light.wgsl`).
    let [lo, _, hi, _] = cell.corners.map(|c| light.plane_point(c));
    LightCellGpu { rect: [lo.x, hi.x, lo.y, hi.y], radiance: [cell.radiance.x, cell.radiance.y, cell.radiance.z, 0.0] }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_frame_constants_match_their_wgsl() {
        crate::gpu::shaders::assert_wgsl_layout!(
            FrameUniforms,
            "common/frame.wgsl",
            "Frame",
            [view_proj, light_view_proj, eye, view_dir, light_center, light_n, light_u, light_r, light_proj, ambient, sizes, cells_bounds]
        );
        crate::gpu::shaders::assert_wgsl_layout!(LightCellGpu, "common/light.wgsl", "LightCell", [rect, radiance]);
    }
}
