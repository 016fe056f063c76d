//! glTF 2.0 loading (`.gltf`, with its resources embedded or beside it, and `.glb`) into a
//! `Scene`.
//!
//! Every node holding a mesh is one object; ids are the rank of the node's index among the
//! mesh nodes of the scene, so they are stable for a file (contract §1). An uploaded document
//! is read alone (`data:` URIs and the GLB binary chunk); one read from disk may name files
//! by relative URI, which are read from its folder and never from outside the directory the
//! server may read (contract §3). No document ever makes the loader open an absolute path,
//! a `file:` URI or a network address.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec2, Vec3};

use super::{fitted_defaults, Material, MeshData, Scene, SceneBuilder, TextureData};
use crate::error::{ErrorCode, JobError, JobResult};
use crate::job::Limits;

mod checks;
mod pack;
mod synthetic;
mod uris;

use checks::parse_document;
pub use pack::{glb, pack};
pub use synthetic::{height_field_glb, textured_height_field_glb};
pub use uris::files_named;
use uris::{read_buffers, UriReader};

/// Where the files a document names by URI may be read from (contract §3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resources<'a> {
    /// A self-contained document (an upload): `data:` URIs and the GLB binary chunk only.
    Embedded,
    /// A document read from disk: URIs relative to it are read from `folder`, its own
    /// folder; with `confined_to` (`serve --scene-dir`) never from outside that directory,
    /// symlinks resolved. Both paths are canonical.
    Beside { folder: &'a Path, confined_to: Option<&'a Path> },
}

/// Loads a self-contained glTF or GLB document from bytes. `field` names the job field for
/// errors.
pub fn load(bytes: &[u8], limits: &Limits, field: &str) -> JobResult<Scene> {
    load_from(bytes, limits, field, Resources::Embedded)
}

/// Loads a glTF or GLB document whose URIs are read as `resources` says.
pub fn load_from(bytes: &[u8], limits: &Limits, field: &str, resources: Resources<'_>) -> JobResult<Scene> {
    // The gltf crate validates indices into the document, but a hostile file is still
    // untrusted input: a panic anywhere in decoding becomes a clean error for this job.
    match std::panic::catch_unwind(|| {
        let uris = UriReader { resources, limits, field, read: std::cell::Cell::new(0) };
        load_unchecked(bytes, limits, field, &uris)
    }) {
        Ok(result) => result,
        Err(_) => Err(invalid(field, "the glTF document could not be decoded")),
    }
}

fn invalid(field: &str, message: impl Into<String>) -> JobError {
    JobError::field(ErrorCode::InvalidAsset, field, message)
}

fn load_unchecked(bytes: &[u8], limits: &Limits, field: &str, uris: &UriReader<'_>) -> JobResult<Scene> {
    let (gltf, repaired) = parse_document(bytes, field)?;
    let buffers = read_buffers(&gltf, limits, field, uris)?;
    let instances = mesh_instances(&gltf.document, field)?;
    // Object ids: each mesh node's rank among the scene's mesh nodes (by index).
    let mut mesh_nodes: Vec<usize> = instances.iter().map(|(n, _)| n.index()).collect();
    mesh_nodes.dedup();
    let id_of: HashMap<usize, u32> = mesh_nodes.iter().enumerate().map(|(id, &node)| (node, id as u32)).collect();

    let mut loader = Loader {
        builder: SceneBuilder::default(),
        limits,
        field,
        uris,
        buffers: &buffers,
        materials: BTreeMap::new(),
        textures: HashMap::new(),
        texture_bytes: 0,
        skipped_primitives: 0,
        untextured: Vec::new(),
        vertices: 0,
        declared_triangles: 0,
    };
    if let Some(repair) = repaired {
        loader.builder.warn(repair);
    }
    warn_of_what_is_ignored(&gltf.document, &mut loader.builder);
    for &node_index in &mesh_nodes {
        let node = gltf.document.nodes().nth(node_index).expect("index from this document");
        loader.builder.begin_object(node.name().map(str::to_owned).unwrap_or_else(|| format!("node-{node_index}")));
    }
    for (node, world) in &instances {
        let mesh = node.mesh().expect("mesh nodes only");
        for primitive in mesh.primitives() {
            loader.add_primitive(&primitive, mesh.index(), id_of[&node.index()], *world)?;
        }
    }
    loader.finish(instances.len())
}

/// The mesh nodes of the default scene (else the first, else every node) with their world
/// transforms, one entry per instance, sorted by node index.
fn mesh_instances<'d>(document: &'d gltf::Document, field: &str) -> JobResult<Vec<(gltf::Node<'d>, Mat4)>> {
    let scene = document.default_scene().or_else(|| document.scenes().next());
    let roots: Vec<gltf::Node> = match &scene {
        Some(scene) => scene.nodes().collect(),
        None => document.nodes().collect(),
    };
    let mut instances: Vec<(gltf::Node, Mat4)> = Vec::new();
    let mut stack: Vec<(gltf::Node, Mat4, u32)> = roots.into_iter().map(|n| (n, Mat4::IDENTITY, 0)).collect();
    while let Some((node, parent, depth)) = stack.pop() {
        if depth > 64 || instances.len() > 1_000_000 {
            return Err(invalid(field, "the node hierarchy is too deep or too large"));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if node.mesh().is_some() {
            instances.push((node.clone(), world));
        }
        for child in node.children() {
            stack.push((child, world, depth + 1));
        }
    }
    instances.sort_by_key(|(n, _)| n.index());
    Ok(instances)
}

/// The triangles of a primitive's index list (`flat`) in its mode; `None` for points and
/// lines, which cast no area shadow.
fn triangles(mode: gltf::mesh::Mode, flat: &[u32]) -> Option<Vec<u32>> {
    match mode {
        gltf::mesh::Mode::Triangles => Some(flat.chunks_exact(3).flatten().copied().collect()),
        gltf::mesh::Mode::TriangleStrip => Some(
            (2..flat.len())
                .flat_map(|k| if k % 2 == 0 { [flat[k - 2], flat[k - 1], flat[k]] } else { [flat[k - 1], flat[k - 2], flat[k]] })
                .collect(),
        ),
        gltf::mesh::Mode::TriangleFan => Some((2..flat.len()).flat_map(|k| [flat[0], flat[k - 1], flat[k]]).collect()),
        _ => None,
    }
}

/// A document's primitives going into a `SceneBuilder`, with what the limits count and what
/// the warnings report.
struct Loader<'a> {
    builder: SceneBuilder,
    limits: &'a Limits,
    field: &'a str,
    uris: &'a UriReader<'a>,
    buffers: &'a [Vec<u8>],
    /// The builder's material for each glTF material (`None`: the default one).
    materials: BTreeMap<Option<usize>, u32>,
    /// The builder's texture for each glTF image (`None`: skipped, and said so once).
    textures: HashMap<usize, Option<usize>>,
    /// What the textures decoded so far take (`max_texture_bytes`).
    texture_bytes: u64,
    skipped_primitives: usize,
    /// Meshes whose base-colour texture names coordinates they do not have.
    untextured: Vec<String>,
    vertices: u64,
    declared_triangles: u64,
}

impl Loader<'_> {
    /// Adds one primitive of mesh `mesh_index` as part of object `object_id`, placed by `world`.
    fn add_primitive(&mut self, primitive: &gltf::Primitive<'_>, mesh_index: usize, object_id: u32, world: Mat4) -> JobResult<()> {
        let (limits, field) = (self.limits, self.field);
        // Refused from the counts the accessors declare, before a vertex or index is read:
        // a strip of one-byte indices would otherwise grow twelvefold into triangles.
        let declared_vertices = primitive.get(&gltf::Semantic::Positions).map_or(0, |a| a.count() as u64);
        let declared_indices = primitive.indices().map_or(declared_vertices, |a| a.count() as u64);
        self.declared_triangles += match primitive.mode() {
            gltf::mesh::Mode::Triangles => declared_indices / 3,
            gltf::mesh::Mode::TriangleStrip | gltf::mesh::Mode::TriangleFan => declared_indices.saturating_sub(2),
            _ => 0,
        };
        self.vertices += declared_vertices;
        if self.vertices > limits.max_vertices {
            let message = format!("the scene has more than {} vertices (max_vertices)", limits.max_vertices);
            return Err(JobError::field(ErrorCode::LimitExceeded, field, message));
        }
        if self.declared_triangles > limits.max_triangles {
            let message = format!("the scene has more than {} triangles (max_triangles)", limits.max_triangles);
            return Err(JobError::field(ErrorCode::LimitExceeded, field, message));
        }
        let buffers = self.buffers;
        let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let Some(positions) = reader.read_positions() else {
            self.skipped_primitives += 1;
            return Ok(());
        };
        let positions: Vec<Vec3> = positions.map(Vec3::from).collect();
        let count = positions.len() as u32;
        let flat: Vec<u32> = match reader.read_indices() {
            Some(indices) => indices.into_u32().collect(),
            None => (0..count).collect(),
        };
        let Some(indices) = triangles(primitive.mode(), &flat) else {
            self.skipped_primitives += 1;
            return Ok(());
        };
        if indices.iter().any(|&i| i >= count) {
            return Err(invalid(field, format!("mesh {mesh_index} indexes past its vertices")));
        }
        let normals: Vec<Vec3> = reader.read_normals().map(|n| n.map(Vec3::from).collect()).unwrap_or_default();
        let texture_info = primitive.material().pbr_metallic_roughness().base_color_texture();
        let uvs: Vec<Vec2> = texture_info
            .as_ref()
            .and_then(|info| reader.read_tex_coords(info.tex_coord()))
            .map(|uv| uv.into_f32().map(Vec2::from).collect())
            .unwrap_or_default();
        if let Some(info) = texture_info.as_ref().filter(|_| uvs.len() != positions.len()) {
            self.untextured.push(format!("mesh {mesh_index} (TEXCOORD_{})", info.tex_coord()));
        }
        let material = self.material(&primitive.material())?;
        let mesh_data = MeshData {
            normals: if normals.len() == positions.len() { normals } else { Vec::new() },
            uvs: if uvs.len() == positions.len() { uvs } else { Vec::new() },
            positions,
            indices,
        };
        self.builder.add_mesh(object_id, &mesh_data, world, material);
        Ok(())
    }

    /// The builder's material for `material`, added (with its base-colour texture, decoded
    /// once per image) the first time it is used.
    fn material(&mut self, material: &gltf::Material<'_>) -> JobResult<u32> {
        if let Some(&m) = self.materials.get(&material.index()) {
            return Ok(m);
        }
        let pbr = material.pbr_metallic_roughness();
        let texture = match pbr.base_color_texture() {
            Some(info) => {
                let image = info.texture().source();
                match self.textures.get(&image.index()) {
                    Some(&slot) => slot,
                    None => {
                        let slot = self.texture(&image)?;
                        self.textures.insert(image.index(), slot);
                        slot
                    }
                }
            }
            None => None,
        };
        let m = self.builder.add_material(Material { base_color: pbr.base_color_factor(), texture });
        self.materials.insert(material.index(), m);
        Ok(m)
    }

    /// The builder's texture for `image`, decoded; `None` where the image cannot be read or
    /// decoded — missing, outside the directory the server reads, in a format glTF does not
    /// allow — with a warning naming it (contract §3: a texture never stops a shadow; the
    /// material keeps its base colour factor). Only a limit stops the scene: the operator set
    /// it, and the answer says which.
    fn texture(&mut self, image: &gltf::Image<'_>) -> JobResult<Option<usize>> {
        let named = match image.source() {
            gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => format!("image {} (`{uri}`)", image.index()),
            _ => format!("image {}", image.index()),
        };
        match decode_texture(image, self.buffers, self.uris, self.texture_bytes) {
            Ok((data, read_as)) => {
                if let Some(path) = read_as {
                    self.builder.warn(format!("{named} was read from `{}` beside the document, as its exporter meant", path.display()));
                }
                self.texture_bytes += data.rgba8.len() as u64;
                Ok(Some(self.builder.add_texture(data)))
            }
            Err(error) if error.code == ErrorCode::LimitExceeded => Err(error),
            Err(error) => {
                self.builder.warn(format!("{named} is not used, its materials take their base colour factor alone: {}", error.message));
                Ok(None)
            }
        }
    }

    /// The scene, or why there is none (no triangles among `instances` mesh instances), with
    /// the warnings of what was left out.
    fn finish(mut self, instances: usize) -> JobResult<Scene> {
        if self.builder.triangle_count() == 0 {
            let why = match (self.skipped_primitives, instances) {
                (0, 0) => "its scene has no node with a mesh".to_owned(),
                (0, _) => "its meshes have no triangles".to_owned(),
                (n, _) => format!("its {n} primitive(s) draw points or lines, which cast no area shadow"),
            };
            return Err(invalid(self.field, format!("the scene holds no triangles: {why}")));
        }
        if self.skipped_primitives > 0 {
            self.builder
                .warn(format!("{} primitive(s) of points or lines were left out: they cast no area shadow", self.skipped_primitives));
        }
        if !self.untextured.is_empty() {
            self.untextured.dedup();
            let list = self.untextured.join(", ");
            self.builder.warn(format!(
                "base-colour textures without the texture coordinates they name are drawn in their first texel's colour: {list}"
            ));
        }
        Ok(self.builder.finish(fitted_defaults))
    }
}

/// Records in the scene's warnings what the document holds that penumbra does not draw
/// (contract §3: listed, never dropped silently). Extensions a document *requires* and
/// penumbra lacks never get here: the gltf crate refuses them.
fn warn_of_what_is_ignored(document: &gltf::Document, builder: &mut SceneBuilder) {
    for name in document.extensions_used() {
        builder.warn(format!("extension `{name}` is ignored: penumbra draws geometry and the base colour"));
    }
    let mut features = std::collections::BTreeSet::new();
    for material in document.materials() {
        if material.emissive_factor() != [0.0; 3] || material.emissive_texture().is_some() {
            features.insert("emission");
        }
        if material.normal_texture().is_some() {
            features.insert("normal textures");
        }
        if material.occlusion_texture().is_some() {
            features.insert("occlusion textures");
        }
        if material.pbr_metallic_roughness().metallic_roughness_texture().is_some() {
            features.insert("metallic-roughness textures");
        }
        if material.alpha_mode() != gltf::material::AlphaMode::Opaque {
            features.insert("alpha blending and masking");
        }
    }
    if !features.is_empty() {
        let list: Vec<&str> = features.into_iter().collect();
        builder.warn(format!("material features ignored ({}): surfaces are Lambertian with their base colour", list.join(", ")));
    }
    if document.animations().next().is_some() {
        builder.warn("animations are ignored: the scene is drawn at rest");
    }
    if document.skins().next().is_some() {
        builder.warn("skins are ignored: skinned meshes are drawn in their bind pose");
    }
    if document.meshes().flat_map(|m| m.primitives()).any(|p| p.morph_targets().next().is_some()) {
        builder.warn("morph targets are ignored: meshes are drawn in their base shape");
    }
    if document.cameras().next().is_some() {
        builder.warn("the file's cameras are not used: the job's camera, or one fitted to the scene, is");
    }
}

/// Decodes image `image` into 8-bit RGBA, `taken` bytes of `max_texture_bytes` having gone to
/// the scene's textures before it: its decoder may allocate what is left and no more, and its
/// texels must fit there.
///
/// Answers, with the texels, the path an exporter's spelling of its URI was read from
/// (`UriReader::read_image`), if one was.
fn decode_texture(image: &gltf::Image, buffers: &[Vec<u8>], uris: &UriReader<'_>, taken: u64) -> JobResult<(TextureData, Option<PathBuf>)> {
    let (limits, field) = (uris.limits, uris.field);
    let left = limits.max_texture_bytes.saturating_sub(taken);
    let too_large = |what: String| {
        let message = format!(
            "image {}: too large: {what} (max_texture_dim {}; max_texture_bytes {} for the scene's decoded textures, {left} of them left)",
            image.index(),
            limits.max_texture_dim,
            limits.max_texture_bytes
        );
        JobError::field(ErrorCode::LimitExceeded, field, message)
    };
    let (bytes, read_as) = match image.source() {
        gltf::image::Source::View { view, .. } => {
            let buffer = &buffers[view.buffer().index()];
            let bytes = buffer
                .get(view.offset()..view.offset() + view.length())
                .ok_or_else(|| invalid(field, "an image's buffer view lies outside its buffer"))?;
            (bytes.to_vec(), None)
        }
        gltf::image::Source::Uri { uri, .. } => uris.read_image(uri)?,
    };
    use crate::image_input::{self, Refusal};
    // glTF 2.0 images are PNG or JPEG; an EXR is taken as well, as it always was.
    let formats = [image::ImageFormat::Png, image::ImageFormat::Jpeg, image::ImageFormat::OpenExr];
    // The decoder's buffers (for an EXR, every part's, from its header) within what is left.
    let image_limits = image_input::Limits { max_dim: limits.max_texture_dim, max_alloc: left };
    let (decoded, _) = image_input::decode(&bytes, &formats, image_limits).map_err(|refusal| match refusal {
        Refusal::Format(_) => invalid(field, "a texture must be a PNG, a JPEG or an OpenEXR file"),
        Refusal::TooLarge(what) => too_large(what),
        Refusal::Invalid(why) => invalid(field, format!("cannot decode texture: {why}")),
    })?;
    // A decoder's buffer of fewer bytes a texel (8-bit RGB, gray) fits where its RGBA would not.
    let rgba_bytes = 4 * u64::from(decoded.width()) * u64::from(decoded.height());
    if rgba_bytes > left {
        return Err(too_large(format!("{}×{} texels, {rgba_bytes} bytes as RGBA", decoded.width(), decoded.height())));
    }
    let rgba = decoded.into_rgba8();
    Ok((TextureData { width: rgba.width(), height: rgba.height(), rgba8: rgba.into_raw() }, read_as))
}

#[cfg(test)]
mod tests;
