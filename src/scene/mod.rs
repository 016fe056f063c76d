//! Scenes: triangle meshes with per-object ids and Lambertian albedo (contract §1), from
//! glTF 2.0 files or built-in generators, each with a default camera and light.
//!
//! A `Scene` is CPU data in the layout the GPU draws (one vertex buffer, one index buffer,
//! draw ranges grouped by material); `gpu::GpuScene` uploads it once and keeps it warm.

pub mod adjacency;
pub mod bounding;
pub mod builtin;
pub mod gltf;

use glam::{Mat3, Mat4, Vec2, Vec3};

use crate::job::{AssetRef, FloorSpec};

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
    /// What penumbra left out of the file or repaired in it, for the client to read in the
    /// job's answer (contract §3: never silently).
    pub warnings: Vec<String>,
    /// With a floor (`with_floor`): the bounds of what stands on it, and the floor's height.
    pub on_floor: Option<OnFloor>,
}

/// What stands on a floor added under a scene: only it casts shadows on the floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnFloor {
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    pub height: f32,
}

/// Where a scene lies: its bounds and, on a floor, what stands on it — what framing a camera
/// and a shadow map needs (`gpu::scene::shadow_fit_points`), without the triangles
/// (`Scene::extent`, `GpuScene::extent`): an estimate predicts a reference's crop from it
/// before the scene is uploaded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    pub on_floor: Option<OnFloor>,
}

impl Extent {
    /// This extent with a floor under it (`Scene::with_floor`): the floor's square joins the
    /// bounds, and what stood there is what stands on the floor.
    pub fn with_floor(&self, floor: &FloorSpec) -> Extent {
        let (min, max) = (self.bounds_min, self.bounds_max);
        let ((x0, z0), (x1, z1), y) = self.floor_square(floor);
        Extent {
            bounds_min: min.min(Vec3::new(x0, y, z0)),
            bounds_max: max.max(Vec3::new(x1, y, z1)),
            on_floor: Some(OnFloor { bounds_min: min, bounds_max: max, height: y }),
        }
    }

    /// The floor's corners in x and z and its height: centred under the bounds, `margin`
    /// bounding radii past them, a hair below their lowest point.
    fn floor_square(&self, floor: &FloorSpec) -> ((f32, f32), (f32, f32), f32) {
        let (min, max, radius) = (self.bounds_min, self.bounds_max, self.radius());
        let reach = floor.margin * radius;
        ((min.x - reach, min.z - reach), (max.x + reach, max.z + reach), min.y - 1e-3 * radius)
    }

    /// Half the bounding box's diagonal (at least a millimetre).
    pub fn radius(&self) -> f32 {
        ((self.bounds_max - self.bounds_min) * 0.5).length().max(1e-3)
    }

    /// The eight corners of the bounding box.
    pub fn corners(&self) -> [Vec3; 8] {
        box_corners(self.bounds_min, self.bounds_max)
    }
}

/// What predicting a job needs of its scene, without its triangles (`Engine::scene_shape`):
/// how many there are, where the scene lies and the view it is shown with by default.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// The floor's two included.
    pub triangles: u64,
    pub extent: Extent,
    pub defaults: SceneDefaults,
}

impl Shape {
    /// This shape with `floor` under it, if one is added (`Scene::with_floor`).
    pub fn on(mut self, floor: Option<&FloorSpec>) -> Shape {
        if let Some(floor) = floor {
            self.triangles += 2;
            self.extent = self.extent.with_floor(floor);
        }
        self
    }
}

/// The eight corners of the box [a, b], corner k taking b's coordinate where bit 0 (x), 1 (y)
/// or 2 (z) of k is set.
pub fn box_corners(a: Vec3, b: Vec3) -> [Vec3; 8] {
    [0, 1, 2, 3, 4, 5, 6, 7]
        .map(|k| Vec3::new(if k & 1 == 0 { a.x } else { b.x }, if k & 2 == 0 { a.y } else { b.y }, if k & 4 == 0 { a.z } else { b.z }))
}

impl Scene {
    pub fn triangle_count(&self) -> u64 {
        self.indices.len() as u64 / 3
    }

    pub fn center(&self) -> Vec3 {
        (self.bounds_min + self.bounds_max) * 0.5
    }

    pub fn radius(&self) -> f32 {
        self.extent(None).radius()
    }

    /// This scene with a floor under it (contract §3): a square at the bounds' lowest height
    /// (a hair below it, so that a face resting there does not fight the floor in depth),
    /// centred under the bounds and reaching `margin` bounding radii past them on every side.
    /// It is one more object, `floor`, with its own material; the defaults stay as they were
    /// (`fitted_defaults` already frames the shadow on it).
    pub fn with_floor(&self, floor: &FloorSpec) -> Scene {
        let mut out = self.clone();
        let ((x0, z0), (x1, z1), y) = self.extent(None).floor_square(floor);
        let object_id = out.objects.len() as u32;
        out.objects.push("floor".into());
        let material = out.materials.len() as u32;
        let [r, g, b] = floor.albedo;
        out.materials.push(Material { base_color: [r, g, b, 1.0], texture: None });
        let base = out.vertices.len() as u32;
        for (x, z, u, v) in [(x0, z0, 0.0, 0.0), (x0, z1, 0.0, 1.0), (x1, z1, 1.0, 1.0), (x1, z0, 1.0, 0.0)] {
            out.vertices.push(Vertex { position: [x, y, z], normal: [0.0, 1.0, 0.0], uv: [u, v], object_id, material });
        }
        // Counter-clockwise seen from above (+y), glTF's front face.
        out.draws.push(DrawRange { material, first_index: out.indices.len() as u32, index_count: 6 });
        out.indices.extend([0, 1, 2, 0, 2, 3].map(|k| base + k));
        Extent { bounds_min: out.bounds_min, bounds_max: out.bounds_max, on_floor: out.on_floor } = self.extent(Some(floor));
        out
    }

    /// Where this scene lies, on `floor` if one is added (`with_floor`'s bounds, without
    /// copying the scene).
    pub fn extent(&self, floor: Option<&FloorSpec>) -> Extent {
        let extent = Extent { bounds_min: self.bounds_min, bounds_max: self.bounds_max, on_floor: self.on_floor };
        floor.map_or(extent, |floor| extent.with_floor(floor))
    }

    /// What predicting a job on this scene needs of it, on `floor` if one is added.
    pub fn shape(&self, floor: Option<&FloorSpec>) -> Shape {
        Shape { triangles: self.triangle_count(), extent: self.extent(None), defaults: self.defaults.clone() }.on(floor)
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
    /// One finite, non-zero normal per position.
    pub fn has_valid_normals(&self) -> bool {
        self.normals.len() == self.positions.len() && self.normals.iter().all(|n| n.is_finite() && n.length_squared() > 1e-12)
    }

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
    /// Meshes given normals that were zero or not finite (replaced by flat ones).
    repaired_normals: usize,
    warnings: Vec<String>,
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
            repaired_normals: 0,
            warnings: Vec::new(),
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

    /// Adds geometry to object `object_id`, transformed to world space. A mesh without a
    /// normal per vertex, or with any normal that is zero or not finite, gets flat face
    /// normals instead (glTF 2.0 §3.7.2.1; a viewer cannot light a zero normal).
    pub fn add_mesh(&mut self, object_id: u32, mesh: &MeshData, transform: Mat4, material: u32) {
        let flat;
        if !mesh.normals.is_empty() && !mesh.has_valid_normals() {
            self.repaired_normals += 1;
        }
        let mesh = if !mesh.has_valid_normals() {
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

    /// Records something the client should know about the scene (`Scene::warnings`).
    pub fn warn(&mut self, warning: impl Into<String>) {
        self.warnings.push(warning.into());
    }

    pub fn triangle_count(&self) -> u64 {
        self.indices_by_material.iter().map(|i| i.len() as u64 / 3).sum()
    }

    pub fn finish(mut self, defaults: impl FnOnce(Vec3, Vec3) -> SceneDefaults) -> Scene {
        if self.repaired_normals > 0 {
            let count = self.repaired_normals;
            self.warn(format!("{count} primitive(s) had normals that were zero or not finite: flat face normals were used instead"));
        }
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
            warnings: self.warnings,
            on_floor: None,
        }
    }
}

/// The view and light a scene from a file gets where a job names none (contract §3), fitted
/// to its bounds — centre c, bounding radius r — so that the scene and the shadow it casts on
/// a floor under it (`Scene::with_floor`) are both in view:
/// - the light, a 0.5 r square, sits 3 r from c towards (0.8, 1, 0.35) — above, to the right
///   and a little in front, 41° off the vertical — and faces c: the top and the front the
///   camera sees are lit, and the shadow falls to the left and a little behind, beside the
///   object as the camera sees it rather than hidden behind it;
/// - the camera looks from the front and above, along (0, 0.8, 1.6), at the centre of the
///   bounds joined with the shadow's footprint (the top corners of the bounds cast from the
///   light's centre onto the bounds' lowest height), from where the sphere around both fills
///   its 45° vertical field of view.
pub fn fitted_defaults(min: Vec3, max: Vec3) -> SceneDefaults {
    let center = (min + max) * 0.5;
    let radius = ((max - min) * 0.5).length().max(1e-3);
    let towards_light = Vec3::new(0.8, 1.0, 0.35).normalize();
    let light_center = center + towards_light * 3.0 * radius;
    let light_direction = -towards_light;
    // The image's up: the light's side away from the camera, kept square to its direction.
    let back = Vec3::NEG_Z;
    let light_up = (back - light_direction * back.dot(light_direction)).normalize();

    let (mut lo, mut hi) = (min, max);
    for corner in [(min.x, min.z), (min.x, max.z), (max.x, min.z), (max.x, max.z)] {
        let top = Vec3::new(corner.0, max.y, corner.1);
        // The light's centre is above every top corner (3 r · 0.75 > r), so the ray reaches
        // the floor's height beyond the corner.
        let t = (light_center.y - min.y) / (light_center.y - top.y).max(1e-6 * radius);
        let shadow = light_center + (top - light_center) * t;
        lo = lo.min(shadow);
        hi = hi.max(shadow);
    }
    let view_center = (lo + hi) * 0.5;
    let view_radius = ((hi - lo) * 0.5).length().max(1e-3);
    let fov_y_deg: f32 = 45.0;
    let distance = view_radius / (0.5 * fov_y_deg.to_radians()).sin();
    SceneDefaults {
        eye: view_center + Vec3::new(0.0, 0.8, 1.6).normalize() * distance,
        target: view_center,
        up: Vec3::Y,
        fov_y_deg,
        light_center,
        light_direction,
        light_up,
        light_size_m: Vec2::splat(0.5 * radius),
        // Radiance; the light's solid angle from c, A/d² = 0.25/9, is scale-free, so this
        // gives a floor under the scene an irradiance near 1.5 (2 × cos 41°).
        light_intensity: 72.0,
        light_image: AssetRef::builtin("white"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(normals: Vec<Vec3>) -> Scene {
        let positions: Vec<Vec3> = (0..8).map(|k| Vec3::new((k & 1) as f32, ((k >> 1) & 1) as f32 + 2.0, (k >> 2) as f32)).collect();
        let indices = vec![0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5];
        let mut builder = SceneBuilder::default();
        let object = builder.begin_object("cube");
        let material = builder.color([0.5; 3]);
        builder.add_mesh(object, &MeshData { positions, normals, uvs: Vec::new(), indices }, Mat4::IDENTITY, material);
        builder.finish(fitted_defaults)
    }

    #[test]
    fn zero_or_infinite_normals_are_replaced_by_face_normals() {
        let mut normals = vec![Vec3::Y; 8];
        normals[3] = Vec3::ZERO;
        let repaired = cube(normals.clone());
        normals[3] = Vec3::splat(f32::INFINITY);
        let (infinite, absent) = (cube(normals), cube(Vec::new()));
        // A repair is reported; normals the file left out are the spec's flat shading.
        assert!(repaired.warnings.len() == 1 && repaired.warnings[0].contains("flat face normals"), "{:?}", repaired.warnings);
        assert_eq!(infinite.warnings.len(), 1);
        assert!(absent.warnings.is_empty());
        for scene in [repaired, infinite, absent] {
            assert_eq!(scene.vertices.len(), 36, "flat: one vertex per corner of each triangle");
            for tri in scene.indices.chunks_exact(3) {
                let p = [0, 1, 2].map(|k| Vec3::from(scene.vertices[tri[k] as usize].position));
                let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
                for &i in tri {
                    assert!(Vec3::from(scene.vertices[i as usize].normal).distance(face) < 1e-6);
                }
            }
        }
    }

    #[test]
    fn a_floor_lies_under_the_bounds_facing_up_and_reaching_the_margin() {
        let scene = cube(Vec::new());
        let floor = FloorSpec { albedo: [0.2, 0.3, 0.4], margin: 1.5 };
        let staged = scene.with_floor(&floor);
        assert_eq!(staged.triangle_count(), scene.triangle_count() + 2);
        assert_eq!(staged.objects.last().map(String::as_str), Some("floor"));
        assert_eq!(staged.materials.last().map(|m| m.base_color), Some([0.2, 0.3, 0.4, 1.0]));
        let reach = 1.5 * scene.radius();
        assert!((staged.bounds_max.x - scene.bounds_max.x - reach).abs() < 1e-5);
        assert!((staged.bounds_min.z - scene.bounds_min.z + reach).abs() < 1e-5);
        assert!(staged.bounds_min.y < scene.bounds_min.y && staged.bounds_min.y > scene.bounds_min.y - 0.01);
        let draw = staged.draws.last().unwrap();
        let floor_indices = &staged.indices[draw.first_index as usize..][..draw.index_count as usize];
        for tri in floor_indices.chunks_exact(3) {
            let p = [0, 1, 2].map(|k| Vec3::from(staged.vertices[tri[k] as usize].position));
            // Wound counter-clockwise seen from above, as its normal says.
            assert!((p[1] - p[0]).cross(p[2] - p[0]).normalize().distance(Vec3::Y) < 1e-6);
        }
    }

    /// The staging rule: the object and its shadow's footprint are inside the fitted camera's
    /// view, and the fitted light is a valid frame that lights the faces the camera sees.
    #[test]
    fn the_fitted_camera_sees_the_object_and_the_shadow_the_fitted_light_casts() {
        for (min, max) in [(Vec3::new(0.0, 2.0, 0.0), Vec3::new(1.0, 3.0, 1.0)), (Vec3::new(-5.0, 0.0, -0.1), Vec3::new(5.0, 20.0, 0.1))] {
            let d = fitted_defaults(min, max);
            assert!((d.light_direction.length() - 1.0).abs() < 1e-5 && d.light_up.dot(d.light_direction).abs() < 1e-5);
            // Lights the side facing the camera (+z) and the top.
            assert!(d.light_direction.dot(Vec3::Z) < 0.0 && d.light_direction.dot(Vec3::Y) < 0.0);
            let view = Mat4::look_at_rh(d.eye, d.target, d.up);
            let half = (0.5 * d.fov_y_deg).to_radians().tan();
            let in_view = |p: Vec3| {
                let v = view.transform_point3(p);
                -v.z > 0.0 && v.y.abs() <= half * -v.z * 1.0001 && v.x.abs() <= half * -v.z * 1.0001
            };
            for k in 0..8 {
                let corner = Vec3::new([min.x, max.x][k & 1], [min.y, max.y][(k >> 1) & 1], [min.z, max.z][k >> 2]);
                assert!(in_view(corner), "{corner}");
                // Where the light's centre casts the corner onto the floor's height.
                let t = (d.light_center.y - min.y) / (d.light_center.y - corner.y).max(1e-6);
                assert!(in_view(d.light_center + (corner - d.light_center) * t), "shadow of {corner}");
            }
        }
    }
}
