//! Scenes: triangle meshes with per-object ids and Lambertian albedo (contract §1), from
//! glTF 2.0 files or built-in generators, each with a default camera and light.
//!
//! A `Scene` is CPU data in the layout the GPU draws (one vertex buffer, one index buffer,
//! draw ranges grouped by material); `gpu::GpuScene` uploads it once and keeps it warm.

pub mod adjacency;
pub mod builtin;
pub mod gltf;

use glam::{Mat3, Mat4, Vec2, Vec3};

use crate::job::AssetRef;

/// One vertex as the G-buffer and shadow-map passes read it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub uv: [f32; 2],
    pub object_id: u32,
    pub material: u32,
}

/// Lambertian material: albedo = `base_color` × texture (sRGB decoded to linear on the GPU).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub base_color: [f32; 4],
    pub texture: Option<usize>,
}

/// An 8-bit sRGB RGBA texture.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureData {
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
}

/// Indices `first..first + count` all use one material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawRange {
    pub material: u32,
    pub first_index: u32,
    pub index_count: u32,
}

/// The view and light a scene is shown with when a job does not say otherwise.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneDefaults {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub fov_y_deg: f32,
    pub light_center: Vec3,
    pub light_direction: Vec3,
    pub light_up: Vec3,
    pub light_size_m: Vec2,
    pub light_intensity: f32,
    pub light_image: AssetRef,
}

/// A loaded scene, ready for upload.
#[derive(Debug, Clone)]
pub struct Scene {
    pub vertices: Vec<Vertex>,
    pub indices: Vec<u32>,
    pub materials: Vec<Material>,
    pub textures: Vec<TextureData>,
    pub draws: Vec<DrawRange>,
    /// Object names, indexed by object id.
    pub objects: Vec<String>,
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    pub defaults: SceneDefaults,
}

impl Scene {
    pub fn triangle_count(&self) -> u64 {
        self.indices.len() as u64 / 3
    }

    pub fn center(&self) -> Vec3 {
        (self.bounds_min + self.bounds_max) * 0.5
    }

    pub fn radius(&self) -> f32 {
        ((self.bounds_max - self.bounds_min) * 0.5).length().max(1e-3)
    }

    /// Bytes this scene occupies once uploaded (vertices, indices, textures).
    pub fn gpu_bytes(&self) -> u64 {
        (self.vertices.len() * std::mem::size_of::<Vertex>()
            + self.indices.len() * 4
            + self.textures.iter().map(|t| t.rgba8.len()).sum::<usize>()) as u64
    }
}

/// Triangle geometry in object space, before it becomes part of a scene.
#[derive(Debug, Clone, Default)]
pub struct MeshData {
    pub positions: Vec<Vec3>,
    /// One per position, or empty to get flat face normals.
    pub normals: Vec<Vec3>,
    /// One per position, or empty.
    pub uvs: Vec<Vec2>,
    pub indices: Vec<u32>,
}

impl MeshData {
    /// Replaces the indexed mesh by unshared vertices with face normals (what a mesh without
    /// normals gets: flat shading, as glTF 2.0 §3.7.2.1 asks).
    fn with_flat_normals(&self) -> MeshData {
        let mut out = MeshData::default();
        for tri in self.indices.chunks_exact(3) {
            let p = [0, 1, 2].map(|k| self.positions[tri[k] as usize]);
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            for k in 0..3 {
                out.indices.push(out.positions.len() as u32);
                out.positions.push(p[k]);
                out.normals.push(n);
                if !self.uvs.is_empty() {
                    out.uvs.push(self.uvs[tri[k] as usize]);
                }
            }
        }
        out
    }
}

/// Accumulates objects into one `Scene`; object ids are assigned in insertion order.
pub struct SceneBuilder {
    objects: Vec<String>,
    materials: Vec<Material>,
    textures: Vec<TextureData>,
    // Per material: vertices are shared in one buffer, indices grouped for draw ranges.
    vertices: Vec<Vertex>,
    indices_by_material: Vec<Vec<u32>>,
    bounds_min: Vec3,
    bounds_max: Vec3,
}

impl Default for SceneBuilder {
    fn default() -> Self {
        Self {
            objects: Vec::new(),
            materials: Vec::new(),
            textures: Vec::new(),
            vertices: Vec::new(),
            indices_by_material: Vec::new(),
            bounds_min: Vec3::splat(f32::INFINITY),
            bounds_max: Vec3::splat(f32::NEG_INFINITY),
        }
    }
}

impl SceneBuilder {
    pub fn add_texture(&mut self, texture: TextureData) -> usize {
        self.textures.push(texture);
        self.textures.len() - 1
    }

    pub fn add_material(&mut self, material: Material) -> u32 {
        self.materials.push(material);
        self.indices_by_material.push(Vec::new());
        (self.materials.len() - 1) as u32
    }

    /// A plain material with a linear albedo colour.
    pub fn color(&mut self, rgb: [f32; 3]) -> u32 {
        self.add_material(Material { base_color: [rgb[0], rgb[1], rgb[2], 1.0], texture: None })
    }

    /// Starts a new object and returns its id.
    pub fn begin_object(&mut self, name: impl Into<String>) -> u32 {
        self.objects.push(name.into());
        (self.objects.len() - 1) as u32
    }

    /// Adds geometry to object `object_id`, transformed to world space.
    pub fn add_mesh(&mut self, object_id: u32, mesh: &MeshData, transform: Mat4, material: u32) {
        let flat;
        let mesh = if mesh.normals.len() != mesh.positions.len() {
            flat = mesh.with_flat_normals();
            &flat
        } else {
            mesh
        };
        let normal_matrix = Mat3::from_mat4(transform).inverse().transpose();
        // A mirroring transform flips the winding; normals stay as authored.
        let base = self.vertices.len() as u32;
        for (k, p) in mesh.positions.iter().enumerate() {
            let world = transform.transform_point3(*p);
            self.bounds_min = self.bounds_min.min(world);
            self.bounds_max = self.bounds_max.max(world);
            let normal = (normal_matrix * mesh.normals[k]).normalize_or_zero();
            self.vertices.push(Vertex {
                position: world.to_array(),
                normal: normal.to_array(),
                uv: mesh.uvs.get(k).copied().unwrap_or(Vec2::ZERO).to_array(),
                object_id,
                material,
            });
        }
        let out = &mut self.indices_by_material[material as usize];
        out.extend(mesh.indices.iter().map(|i| base + i));
    }

    pub fn triangle_count(&self) -> u64 {
        self.indices_by_material.iter().map(|i| i.len() as u64 / 3).sum()
    }

    pub fn finish(self, defaults: impl FnOnce(Vec3, Vec3) -> SceneDefaults) -> Scene {
        let (bounds_min, bounds_max) = if self.vertices.is_empty() { (Vec3::ZERO, Vec3::ZERO) } else { (self.bounds_min, self.bounds_max) };
        let mut indices = Vec::new();
        let mut draws = Vec::new();
        for (material, list) in self.indices_by_material.into_iter().enumerate() {
            if list.is_empty() {
                continue;
            }
            draws.push(DrawRange { material: material as u32, first_index: indices.len() as u32, index_count: list.len() as u32 });
            indices.extend(list);
        }
        Scene {
            vertices: self.vertices,
            indices,
            materials: self.materials,
            textures: self.textures,
            draws,
            objects: self.objects,
            bounds_min,
            bounds_max,
            defaults: defaults(bounds_min, bounds_max),
        }
    }
}

/// A default view of any scene from its bounds: from the front and above, the light above.
pub fn fitted_defaults(min: Vec3, max: Vec3) -> SceneDefaults {
    let center = (min + max) * 0.5;
    let radius = ((max - min) * 0.5).length().max(1e-3);
    SceneDefaults {
        eye: center + Vec3::new(0.0, 0.8, 1.6).normalize() * radius * 2.4,
        target: center,
        up: Vec3::Y,
        fov_y_deg: 45.0,
        light_center: center + Vec3::new(0.3, 2.0, 0.4) * radius,
        light_direction: -Vec3::Y,
        light_up: -Vec3::Z,
        light_size_m: Vec2::splat(radius * 0.25),
        // Radiance; A/d² is scale-free, so this gives the floor an irradiance near 2.
        light_intensity: 150.0,
        light_image: AssetRef::builtin("white"),
    }
}
