//! The files a glTF document names by URI (contract §3): `data:` URIs, files beside a
//! document from disk, confined to `--scene-dir` on the server, exporters' spellings of them;
//! never an absolute path, a `file:` URI or a network address.

use std::path::{Component, Path, PathBuf};

use base64::Engine as _;

use super::{invalid, Resources};
use crate::error::{ErrorCode, JobError, JobResult};
use crate::job::Limits;

/// Every buffer's bytes: the GLB binary chunk or what its URI names, each within
/// `max_body_bytes` and at least as long as it declares.
pub(super) fn read_buffers(gltf: &gltf::Gltf, limits: &Limits, field: &str, uris: &UriReader<'_>) -> JobResult<Vec<Vec<u8>>> {
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
pub(super) struct UriReader<'a> {
    pub(super) resources: Resources<'a>,
    pub(super) limits: &'a Limits,
    pub(super) field: &'a str,
    pub(super) read: std::cell::Cell<u64>,
}

impl UriReader<'_> {
    pub(super) fn read(&self, uri: &str) -> JobResult<Vec<u8>> {
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
    pub(super) fn read_image(&self, uri: &str) -> JobResult<(Vec<u8>, Option<PathBuf>)> {
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

    pub(super) fn refused(&self, uri: &str, why: &str) -> JobError {
        JobError::field(ErrorCode::PathNotAllowed, self.field, format!("URI `{uri}`: {why}"))
    }

    /// Reads `relative` (what `uri` names) from beside the document, inside the directory the
    /// server reads and within the document's budget.
    pub(super) fn read_relative(&self, relative: &Path, uri: &str) -> JobResult<Vec<u8>> {
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
pub(super) fn exporter_spellings(uri: &str) -> Vec<PathBuf> {
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
pub(super) fn relative_uri_path(uri: &str) -> Result<PathBuf, &'static str> {
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
pub(super) fn lexical_join(folder: &Path, relative: &Path) -> Option<PathBuf> {
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
pub(super) fn decode_data_uri(rest: &str, field: &str) -> JobResult<Vec<u8>> {
    let Some((header, payload)) = rest.split_once(',') else {
        return Err(invalid(field, "malformed data: URI"));
    };
    if !header.ends_with(";base64") {
        return Err(invalid(field, "data: URIs must be base64-encoded"));
    }
    base64::engine::general_purpose::STANDARD.decode(payload.trim()).map_err(|e| invalid(field, format!("bad base64 in data: URI: {e}")))
}
