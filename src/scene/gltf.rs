//! glTF 2.0 loading (`.gltf` with embedded `data:` buffers, and `.glb`) into a `Scene`.
//!
//! Every node holding a mesh is one object; ids are the rank of the node's index among the
//! mesh nodes of the scene, so they are stable for a file (contract §1). Only `data:` URIs
//! and the GLB binary chunk are read: the loader never opens a file or a network address
//! named inside a document, whoever sent it.

use std::collections::{BTreeMap, HashMap};
use std::io::Cursor;

use base64::Engine as _;
use glam::{Mat4, Vec2, Vec3};

use super::{fitted_defaults, Material, MeshData, Scene, SceneBuilder, TextureData};
use crate::error::{ErrorCode, JobError, JobResult};
use crate::job::Limits;

/// Loads a glTF or GLB document from bytes. `field` names the job field for errors.
pub fn load(bytes: &[u8], limits: &Limits, field: &str) -> JobResult<Scene> {
    // The gltf crate validates indices into the document, but a hostile file is still
    // untrusted input: a panic anywhere in decoding becomes a clean error for this job.
    match std::panic::catch_unwind(|| load_unchecked(bytes, limits, field)) {
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

fn load_unchecked(bytes: &[u8], limits: &Limits, field: &str) -> JobResult<Scene> {
    check_glb_container(bytes, field)?;
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| invalid(field, format!("not a valid glTF 2.0 document: {e}")))?;
    let buffers = gltf
        .document
        .buffers()
        .map(|buffer| {
            let data = match buffer.source() {
                gltf::buffer::Source::Bin => gltf.blob.clone().ok_or_else(|| invalid(field, "GLB binary chunk missing"))?,
                gltf::buffer::Source::Uri(uri) => decode_data_uri(uri, field)?,
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
        .collect::<JobResult<Vec<_>>>()?;

    // Mesh nodes in traversal order with their world transforms.
    let scene = gltf.document.default_scene().or_else(|| gltf.document.scenes().next());
    let roots: Vec<gltf::Node> = match &scene {
        Some(scene) => scene.nodes().collect(),
        None => gltf.document.nodes().collect(),
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
    let mut mesh_nodes: Vec<usize> = instances.iter().map(|(n, _)| n.index()).collect();
    mesh_nodes.sort_unstable();
    mesh_nodes.dedup();
    let id_of: HashMap<usize, u32> = mesh_nodes.iter().enumerate().map(|(id, &node)| (node, id as u32)).collect();
    instances.sort_by_key(|(n, _)| n.index());

    let mut builder = SceneBuilder::default();
    for &node_index in &mesh_nodes {
        let node = gltf.document.nodes().nth(node_index).expect("index from this document");
        builder.begin_object(node.name().map(str::to_owned).unwrap_or_else(|| format!("node-{node_index}")));
    }
    let mut materials: BTreeMap<Option<usize>, u32> = BTreeMap::new();
    let mut textures: HashMap<usize, usize> = HashMap::new();
    let mut skipped_primitives = 0usize;
    let (mut vertices, mut declared_triangles) = (0u64, 0u64);
    for (node, world) in &instances {
        let object_id = id_of[&node.index()];
        let mesh = node.mesh().expect("mesh nodes only");
        for primitive in mesh.primitives() {
            // Refused from the counts the accessors declare, before a vertex or index is read:
            // a strip of one-byte indices would otherwise grow twelvefold into triangles.
            let declared_vertices = primitive.get(&gltf::Semantic::Positions).map_or(0, |a| a.count() as u64);
            let declared_indices = primitive.indices().map_or(declared_vertices, |a| a.count() as u64);
            declared_triangles += match primitive.mode() {
                gltf::mesh::Mode::Triangles => declared_indices / 3,
                gltf::mesh::Mode::TriangleStrip | gltf::mesh::Mode::TriangleFan => declared_indices.saturating_sub(2),
                _ => 0,
            };
            vertices += declared_vertices;
            if vertices > limits.max_vertices {
                let message = format!("the scene has more than {} vertices (max_vertices)", limits.max_vertices);
                return Err(JobError::field(ErrorCode::LimitExceeded, field, message));
            }
            if declared_triangles > limits.max_triangles {
                let message = format!("the scene has more than {} triangles (max_triangles)", limits.max_triangles);
                return Err(JobError::field(ErrorCode::LimitExceeded, field, message));
            }
            let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let Some(positions) = reader.read_positions() else {
                skipped_primitives += 1;
                continue;
            };
            let positions: Vec<Vec3> = positions.map(Vec3::from).collect();
            let count = positions.len() as u32;
            let flat: Vec<u32> = match reader.read_indices() {
                Some(indices) => indices.into_u32().collect(),
                None => (0..count).collect(),
            };
            let indices = match primitive.mode() {
                gltf::mesh::Mode::Triangles => flat.chunks_exact(3).flatten().copied().collect(),
                gltf::mesh::Mode::TriangleStrip => (2..flat.len())
                    .flat_map(|k| if k % 2 == 0 { [flat[k - 2], flat[k - 1], flat[k]] } else { [flat[k - 1], flat[k - 2], flat[k]] })
                    .collect(),
                gltf::mesh::Mode::TriangleFan => (2..flat.len()).flat_map(|k| [flat[0], flat[k - 1], flat[k]]).collect(),
                _ => {
                    // Points and lines cast no area shadow; they are left out.
                    skipped_primitives += 1;
                    continue;
                }
            };
            let indices: Vec<u32> = indices;
            if indices.iter().any(|&i| i >= count) {
                return Err(invalid(field, format!("mesh {} indexes past its vertices", mesh.index())));
            }
            let normals: Vec<Vec3> = reader.read_normals().map(|n| n.map(Vec3::from).collect()).unwrap_or_default();
            let pbr = primitive.material().pbr_metallic_roughness();
            let texture_info = pbr.base_color_texture();
            let uvs: Vec<Vec2> = texture_info
                .as_ref()
                .and_then(|info| reader.read_tex_coords(info.tex_coord()))
                .map(|uv| uv.into_f32().map(Vec2::from).collect())
                .unwrap_or_default();
            let material_key = primitive.material().index();
            let material = match materials.get(&material_key) {
                Some(&m) => m,
                None => {
                    let texture = match &texture_info {
                        Some(info) => {
                            let image = info.texture().source();
                            let slot = match textures.get(&image.index()) {
                                Some(&slot) => slot,
                                None => {
                                    let data = decode_texture(&image, &buffers, limits, field)?;
                                    let slot = builder.add_texture(data);
                                    textures.insert(image.index(), slot);
                                    slot
                                }
                            };
                            Some(slot)
                        }
                        None => None,
                    };
                    let m = builder.add_material(Material { base_color: pbr.base_color_factor(), texture });
                    materials.insert(material_key, m);
                    m
                }
            };
            let mesh_data = MeshData {
                normals: if normals.len() == positions.len() { normals } else { Vec::new() },
                uvs: if uvs.len() == positions.len() { uvs } else { Vec::new() },
                positions,
                indices,
            };
            builder.add_mesh(object_id, &mesh_data, *world, material);
        }
    }
    if skipped_primitives > 0 {
        tracing::debug!(skipped_primitives, "glTF primitives without triangles were left out");
    }
    if builder.triangle_count() == 0 {
        return Err(invalid(field, "the scene holds no triangles"));
    }
    Ok(builder.finish(fitted_defaults))
}

/// Decodes an RFC 2397 `data:` URI with base64 content; every other URI is refused.
fn decode_data_uri(uri: &str, field: &str) -> JobResult<Vec<u8>> {
    let Some(rest) = uri.strip_prefix("data:") else {
        return Err(invalid(field, "only data: URIs are accepted inside an uploaded scene (no files, no network)"));
    };
    let Some((header, payload)) = rest.split_once(',') else {
        return Err(invalid(field, "malformed data: URI"));
    };
    if !header.ends_with(";base64") {
        return Err(invalid(field, "data: URIs must be base64-encoded"));
    }
    base64::engine::general_purpose::STANDARD.decode(payload.trim()).map_err(|e| invalid(field, format!("bad base64 in data: URI: {e}")))
}

fn decode_texture(image: &gltf::Image, buffers: &[Vec<u8>], limits: &Limits, field: &str) -> JobResult<TextureData> {
    let bytes: Vec<u8> = match image.source() {
        gltf::image::Source::View { view, .. } => {
            let buffer = &buffers[view.buffer().index()];
            buffer
                .get(view.offset()..view.offset() + view.length())
                .ok_or_else(|| invalid(field, "an image's buffer view lies outside its buffer"))?
                .to_vec()
        }
        gltf::image::Source::Uri { uri, .. } => decode_data_uri(uri, field)?,
    };
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| invalid(field, format!("cannot read texture: {e}")))?;
    let mut image_limits = image::Limits::default();
    image_limits.max_image_width = Some(limits.max_texture_dim);
    image_limits.max_image_height = Some(limits.max_texture_dim);
    reader.limits(image_limits);
    let decoded = reader.decode().map_err(|e| invalid(field, format!("cannot decode texture: {e}")))?;
    let rgba = decoded.into_rgba8();
    Ok(TextureData { width: rgba.width(), height: rgba.height(), rgba8: rgba.into_raw() })
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
    glb(&document, &bin)
}

#[cfg(test)]
mod tests {
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
}
