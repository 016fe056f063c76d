//! One self-contained GLB from a `.gltf` and the files it names (what a client uploads).

use std::path::Path;

use super::invalid;
use super::uris::UriReader;
use super::Resources;
use crate::error::{ErrorCode, JobResult};
use crate::job::Limits;

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
