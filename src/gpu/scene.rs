//! A scene uploaded to the GPU once and kept warm: vertex and index buffers, material
//! colours, and one bind group per material with its base-colour texture; the triangles also
//! stay on the CPU for object-space methods, with their adjacency built on first use.

use std::ops::Range;

use glam::Vec3;
use wgpu::util::DeviceExt;

use super::GpuContext;
use crate::light::AreaLight;
use crate::scene::adjacency::{Casting, EdgeMesh};
use crate::scene::bounding::BoundingTriangles;
use crate::scene::{box_corners, DrawRange, Extent, OnFloor, Scene, SceneDefaults};

/// Runs of the index buffer, three indices a triangle.
pub type Runs = std::sync::Arc<[Range<u32>]>;

/// A material's constant part as the G-buffer shader reads it.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct MaterialGpu {
    base_color: [f32; 4],
}

pub struct GpuScene {
    pub vertex_buffer: wgpu::Buffer,
    pub index_buffer: wgpu::Buffer,
    pub index_count: u32,
    pub materials: wgpu::Buffer,
    /// Group 1 of the G-buffer pass, one per material: base-colour texture and sampler.
    pub material_bind_groups: Vec<wgpu::BindGroup>,
    /// Per material, whether it samples a texture of its own (else the 1×1 white one is bound
    /// and the G-buffer pass draws it without sampling).
    pub textured: Vec<bool>,
    pub draws: Vec<DrawRange>,
    pub triangles: u64,
    pub textures: u64,
    pub object_count: u32,
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    pub defaults: SceneDefaults,
    /// `Scene::warnings`: reported with every frame of this scene.
    pub warnings: Vec<String>,
    /// `Scene::on_floor`: what `shadow_fit_points` frames instead of the whole floor.
    pub on_floor: Option<OnFloor>,
    /// Bytes uploaded for this scene (buffers and textures).
    pub bytes: u64,
    /// The triangles on the CPU as well, for object-space methods (`wedges`).
    positions: Vec<Vec3>,
    vertex_objects: Vec<u32>,
    indices: Vec<u32>,
    /// Adjacency, built on first use and kept with the scene.
    edge_mesh: std::sync::OnceLock<std::sync::Arc<EdgeMesh>>,
    /// The triangles casting from the last point asked (`casting_from`): the jobs that follow
    /// one another on a scene mostly share their light.
    casting: std::sync::Mutex<Option<([u32; 3], std::sync::Arc<Casting>)>>,
    /// The triangles with the whole scene on one side (`BoundingTriangles`), found on first use.
    bounding: std::sync::OnceLock<BoundingTriangles>,
    /// The runs of triangles that can shadow from the last light asked (`casting_runs`).
    casting_runs: std::sync::Mutex<Option<([u32; 12], Runs)>>,
}

impl GpuScene {
    /// Uploads `scene`. `material_layout` is the G-buffer pass's group-1 layout.
    ///
    /// A scene within the operator's limits can still exceed this device's (a texture wider
    /// than it allows, memory it does not have): the error is caught here, so the scene fails
    /// its own job and is never cached, instead of an invalid scene failing later jobs.
    pub fn upload(gpu: &GpuContext, scene: &Scene, material_layout: &wgpu::BindGroupLayout) -> Result<Self, wgpu::Error> {
        let out_of_memory = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let uploaded = Self::upload_unchecked(gpu, scene, material_layout);
        let errors = [pollster::block_on(validation.pop()), pollster::block_on(out_of_memory.pop())];
        match errors.into_iter().flatten().next() {
            Some(error) => Err(error),
            None => Ok(uploaded),
        }
    }

    fn upload_unchecked(gpu: &GpuContext, scene: &Scene, material_layout: &wgpu::BindGroupLayout) -> Self {
        let device = &gpu.device;
        let vertex_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("GpuScene::vertex_buffer"),
            contents: bytemuck::cast_slice(&scene.vertices),
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE,
        });
        let index_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("GpuScene::index_buffer"),
            contents: bytemuck::cast_slice(&scene.indices),
            usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::STORAGE,
        });
        let mut material_data: Vec<MaterialGpu> = scene.materials.iter().map(|m| MaterialGpu { base_color: m.base_color }).collect();
        if material_data.is_empty() {
            material_data.push(MaterialGpu { base_color: [1.0; 4] });
        }
        let materials = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("GpuScene::materials"),
            contents: bytemuck::cast_slice(&material_data),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let (material_bind_groups, textured) = material_bind_groups(gpu, scene, material_layout);
        Self {
            vertex_buffer,
            index_buffer,
            index_count: scene.indices.len() as u32,
            materials,
            material_bind_groups,
            textured,
            draws: scene.draws.clone(),
            triangles: scene.triangle_count(),
            textures: scene.textures.len() as u64,
            object_count: scene.objects.len() as u32,
            bounds_min: scene.bounds_min,
            bounds_max: scene.bounds_max,
            defaults: scene.defaults.clone(),
            warnings: scene.warnings.clone(),
            on_floor: scene.on_floor,
            bytes: scene.gpu_bytes(),
            positions: scene.vertices.iter().map(|v| Vec3::from(v.position)).collect(),
            vertex_objects: scene.vertices.iter().map(|v| v.object_id).collect(),
            indices: scene.indices.clone(),
            edge_mesh: Default::default(),
            casting: Default::default(),
            bounding: Default::default(),
            casting_runs: Default::default(),
        }
    }

    pub fn center(&self) -> Vec3 {
        (self.bounds_min + self.bounds_max) * 0.5
    }

    /// The scene's adjacency (welded vertices, edges with their triangles), built on first use.
    pub fn edge_mesh(&self) -> std::sync::Arc<EdgeMesh> {
        self.edge_mesh.get_or_init(|| std::sync::Arc::new(EdgeMesh::build(&self.positions, &self.indices, &self.vertex_objects))).clone()
    }

    /// Which triangles cast from `point` (`EdgeMesh::casting`), kept for the next job from the
    /// same point.
    pub fn casting_from(&self, point: Vec3) -> std::sync::Arc<Casting> {
        let key = point.to_array().map(f32::to_bits);
        let mut last = self.casting.lock().unwrap_or_else(|p| p.into_inner());
        match &*last {
            Some((at, casting)) if *at == key => casting.clone(),
            _ => {
                let casting = std::sync::Arc::new(self.edge_mesh().casting(point));
                *last = Some((key, casting.clone()));
                casting
            }
        }
    }

    /// The runs of the index buffer (three indices a triangle) whose triangles can shadow some
    /// point of the scene from `light`: all but the bounding triangles it lies beyond
    /// (`BoundingTriangles::casting_runs`), which the sample maps of `reference` and
    /// `filtered` leave out. Kept for the next job under the same light.
    pub fn casting_runs(&self, light: &AreaLight) -> Runs {
        let corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)].map(|(s, t)| light.image_point(s, t));
        let mut key = [0; 12];
        for (k, c) in corners.iter().enumerate() {
            key[3 * k..3 * k + 3].copy_from_slice(&c.to_array().map(f32::to_bits));
        }
        let mut last = self.casting_runs.lock().unwrap_or_else(|p| p.into_inner());
        match &*last {
            Some((at, runs)) if *at == key => runs.clone(),
            _ => {
                let bounding = self.bounding.get_or_init(|| BoundingTriangles::find(&self.positions, &self.indices));
                let runs: Runs = bounding.casting_runs(&corners).into();
                *last = Some((key, runs.clone()));
                runs
            }
        }
    }

    /// Every vertex's position, as the vertex buffer holds them.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The triangles' vertex indices, three a triangle.
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// Where the scene lies: its bounds and what stands on its floor.
    pub fn extent(&self) -> Extent {
        Extent { bounds_min: self.bounds_min, bounds_max: self.bounds_max, on_floor: self.on_floor }
    }

    /// The eight corners of the scene's bounding box.
    pub fn corners(&self) -> [Vec3; 8] {
        self.extent().corners()
    }

    /// `shadow_fit_points` of this scene.
    pub fn shadow_fit_points(&self, light: &AreaLight) -> Vec<Vec3> {
        shadow_fit_points(&self.extent(), light)
    }
}

/// The points a shadow map's frustum from `light` must hold (`LightProjection::fit`) for a
/// scene lying in `extent`: its bounds, or, on a floor added under the scene (contract §3),
/// what stands on it and the part of the floor it can shadow from some point of the light —
/// the corners of its bounds cast from the light's corners and centre onto the floor. The
/// floor reaches well past the scene; the rest of it is lit whichever way (every method takes
/// a point outside the frustum as lit), and framing it all would spread the map's texels
/// thin. A light not above everything on the floor gets the whole bounds.
pub fn shadow_fit_points(extent: &Extent, light: &AreaLight) -> Vec<Vec3> {
    let Some(on_floor) = extent.on_floor else { return extent.corners().to_vec() };
    let standing = box_corners(on_floor.bounds_min, on_floor.bounds_max);
    // The light's corners and centre.
    let light_points = [(0.0, 1.0), (1.0, 1.0), (0.0, 0.0), (1.0, 0.0), (0.5, 0.5)].map(|(s, t)| light.image_point(s, t));
    let mut points = standing.to_vec();
    for from in light_points {
        for corner in standing {
            if from.y <= corner.y + 1e-6 * (1.0 + corner.y.abs()) {
                return extent.corners().to_vec();
            }
            let cast = from + (corner - from) * ((from.y - on_floor.height) / (from.y - corner.y));
            points.push(cast.clamp(extent.bounds_min, extent.bounds_max));
        }
    }
    points
}

/// Each material's bind group (its texture, or a white texel, and the scene's sampler) and
/// whether it has a texture: the scene's textures uploaded once, shared by their materials.
fn material_bind_groups(gpu: &GpuContext, scene: &Scene, material_layout: &wgpu::BindGroupLayout) -> (Vec<wgpu::BindGroup>, Vec<bool>) {
    let device = &gpu.device;
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("GpuScene::sampler"),
        address_mode_u: wgpu::AddressMode::Repeat,
        address_mode_v: wgpu::AddressMode::Repeat,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    let upload_texture = |width: u32, height: u32, rgba8: &[u8]| {
        let texture = device.create_texture_with_data(
            &gpu.queue,
            &wgpu::TextureDescriptor {
                label: Some("GpuScene::texture"),
                size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                // sRGB storage: the sampler returns linear albedo (contract §1).
                format: wgpu::TextureFormat::Rgba8UnormSrgb,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            rgba8,
        );
        texture.create_view(&wgpu::TextureViewDescriptor::default())
    };
    let white = upload_texture(1, 1, &[255; 4]);
    let views: Vec<wgpu::TextureView> = scene.textures.iter().map(|t| upload_texture(t.width, t.height, &t.rgba8)).collect();
    scene
        .materials
        .iter()
        .map(|m| {
            let texture = m.texture.and_then(|t| views.get(t));
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("GpuScene::material_bind_group"),
                layout: material_layout,
                entries: &super::layout::entries(&[
                    wgpu::BindingResource::TextureView(texture.unwrap_or(&white)),
                    wgpu::BindingResource::Sampler(&sampler),
                ]),
            });
            (group, texture.is_some())
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_material_matches_its_wgsl() {
        crate::gpu::shaders::assert_wgsl_layout!(MaterialGpu, "gbuffer.wgsl", "Material", [base_color]);
    }
}
