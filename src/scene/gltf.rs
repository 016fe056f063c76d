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
use std::path::{Component, Path, PathBuf};

use base64::Engine as _;
use glam::{Mat4, Vec2, Vec3};

use super::{fitted_defaults, Material, MeshData, Scene, SceneBuilder, TextureData};
use crate::error::{ErrorCode, JobError, JobResult};
use crate::job::Limits;

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

/// Checks a GLB container's header and chunk lengths against the bytes there are (glTF 2.0
/// §4.4) before the gltf crate reads them: its parser subtracts before it compares (a declared
/// length under 12 underflows; found by `cargo fuzz`, kept as a regression test).
fn check_glb_container(bytes: &[u8], field: &str) -> JobResult<()> {
    if !bytes.starts_with(b"glTF") {
        return Ok(()); // glTF JSON: the JSON parser bounds itself.
    }
    let word = |at: usize| bytes.get(at..at + 4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]) as usize);
    let (Some(version), Some(length)) = (word(4), word(8)) else { return Err(invalid(field, "GLB header truncated")) };
    if version != 2 {
        return Err(invalid(field, format!("GLB version {version}; only glTF 2.0 is supported")));
    }
    if length < 12 + 8 || length > bytes.len() {
        return Err(invalid(field, format!("GLB declares {length} bytes; the body has {}", bytes.len())));
    }
    let mut at = 12;
    while at < length {
        let Some(chunk) = word(at).filter(|_| at + 8 <= length) else { return Err(invalid(field, "GLB chunk header truncated")) };
        if chunk > length - at - 8 {
            return Err(invalid(field, format!("GLB chunk at byte {at} declares {chunk} bytes past the end of the file")));
        }
        at += 8 + chunk;
    }
    Ok(())
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

/// Parses the document, refusing one that requires an extension, then validates its indices.
/// Answers with it what was repaired to read it (for the scene's warnings).
fn parse_document(bytes: &[u8], field: &str) -> JobResult<(gltf::Gltf, Option<&'static str>)> {
    check_glb_container(bytes, field)?;
    let not_valid = |e: gltf::Error| invalid(field, format!("not a valid glTF 2.0 document: {e}"));
    let parse = |bytes: &[u8]| {
        gltf::Gltf::from_slice_without_validation(bytes)
            .or_else(|error| with_scene_nodes(bytes).map_or(Err(error), |patched| gltf::Gltf::from_slice_without_validation(&patched)))
    };
    let (parsed, repaired) = match parse(bytes) {
        Err(error) => match with_utf8_json(bytes) {
            Some(patched) => {
                (parse(&patched), Some("its JSON was not UTF-8 (glTF 2.0 §3.1): the bytes that were not were read as U+FFFD in its names"))
            }
            None => (Err(error), None),
        },
        parsed => (parsed, None),
    };
    let gltf::Gltf { document, blob } = parsed.map_err(not_valid)?;
    // Checked before the document's indices: a required extension such as Draco changes
    // what they mean, and the gltf crate's validation would report its symptoms instead.
    if let Some(name) = document.extensions_required().next() {
        return Err(invalid(
            field,
            format!("the document requires extension `{name}`, which penumbra does not support (it reads plain glTF 2.0 meshes)"),
        ));
    }
    Ok((gltf::Gltf { document: gltf::Document::from_json(document.into_json()).map_err(not_valid)?, blob }, repaired))
}

/// Some exporters write names in an 8-bit code page where glTF's JSON must be UTF-8: the
/// document (JSON, or GLB with its JSON chunk) with every byte that is not UTF-8 read as
/// U+FFFD, or `None` if it is UTF-8 already. Only strings change: JSON's syntax is ASCII.
fn with_utf8_json(bytes: &[u8]) -> Option<Vec<u8>> {
    if !bytes.starts_with(b"glTF") {
        return std::str::from_utf8(bytes).is_err().then(|| String::from_utf8_lossy(bytes).into_owned().into_bytes());
    }
    // The container was checked (`check_glb_container`): its first chunk is the JSON.
    let length = u32::from_le_bytes(bytes.get(12..16)?.try_into().ok()?) as usize;
    let json = bytes.get(20..20 + length)?;
    if std::str::from_utf8(json).is_ok() {
        return None;
    }
    let mut fixed = String::from_utf8_lossy(json).into_owned().into_bytes();
    fixed.resize(fixed.len().next_multiple_of(4), b' ');
    let rest = &bytes[20 + length..];
    let mut out = Vec::with_capacity(20 + fixed.len() + rest.len());
    out.extend_from_slice(&bytes[..8]);
    out.extend_from_slice(&((20 + fixed.len() + rest.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(fixed.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&fixed);
    out.extend_from_slice(rest);
    Some(out)
}

/// Every buffer's bytes: the GLB binary chunk or what its URI names, each within
/// `max_body_bytes` and at least as long as it declares.
fn read_buffers(gltf: &gltf::Gltf, limits: &Limits, field: &str, uris: &UriReader<'_>) -> JobResult<Vec<Vec<u8>>> {
    gltf.document
        .buffers()
        .map(|buffer| {
            let data = match buffer.source() {
                gltf::buffer::Source::Bin => gltf.blob.clone().ok_or_else(|| invalid(field, "GLB binary chunk missing"))?,
                gltf::buffer::Source::Uri(uri) => uris.read(uri)?,
            };
            if buffer.length() > limits.max_body_bytes {
                return Err(JobError::field(
                    ErrorCode::LimitExceeded,
                    field,
                    format!(
                        "buffer {} declares {} bytes; the limit is {} (max_body_bytes)",
                        buffer.index(),
                        buffer.length(),
                        limits.max_body_bytes
                    ),
                ));
            }
            if data.len() < buffer.length() {
                return Err(invalid(field, format!("buffer {} is shorter than its declared length", buffer.index())));
            }
            Ok(data)
        })
        .collect()
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

/// The gltf crate requires `nodes` in every scene, which glTF 2.0 makes optional (§5.29, a
/// scene without nodes is valid and empty): a JSON document whose scenes leave it out,
/// with empty lists in their place. `None` if nothing was left out.
fn with_scene_nodes(bytes: &[u8]) -> Option<Vec<u8>> {
    let mut document: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    let mut patched = false;
    for scene in document.get_mut("scenes")?.as_array_mut()?.iter_mut().filter_map(serde_json::Value::as_object_mut) {
        if !scene.contains_key("nodes") {
            scene.insert("nodes".into(), serde_json::json!([]));
            patched = true;
        }
    }
    patched.then(|| serde_json::to_vec(&document).ok()).flatten()
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

/// The files a glTF JSON document names by relative URI, beside it in `folder` (`..` applied
/// as written, nothing opened): what its scene also depends on, for cache keys. URIs the
/// loader would refuse are left out (the load reports them).
pub fn files_named(bytes: &[u8], folder: &Path) -> Vec<PathBuf> {
    #[derive(serde::Deserialize)]
    struct Named<'a> {
        #[serde(borrow, default)]
        uri: Option<std::borrow::Cow<'a, str>>,
    }
    #[derive(serde::Deserialize)]
    struct Document<'a> {
        #[serde(borrow, default)]
        buffers: Vec<Named<'a>>,
        #[serde(borrow, default)]
        images: Vec<Named<'a>>,
    }
    let Ok(document) = serde_json::from_slice::<Document>(bytes) else { return Vec::new() };
    document
        .buffers
        .iter()
        .chain(&document.images)
        .filter_map(|named| named.uri.as_deref())
        .filter(|uri| !uri.starts_with("data:"))
        .filter_map(|uri| relative_uri_path(uri).ok())
        .filter_map(|relative| lexical_join(folder, &relative))
        .collect()
}

/// Reads what a document's URIs name, as its `Resources` allow, within one budget for the
/// whole document: a scene from disk may hold no more than an upload may (`max_body_bytes`).
struct UriReader<'a> {
    resources: Resources<'a>,
    limits: &'a Limits,
    field: &'a str,
    read: std::cell::Cell<u64>,
}

impl UriReader<'_> {
    fn read(&self, uri: &str) -> JobResult<Vec<u8>> {
        if let Some(rest) = uri.strip_prefix("data:") {
            return decode_data_uri(rest, self.field);
        }
        let Resources::Beside { .. } = self.resources else {
            return Err(invalid(
                self.field,
                format!(
                    "URI `{uri}`: an uploaded scene must be self-contained (data: URIs or one GLB); \
                     pack a multi-file glTF into one GLB first (`penumbra submit` does)"
                ),
            ));
        };
        let relative = relative_uri_path(uri).map_err(|why| self.refused(uri, why))?;
        self.read_relative(&relative, uri)
    }

    /// Reads an image the document names: as written, else where an exporter's spelling of a
    /// path means it (`exporter_spellings`). Answers the bytes and, when a spelling found them,
    /// the path they were read from; the first error when none did (a limit at once).
    fn read_image(&self, uri: &str) -> JobResult<(Vec<u8>, Option<PathBuf>)> {
        let first = match self.read(uri) {
            Ok(bytes) => return Ok((bytes, None)),
            Err(error) if error.code == ErrorCode::LimitExceeded => return Err(error),
            Err(error) => error,
        };
        if matches!(self.resources, Resources::Beside { .. }) {
            for relative in exporter_spellings(uri) {
                match self.read_relative(&relative, uri) {
                    Ok(bytes) => return Ok((bytes, Some(relative))),
                    Err(error) if error.code == ErrorCode::LimitExceeded => return Err(error),
                    Err(_) => {}
                }
            }
        }
        Err(first)
    }

    fn refused(&self, uri: &str, why: &str) -> JobError {
        JobError::field(ErrorCode::PathNotAllowed, self.field, format!("URI `{uri}`: {why}"))
    }

    /// Reads `relative` (what `uri` names) from beside the document, inside the directory the
    /// server reads and within the document's budget.
    fn read_relative(&self, relative: &Path, uri: &str) -> JobResult<Vec<u8>> {
        let Resources::Beside { folder, confined_to } = self.resources else { unreachable!("only documents from disk name files") };
        // Judged on the path as written first, so that a refusal says nothing about what
        // exists outside the directory; then again with symlinks resolved.
        let outside = "leads outside the directory this server reads scenes from";
        let joined = lexical_join(folder, relative).ok_or_else(|| self.refused(uri, outside))?;
        if confined_to.is_some_and(|root| !joined.starts_with(root)) {
            return Err(self.refused(uri, outside));
        }
        let resolved = std::fs::canonicalize(&joined)
            .ok()
            .filter(|p| p.is_file())
            .ok_or_else(|| invalid(self.field, format!("URI `{uri}`: no file `{}` beside the document", relative.display())))?;
        if confined_to.is_some_and(|root| !resolved.starts_with(root)) {
            return Err(self.refused(uri, outside));
        }
        let length = std::fs::metadata(&resolved).map(|m| m.len()).unwrap_or(u64::MAX);
        let budget = self.limits.max_body_bytes as u64;
        if self.read.get().saturating_add(length) > budget {
            let message = format!("URI `{uri}`: the document's files exceed {budget} bytes together (max_body_bytes)");
            return Err(JobError::field(ErrorCode::LimitExceeded, self.field, message));
        }
        let bytes = std::fs::read(&resolved).map_err(|e| invalid(self.field, format!("URI `{uri}`: cannot read: {e}")))?;
        self.read.set(self.read.get() + bytes.len() as u64);
        Ok(bytes)
    }
}

/// Where exporters that do not write glTF's URIs mean a file beside the document, in the
/// order tried: the path with Windows' backslashes as separators and without Blender's `//`
/// ("relative to the .blend") prefix; then the file's name alone, beside the document (an
/// absolute path on the author's machine, `D:\models\wood.jpg`, or a relative one into a folder
/// the model was not shipped with). Each is still read as a relative path is: inside the
/// folder the server reads, never from an absolute path.
fn exporter_spellings(uri: &str) -> Vec<PathBuf> {
    let slashed = uri.replace('\\', "/");
    let trimmed = slashed.strip_prefix("//").unwrap_or(&slashed);
    let mut candidates = Vec::new();
    let drive = trimmed.as_bytes().get(1) == Some(&b':');
    if !trimmed.starts_with('/') && !drive && !trimmed.contains("://") {
        candidates.push(PathBuf::from(trimmed));
    }
    if let Some(name) = trimmed.rsplit('/').next().filter(|n| !n.is_empty() && *n != "." && *n != "..") {
        candidates.push(PathBuf::from(name));
    }
    candidates.retain(|c| c.as_os_str() != uri);
    candidates.dedup();
    candidates
}

/// The path a relative URI reference names (glTF 2.0 §3.2 "URIs": relative to the document,
/// percent-encoded as RFC 3986 says), or why it is not one penumbra reads: URIs with a
/// scheme (`file:`, `http:` …), network-path (`//host/…`) and absolute references.
fn relative_uri_path(uri: &str) -> Result<PathBuf, &'static str> {
    let scheme_end = uri.find([':', '/', '?', '#']);
    if let Some(end) = scheme_end.filter(|&end| uri[end..].starts_with(':')) {
        let scheme = &uri[..end];
        if scheme.starts_with(|c: char| c.is_ascii_alphabetic())
            && scheme.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
        {
            return Err("only paths relative to the document are read (no file: or network URIs)");
        }
    }
    // A query or fragment is not part of the file's name (`#` in a name is written `%23`).
    let path = &uri[..uri.find(['?', '#']).unwrap_or(uri.len())];
    let decoded = percent_encoding::percent_decode_str(path).decode_utf8().map_err(|_| "not UTF-8 once percent-decoded")?;
    if decoded.is_empty() || decoded.contains('\0') {
        return Err("not a file name");
    }
    if decoded.starts_with('/') || decoded.starts_with('\\') {
        return Err("absolute paths are not read; only paths relative to the document");
    }
    Ok(PathBuf::from(decoded.as_ref()))
}

/// `folder` joined with `relative`, `.` and `..` applied as written (no file is touched);
/// `None` if it climbs above the filesystem's root or names a root of its own.
fn lexical_join(folder: &Path, relative: &Path) -> Option<PathBuf> {
    let mut joined = folder.to_path_buf();
    for component in relative.components() {
        match component {
            Component::Normal(name) => joined.push(name),
            Component::CurDir => {}
            Component::ParentDir => {
                if !joined.pop() {
                    return None;
                }
            }
            Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    Some(joined)
}

/// Decodes the rest of an RFC 2397 `data:` URI (after `data:`) with base64 content.
fn decode_data_uri(rest: &str, field: &str) -> JobResult<Vec<u8>> {
    let Some((header, payload)) = rest.split_once(',') else {
        return Err(invalid(field, "malformed data: URI"));
    };
    if !header.ends_with(";base64") {
        return Err(invalid(field, "data: URIs must be base64-encoded"));
    }
    base64::engine::general_purpose::STANDARD.decode(payload.trim()).map_err(|e| invalid(field, format!("bad base64 in data: URI: {e}")))
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

/// Packs a `.gltf` document read from `folder`, and the files its relative URIs name, into one
/// self-contained GLB (contract §3: what a client uploads). Every buffer becomes part of the
/// BIN chunk, its views moved by where it landed; every image named by a file becomes a
/// buffer view of it. URIs follow the loader's rule for a document from disk
/// (`Resources::Beside`, unconfined: the client reads its user's files) and its budget. A GLB,
/// or a document that names no file, is returned as it is.
pub fn pack(bytes: &[u8], folder: &Path, limits: &Limits, field: &str) -> JobResult<Vec<u8>> {
    use serde_json::Value;
    let names_a_file = |item: &Value| item.get("uri").and_then(Value::as_str).is_some_and(|uri| !uri.starts_with("data:"));
    if bytes.starts_with(b"glTF") {
        return Ok(bytes.to_vec());
    }
    let mut document: Value = serde_json::from_slice(bytes).map_err(|e| invalid(field, format!("not a glTF 2.0 document: {e}")))?;
    let items = |document: &Value, key: &str| document.get(key).and_then(Value::as_array).cloned().unwrap_or_default();
    if !items(&document, "buffers").iter().chain(&items(&document, "images")).any(names_a_file) {
        return Ok(bytes.to_vec());
    }
    let uris = UriReader { resources: Resources::Beside { folder, confined_to: None }, limits, field, read: std::cell::Cell::new(0) };
    let mut bin = Vec::new();
    let mut starts = Vec::new();
    for (index, buffer) in items(&document, "buffers").iter().enumerate() {
        let length =
            buffer.get("byteLength").and_then(Value::as_u64).ok_or_else(|| invalid(field, format!("buffer {index} has no byteLength")))?;
        let uri =
            buffer.get("uri").and_then(Value::as_str).ok_or_else(|| invalid(field, format!("buffer {index} of a .gltf has no uri")))?;
        let data = uris.read(uri)?;
        let data =
            data.get(..length as usize).ok_or_else(|| invalid(field, format!("buffer {index} is shorter than its declared length")))?;
        starts.push(bin.len() as u64);
        bin.extend_from_slice(data);
        // Views keep their alignment (at most 4 bytes per component) if every buffer starts on 4.
        bin.resize(bin.len().next_multiple_of(4), 0);
    }
    let mut views = items(&document, "bufferViews");
    for (index, view) in views.iter_mut().enumerate() {
        let buffer = view.get("buffer").and_then(Value::as_u64).and_then(|b| starts.get(b as usize));
        let start = *buffer.ok_or_else(|| invalid(field, format!("buffer view {index} names no buffer of the document")))?;
        let offset = view.get("byteOffset").and_then(Value::as_u64).unwrap_or(0);
        view["buffer"] = 0.into();
        view["byteOffset"] = (start + offset).into();
    }
    let mut images = items(&document, "images");
    for image in images.iter_mut().filter(|image| names_a_file(image)) {
        let uri = image["uri"].as_str().unwrap_or_default().to_owned();
        // An image that cannot be read, or is neither PNG nor JPEG (glTF 2.0 §3.8.2), stays a
        // URI: the scene still loads, with a warning naming it (a texture never stops a shadow).
        let data = match uris.read_image(&uri) {
            Ok((data, _)) => data,
            Err(error) if error.code == ErrorCode::LimitExceeded => return Err(error),
            Err(_) => continue,
        };
        let mime = match data.as_slice() {
            [0x89, b'P', b'N', b'G', ..] => "image/png",
            [0xFF, 0xD8, ..] => "image/jpeg",
            _ => continue,
        };
        views.push(serde_json::json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": data.len()}));
        bin.extend_from_slice(&data);
        bin.resize(bin.len().next_multiple_of(4), 0);
        let object = image.as_object_mut().expect("an image with a uri is an object");
        object.remove("uri");
        object.insert("bufferView".into(), (views.len() - 1).into());
        object.insert("mimeType".into(), mime.into());
    }
    document["buffers"] = serde_json::json!([{"byteLength": bin.len()}]);
    document["bufferViews"] = views.into();
    if !images.is_empty() {
        document["images"] = images.into();
    }
    Ok(glb(&document, &bin))
}

/// Packs a glTF document and its binary buffer into one GLB file (glTF 2.0 §4.4: a 12-byte
/// header, a JSON chunk padded with spaces, a BIN chunk padded with zeros). The document's
/// buffer 0 must leave out `uri` to mean the BIN chunk.
pub fn glb(document: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(document).expect("a JSON value serialises");
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut bin = bin.to_vec();
    bin.resize(bin.len().next_multiple_of(4), 0);
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// A GLB height field of `n × n` vertices (2 (n−1)² triangles) over a 4 m square with bumps
/// set by `seed`: distinct bytes for every seed, for benchmarks and load tests that need many
/// different scenes of a chosen size.
pub fn height_field_glb(n: u32, seed: u32) -> Vec<u8> {
    let (document, bin) = height_field(n, seed);
    glb(&document, &bin)
}

/// `height_field_glb(3, 1)` drawn in one part per entry of `colors`, each with a material of
/// its own whose base colour is a `side × side` PNG of that colour type (3 bytes a texel
/// decoded for RGB, 4 as a texture): for tests of what textures may take.
pub fn textured_height_field_glb(colors: &[image::ColorType], side: u32) -> Vec<u8> {
    let images: Vec<Vec<u8>> = colors
        .iter()
        .enumerate()
        .map(|(k, &color)| {
            let texels = vec![(40 * k) as u8; (side * side) as usize * usize::from(color.bytes_per_pixel())];
            let mut png = Vec::new();
            image::ImageEncoder::write_image(image::codecs::png::PngEncoder::new(&mut png), &texels, side, side, color.into())
                .expect("a PNG of whole texels encodes");
            png
        })
        .collect();
    height_field_with_images(&images)
}

/// `height_field_glb(3, 1)` drawn in one part per image file of `images` (stored in the BIN
/// chunk as they are), each part with a material whose base colour is that image.
fn height_field_with_images(images: &[Vec<u8>]) -> Vec<u8> {
    let (mut document, mut bin) = height_field(3, 1);
    let mut views = Vec::new();
    for file in images {
        views.push(serde_json::json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": file.len()}));
        bin.extend_from_slice(file);
        bin.resize(bin.len().next_multiple_of(4), 0);
    }
    let parts = images.len();
    document["buffers"][0]["byteLength"] = bin.len().into();
    document["bufferViews"].as_array_mut().expect("the height field's views").extend(views);
    document["images"] = (0..parts).map(|k| serde_json::json!({"bufferView": 2 + k, "mimeType": "image/png"})).collect();
    document["textures"] = (0..parts).map(|k| serde_json::json!({"source": k})).collect();
    document["materials"] = (0..parts).map(|k| serde_json::json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": k}}})).collect();
    let primitive = document["meshes"][0]["primitives"][0].clone();
    document["meshes"][0]["primitives"] = (0..parts)
        .map(|k| {
            let mut primitive = primitive.clone();
            primitive["material"] = k.into();
            primitive
        })
        .collect();
    glb(&document, &bin)
}

/// The glTF document of `height_field_glb` and its binary buffer (buffer 0, without `uri`).
fn height_field(n: u32, seed: u32) -> (serde_json::Value, Vec<u8>) {
    let n = n.max(2);
    let mut bin = Vec::new();
    let (fx, fz) = (1.0 + (seed % 7) as f32, 1.0 + (seed / 7 % 5) as f32);
    for z in 0..n {
        for x in 0..n {
            let (u, v) = (x as f32 / (n - 1) as f32, z as f32 / (n - 1) as f32);
            let y = 0.3 * (fx * u * std::f32::consts::TAU).sin() * (fz * v * std::f32::consts::TAU).cos() + 0.4;
            for c in [4.0 * u - 2.0, y, 4.0 * v - 2.0] {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    let positions = bin.len();
    for z in 0..n - 1 {
        for x in 0..n - 1 {
            let i = z * n + x;
            for k in [i, i + n, i + 1, i + 1, i + n, i + n + 1] {
                bin.extend_from_slice(&k.to_le_bytes());
            }
        }
    }
    let indices = bin.len() - positions;
    let document = serde_json::json!({
        "asset": {"version": "2.0", "generator": format!("penumbra height field {n}x{n} seed {seed}")},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "field", "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": positions},
            {"buffer": 0, "byteOffset": positions, "byteLength": indices}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n * n, "type": "VEC3",
             "min": [-2.0, 0.1, -2.0], "max": [2.0, 0.7, 2.0]},
            {"bufferView": 1, "componentType": 5125, "count": 6 * (n - 1) * (n - 1), "type": "SCALAR"}
        ]
    });
    (document, bin)
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    /// `cargo fuzz run scene` found this: a GLB header declaring a length of 0.
    #[test]
    fn malformed_glb_containers_are_refused_before_parsing() {
        let fuzzed = b"glTF\x02\x00\x00\x00\x00\x00\x00\x00\x80\x02\x00\x00cene\xcd\":[{";
        for bytes in [&fuzzed[..], b"glTF\x02\x00\x00\x00", b"glTF\x02\x00\x00\x00\x14\x00\x00\x00\xff\xff\xff\x7fJSON"] {
            let error = check_glb_container(bytes, "scene").unwrap_err();
            assert_eq!(error.code, ErrorCode::InvalidAsset, "{}", error.message);
            assert_eq!(load(bytes, &Limits::default(), "scene").unwrap_err().code, ErrorCode::InvalidAsset);
        }
        let valid = height_field_glb(3, 1);
        assert!(check_glb_container(&valid, "scene").is_ok());
    }

    /// `cargo fuzz run scene` found this: a POSITION accessor index past the accessors makes
    /// the `gltf` crate's own validator index out of bounds; the loader answers `invalid_asset`.
    #[test]
    fn an_attribute_naming_a_missing_accessor_is_an_invalid_asset() {
        let document = br#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 5}}]}],
            "accessors": [{"componentType": 5126, "count": 3, "type": "VEC3"}]}"#;
        let error = load(document, &Limits::default(), "scene").unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::InvalidAsset, Some("scene")));
    }

    #[test]
    fn counts_and_lengths_are_refused_from_what_the_file_declares() {
        let bytes = height_field_glb(9, 3); // 81 vertices, 128 triangles, 1.3 KiB buffer.
        let refused = |limits: Limits| {
            let error = load(&bytes, &limits, "scene").unwrap_err();
            assert_eq!((error.code, error.field.as_deref()), (ErrorCode::LimitExceeded, Some("scene")), "{}", error.message);
            error.message
        };
        assert!(refused(Limits { max_vertices: 80, ..Limits::default() }).contains("max_vertices"));
        assert!(refused(Limits { max_triangles: 127, ..Limits::default() }).contains("max_triangles"));
        assert!(refused(Limits { max_body_bytes: 1000, ..Limits::default() }).contains("declares"));
        load(&bytes, &Limits { max_vertices: 81, max_triangles: 128, ..Limits::default() }, "scene").expect("at the limits");

        // A billion vertices declared over a 36-byte buffer: refused from the count alone.
        let document = br#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 5}]}],
            "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA"}],
            "bufferViews": [{"buffer": 0, "byteLength": 36}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 1000000000, "type": "VEC3"}]}"#;
        let error = load(document, &Limits::default(), "scene").unwrap_err();
        assert!(matches!(error.code, ErrorCode::LimitExceeded | ErrorCode::InvalidAsset), "{error}");
    }

    #[test]
    fn height_fields_load_with_the_requested_triangles_and_differ_by_seed() {
        let bytes = height_field_glb(9, 3);
        let scene = load(&bytes, &Limits::default(), "scene").expect("a valid GLB");
        assert_eq!(scene.indices.len(), 3 * 2 * 8 * 8);
        assert_ne!(bytes, height_field_glb(9, 4));
    }

    /// A texture is decoded under the same guard as a light image: an EXR whose data window
    /// is far larger than its display window (found by `cargo fuzz run light_image`; its 30 GB
    /// allocation inside the `exr` crate aborted the process) is refused, `limit_exceeded`.
    #[test]
    fn a_texture_whose_exr_parts_exceed_the_limits_is_refused() {
        let exr = include_bytes!("../../fuzz/regressions/light_image-exr-data-window.exr");
        let error = load(&height_field_with_images(&[exr.to_vec()]), &Limits::default(), "scene").unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::LimitExceeded, Some("scene")), "{}", error.message);
        assert!(error.message.contains("data window"), "{}", error.message);
    }

    /// `max_texture_bytes` bounds what a scene's textures take decoded, together: a body of many
    /// small files of large images cannot decode to more. Refused from the decoder's own
    /// budget (an RGBA image that does not fit what is left) or from the RGBA texels of one
    /// whose decoder took less (RGB).
    #[test]
    fn textures_are_decoded_within_the_scenes_texture_budget() {
        let rgba = image::ColorType::Rgba8;
        let bytes = textured_height_field_glb(&[rgba, rgba, image::ColorType::Rgb8], 64);
        let texture = 64 * 64 * 4;
        let fits = |max_texture_bytes: u64| load(&bytes, &Limits { max_texture_bytes, ..Limits::default() }, "scene");
        let scene = fits(3 * texture).expect("three textures within the budget");
        assert_eq!(scene.textures.len(), 3);
        for (max, refused_image) in
            [(texture + texture / 2, "image 1"), (2 * texture + 3 * 64 * 64, "image 2"), (3 * texture - 1, "image 2")]
        {
            let error = fits(max).unwrap_err();
            assert_eq!((error.code, error.field.as_deref()), (ErrorCode::LimitExceeded, Some("scene")), "{}", error.message);
            assert!(error.message.contains(refused_image) && error.message.contains("max_texture_bytes"), "{max}: {}", error.message);
        }
    }

    /// A folder `root` holding a height field as `box.gltf` beside `mesh data.bin`, a
    /// `secret.bin` outside it, and `root/link.bin`, a symlink to the secret.
    struct MultiFile {
        top: PathBuf,
        root: PathBuf,
        bin: Vec<u8>,
    }

    impl MultiFile {
        fn new(name: &str) -> Self {
            let top = std::env::temp_dir().join(format!("penumbra-uris-{name}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&top);
            let root = top.join("root");
            std::fs::create_dir_all(root.join("sub")).unwrap();
            let (_, bin) = height_field(5, 2);
            std::fs::write(root.join("mesh data.bin"), &bin).unwrap();
            std::fs::write(top.join("secret.bin"), &bin).unwrap();
            std::os::unix::fs::symlink(top.join("secret.bin"), root.join("link.bin")).unwrap();
            let root = std::fs::canonicalize(root).unwrap();
            MultiFile { top, root, bin }
        }

        /// The height field's document with buffer 0 read from `uri`.
        fn document(&self, uri: &str) -> Vec<u8> {
            let (mut document, _) = height_field(5, 2);
            document["buffers"][0]["uri"] = uri.into();
            serde_json::to_vec(&document).unwrap()
        }

        fn load(&self, uri: &str, confined: bool, limits: &Limits) -> JobResult<Scene> {
            let resources = Resources::Beside { folder: &self.root, confined_to: confined.then_some(self.root.as_path()) };
            load_from(&self.document(uri), limits, "scene", resources)
        }
    }

    impl Drop for MultiFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.top);
        }
    }

    #[test]
    fn relative_uris_are_read_beside_the_document_percent_decoded() {
        let files = MultiFile::new("beside");
        let triangles = 3 * 2 * 4 * 4;
        for uri in ["mesh%20data.bin", "./mesh%20data.bin", "sub/../mesh%20data.bin", "mesh%20data.bin?v=2"] {
            let scene = files.load(uri, true, &Limits::default()).unwrap_or_else(|e| panic!("{uri}: {e}"));
            assert_eq!(scene.indices.len(), triangles, "{uri}");
        }
        // The same document uploaded is refused, naming the URI and the way out.
        let error = load(&files.document("mesh%20data.bin"), &Limits::default(), "body").unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::InvalidAsset, Some("body")));
        assert!(error.message.contains("`mesh%20data.bin`") && error.message.contains("GLB"), "{}", error.message);
        // A missing file is named; so is a document whose files outgrow the upload limit.
        let error = files.load("missing.bin", true, &Limits::default()).unwrap_err();
        assert_eq!(error.code, ErrorCode::InvalidAsset);
        assert!(error.message.contains("`missing.bin`"), "{}", error.message);
        let small = Limits { max_body_bytes: files.bin.len() - 1, ..Limits::default() };
        assert_eq!(files.load("mesh%20data.bin", true, &small).unwrap_err().code, ErrorCode::LimitExceeded);
    }

    /// A 2×2 orange PNG.
    fn orange_png() -> Vec<u8> {
        let mut png = Vec::new();
        image::RgbaImage::from_pixel(2, 2, image::Rgba([200, 100, 50, 255]))
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        png
    }

    /// What `penumbra submit` uploads: the document and its files as one GLB, which loads
    /// alone to the same scene; an image file becomes a view of the BIN chunk.
    #[test]
    fn a_multi_file_document_packs_into_one_self_contained_glb() {
        let files = MultiFile::new("pack");
        let png = orange_png();
        std::fs::write(files.root.join("sub/tex ture.png"), &png).unwrap();
        let mut document: serde_json::Value = serde_json::from_slice(&files.document("mesh%20data.bin")).unwrap();
        document["images"] = serde_json::json!([{"uri": "sub/tex%20ture.png"}]);
        let bytes = serde_json::to_vec(&document).unwrap();

        let packed = pack(&bytes, &files.root, &Limits::default(), "scene").unwrap();
        let scene = load(&packed, &Limits::default(), "scene").expect("self-contained");
        assert_eq!(scene.indices.len(), 3 * 2 * 4 * 4);
        let glb = gltf::Gltf::from_slice(&packed).unwrap();
        let image = glb.document.images().next().unwrap();
        let gltf::image::Source::View { view, mime_type } = image.source() else { panic!("the image is still a file") };
        assert_eq!(mime_type, "image/png");
        let blob = glb.blob.as_deref().unwrap();
        assert_eq!(&blob[view.offset()..view.offset() + view.length()], png.as_slice());
        // A GLB, or a document naming no file, is left as it is; a missing file is named.
        let glb_bytes = height_field_glb(3, 1);
        assert_eq!(pack(&glb_bytes, &files.root, &Limits::default(), "scene").unwrap(), glb_bytes);
        let error = pack(&files.document("gone.bin"), &files.root, &Limits::default(), "scene").unwrap_err();
        assert!(error.message.contains("`gone.bin`"), "{}", error.message);
    }

    /// Contract §3: a texture never stops a shadow. Images an exporter names its own way are
    /// found beside the document; the ones that cannot be read or decoded are skipped with a
    /// warning naming them; a missing buffer still refuses the scene.
    #[test]
    fn textures_that_cannot_be_read_are_skipped_by_name_and_exporters_spellings_are_found() {
        let files = MultiFile::new("textures");
        let png = orange_png();
        std::fs::write(files.root.join("sub/wood.png"), &png).unwrap();
        std::fs::write(files.root.join("wood.png"), &png).unwrap();
        std::fs::write(files.root.join("paint.tga"), [0u8, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 1, 0, 24, 0, 1, 2, 3]).unwrap();
        std::fs::write(files.top.join("outside.png"), &png).unwrap();
        let uris = [
            "sub/wood.png",              // as glTF writes it
            "D:\\models\\sub\\wood.png", // the author's absolute path: its name beside the document
            ".\\sub\\wood.png",          // Windows separators
            "//sub/wood.png",            // Blender's "relative to the .blend"
            "missing.png",
            "paint.tga",                     // a format glTF does not allow
            "../outside.png",                // outside the directory the server reads
            "Procedural,num=0,type=Voronoi", // not a file at all
        ];
        let mut document: serde_json::Value = serde_json::from_slice(&files.document("mesh%20data.bin")).unwrap();
        document["images"] = uris.iter().map(|uri| serde_json::json!({"uri": uri})).collect();
        document["textures"] = (0..uris.len()).map(|k| serde_json::json!({"source": k})).collect();
        document["materials"] = (0..uris.len())
            .map(|k| serde_json::json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": k}, "baseColorFactor": [0.5, 0.25, 0.125, 1.0]}}))
            .collect();
        let primitive = document["meshes"][0]["primitives"][0].clone();
        document["meshes"][0]["primitives"] = (0..uris.len())
            .map(|k| {
                let mut primitive = primitive.clone();
                primitive["material"] = k.into();
                primitive
            })
            .collect();
        let bytes = serde_json::to_vec(&document).unwrap();
        let resources = Resources::Beside { folder: &files.root, confined_to: Some(&files.root) };
        let scene = load_from(&bytes, &Limits::default(), "scene", resources).expect("textures never stop a shadow");
        assert_eq!(scene.textures.len(), 4, "{:?}", scene.warnings);
        assert!(scene.materials.iter().all(|m| m.base_color == [0.5, 0.25, 0.125, 1.0]));
        assert_eq!(scene.materials.iter().filter(|m| m.texture.is_none()).count(), 4);
        let said = |uri: &str, what: &str| {
            assert!(
                scene.warnings.iter().any(|w| w.contains(&format!("(`{uri}`)")) && w.contains(what)),
                "{uri}: {what}: {:?}",
                scene.warnings
            )
        };
        said("D:\\models\\sub\\wood.png", "read from `wood.png`");
        said(".\\sub\\wood.png", "read from `./sub/wood.png`");
        said("//sub/wood.png", "read from `sub/wood.png`");
        said("missing.png", "is not used");
        said("paint.tga", "PNG, a JPEG or an OpenEXR");
        said("../outside.png", "outside the directory");
        said("Procedural,num=0,type=Voronoi", "is not used");
        assert!(!scene.warnings.iter().any(|w| w.contains("(`sub/wood.png`)")), "read as written: nothing to say");
        // The name alone is read beside the document only, never above it.
        assert!(exporter_spellings("D:\\x\\..\\..").iter().all(|p| p.components().all(|c| matches!(c, Component::Normal(_)))));

        // `penumbra submit` packs what it can embed (its user's own files: `..` too) and leaves
        // the rest to the same warnings.
        let packed = pack(&bytes, &files.root, &Limits::default(), "scene").unwrap();
        let uploaded = load(&packed, &Limits::default(), "scene").unwrap();
        assert_eq!(uploaded.textures.len(), 5, "{:?}", uploaded.warnings);
        assert!(uploaded.warnings.iter().any(|w| w.contains("(`missing.png`)") && w.contains("self-contained")), "{:?}", uploaded.warnings);

        // Geometry is another matter: a missing buffer is refused, naming it.
        let error = files.load("gone.bin", true, &Limits::default()).unwrap_err();
        assert!(error.message.contains("`gone.bin`"), "{}", error.message);
    }

    /// An exporter that writes a Latin-1 name into the JSON (assimp's OBJ `regr01`): read,
    /// the name's byte replaced, and said; in a GLB and in a `.gltf`.
    #[test]
    fn json_that_is_not_utf8_is_read_with_its_bad_bytes_replaced_and_said() {
        let (mut document, bin) = height_field(3, 1);
        document["nodes"][0]["name"] = "caf\u{e9}".into();
        let latin1 = |json: Vec<u8>| -> Vec<u8> {
            let at = json.windows(2).position(|w| w == "é".as_bytes()).expect("the name");
            [&json[..at], &[0xE9u8][..], &json[at + 2..]].concat()
        };
        let glb_json = latin1(serde_json::to_vec(&document).unwrap());
        let mut padded = glb_json.clone();
        padded.resize(padded.len().next_multiple_of(4), b' ');
        let glb_bytes = [
            &b"glTF"[..],
            &2u32.to_le_bytes(),
            &((20 + padded.len() + 8 + bin.len()) as u32).to_le_bytes(),
            &(padded.len() as u32).to_le_bytes(),
            b"JSON",
            &padded,
            &(bin.len() as u32).to_le_bytes(),
            b"BIN\0",
            &bin,
        ]
        .concat();
        let scene = load(&glb_bytes, &Limits::default(), "scene").expect("repaired");
        assert!(scene.warnings.iter().any(|w| w.contains("UTF-8")), "{:?}", scene.warnings);
        assert_eq!(scene.objects[0], "caf\u{fffd}");
        assert_eq!(scene.triangle_count(), 8);
        let mut embedded = document.clone();
        embedded["buffers"][0]["uri"] =
            format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin)).into();
        let scene = load(&latin1(serde_json::to_vec(&embedded).unwrap()), &Limits::default(), "scene").expect("repaired");
        assert!(scene.warnings.iter().any(|w| w.contains("UTF-8")), "{:?}", scene.warnings);
        // Valid UTF-8 needs no repair, and garbage is still refused.
        assert!(load(&height_field_glb(3, 1), &Limits::default(), "scene").unwrap().warnings.is_empty());
        assert_eq!(load(b"{\"asset\": \xff}", &Limits::default(), "scene").unwrap_err().code, ErrorCode::InvalidAsset);
    }

    #[test]
    fn uris_leading_outside_the_scene_directory_are_refused_naming_the_uri() {
        let files = MultiFile::new("escapes");
        let secret = files.top.join("secret.bin");
        let absolute = secret.display().to_string();
        let file_uri = format!("file://{absolute}");
        let escapes = [
            "../secret.bin",
            "sub/../../secret.bin",
            "%2e%2e/secret.bin",
            "..%2fsecret.bin",
            "link.bin", // a symlink out of the directory
            absolute.as_str(),
            file_uri.as_str(),
            "http://127.0.0.1:1/secret.bin",
            "//127.0.0.1/secret.bin",
            "C:/secret.bin",
        ];
        for uri in escapes {
            let error = files.load(uri, true, &Limits::default()).unwrap_err();
            assert_eq!((error.code, error.field.as_deref()), (ErrorCode::PathNotAllowed, Some("scene")), "{uri}: {}", error.message);
            assert!(error.message.contains(&format!("`{uri}`")), "{uri}: {}", error.message);
        }
        // Unconfined (the CLI reads its user's own files), `..` and symlinks are followed,
        // but absolute, `file:` and network URIs are still not.
        for uri in ["../secret.bin", "link.bin"] {
            files.load(uri, false, &Limits::default()).unwrap_or_else(|e| panic!("{uri}: {e}"));
        }
        for uri in [absolute.as_str(), file_uri.as_str(), "http://127.0.0.1:1/secret.bin"] {
            assert_eq!(files.load(uri, false, &Limits::default()).unwrap_err().code, ErrorCode::PathNotAllowed, "{uri}");
        }
    }
}
