//! Checks and repairs of a glTF or GLB file before the gltf crate reads it: the GLB
//! container's lengths, JSON that is not UTF-8, scenes without `nodes`.

use super::invalid;
use crate::error::JobResult;

/// Checks a GLB container's header and chunk lengths against the bytes there are (glTF 2.0
/// §4.4) before the gltf crate reads them: its parser subtracts before it compares (a declared
/// length under 12 underflows; found by `cargo fuzz`, kept as a regression test).
pub(super) fn check_glb_container(bytes: &[u8], field: &str) -> JobResult<()> {
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

/// Parses the document, refusing one that requires an extension, then validates its indices.
/// Answers with it what was repaired to read it (for the scene's warnings).
pub(super) fn parse_document(bytes: &[u8], field: &str) -> JobResult<(gltf::Gltf, Option<&'static str>)> {
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
