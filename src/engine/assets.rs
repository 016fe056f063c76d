//! The assets a job names — scenes and light images, built in, uploaded or read from disk —
//! found in the engine's caches or loaded into them: the path policy that decides which files
//! may be read, cache keys that change whenever an asset may have, and the GPU copies of
//! scenes.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::{Engine, RenderState};
use crate::error::{ErrorCode, JobError, JobResult};
use crate::gpu::scene::GpuScene;
use crate::job::{AssetRef, SceneRef};
use crate::light::LightImage;
use crate::scene::{self, builtin, Shape};
use crate::timing::Timings;
use crate::upload_store::{Asset, Kind};

/// The triangles a terrain is built with for its shape alone (`Engine::scene_shape`): its
/// bounds are those of the same landscape at any count, to within its grid's step.
const COARSE_TERRAIN_TRIANGLES: u64 = 20_000;

/// Where `{"path": ...}` assets may be read from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PathPolicy {
    /// Any path (the CLI: the user reads their own files).
    Any,
    /// Only files inside this directory, after resolving symlinks (`serve --scene-dir`).
    Under(PathBuf),
    /// No paths at all (`serve` without `--scene-dir`).
    Deny,
}

impl Engine {
    /// Finds a scene in the cache or loads it (with its floor) and uploads it to the GPU.
    pub(super) fn scene(&self, state: &mut RenderState, scene: &SceneRef, timings: &mut Timings) -> JobResult<Arc<GpuScene>> {
        let key = self.scene_key(scene)?;
        let asset = &scene.asset;
        self.prune_gone_uploads(state);
        if let Some(scene) = state.scenes.get(&key) {
            timings.scene_cached = true;
            return Ok(scene);
        }
        let loaded = match asset {
            AssetRef::Builtin { name, params } => Arc::new(builtin::build(name, params, "scene", &self.limits)?),
            AssetRef::Path(path) => {
                let (resolved, bytes) = self.read_path(path, "scene.path")?;
                // The document's relative URIs are read from beside it, inside the same
                // directory as the document itself (contract §3).
                let root = match &self.paths {
                    PathPolicy::Under(dir) => Some(std::fs::canonicalize(dir).map_err(|_| not_readable("scene.path"))?),
                    PathPolicy::Any | PathPolicy::Deny => None,
                };
                let folder = resolved.parent().unwrap_or(Path::new("/"));
                let resources = scene::gltf::Resources::Beside { folder, confined_to: root.as_deref() };
                Arc::new(scene::gltf::load_from(&bytes, &self.limits, "scene", resources)?)
            }
            AssetRef::Id(id) => match self.uploaded(Kind::Scene, id, "scene.id")? {
                Asset::Scene(scene) => scene,
                Asset::Light(_) => return Err(not_uploaded(id, "scene.id")),
            },
        };
        let loaded = match &scene.floor {
            Some(floor) => Arc::new(loaded.with_floor(floor)),
            None => loaded,
        };
        let gpu = state.renderer.gpu().clone();
        let uploaded = GpuScene::upload(&gpu, &loaded, state.renderer.material_layout()).map_err(|error| {
            tracing::warn!(%error, "a scene failed to upload to the GPU");
            let first_line = error.to_string().lines().find(|l| !l.trim().is_empty()).unwrap_or("").trim().to_owned();
            JobError::field(
                ErrorCode::LimitExceeded,
                "scene",
                format!("the scene does not fit on this GPU ({}): {first_line}", gpu.adapter.name),
            )
        })?;
        let uploaded = Arc::new(uploaded);
        timings.scene_upload_bytes = uploaded.bytes;
        state.scenes.insert(key, uploaded.clone());
        Ok(uploaded)
    }

    /// Finds a light image in the cache or decodes it.
    pub(super) fn light_image(&self, state: &mut RenderState, asset: &AssetRef) -> JobResult<Arc<LightImage>> {
        let key = self.asset_key(asset, Kind::Light, "light.image")?;
        if let Some(image) = state.lights.get(&key) {
            return Ok(image);
        }
        let image = match asset {
            AssetRef::Builtin { name, params } => Arc::new(LightImage::builtin(name, params, "light.image")?),
            AssetRef::Path(path) => {
                let (_, bytes) = self.read_path(path, "light.image.path")?;
                Arc::new(LightImage::decode(&bytes, self.limits.max_light_image_dim, "light.image")?)
            }
            AssetRef::Id(id) => match self.uploaded(Kind::Light, id, "light.image.id")? {
                Asset::Light(image) => image,
                Asset::Scene(_) => return Err(not_uploaded(id, "light.image.id")),
            },
        };
        state.lights.insert(key, image.clone());
        Ok(image)
    }

    /// What a job's predictions need of its scene (its triangles, where it lies, its default
    /// view: `scene::Shape`) where that is known without loading a file or waiting for the
    /// renderer: a built-in's (built once, then remembered) or an upload's; `None` for a path
    /// (what `auto` and estimates then assume: `model::UNKNOWN_TRIANGLES`, whole maps).
    pub fn scene_shape(&self, scene: &SceneRef) -> Option<Shape> {
        let floor = scene.floor.as_ref();
        match &scene.asset {
            AssetRef::Builtin { name, params } => {
                let key = self.asset_key(&scene.asset, Kind::Scene, "scene").ok()?;
                let mut known = self.builtin_shapes.lock().unwrap_or_else(|p| p.into_inner());
                if let Some(shape) = known.get(&key) {
                    return Some(shape.clone().on(floor));
                }
                // A terrain's count is its parameter, and its bounds barely depend on it: a
                // fuzzer's ten million triangles are not built to be predicted.
                let shape = match builtin::parse(name, params, "scene", &self.limits).ok()? {
                    builtin::Builtin::Terrain { triangles, seed } => {
                        let coarse = builtin::Builtin::Terrain { triangles: triangles.min(COARSE_TERRAIN_TRIANGLES), seed };
                        Shape { triangles, ..builtin::build_parsed(coarse).shape(None) }
                    }
                    _ => builtin::build(name, params, "scene", &self.limits).ok()?.shape(None),
                };
                // A handful of built-in variants in practice; bounded all the same.
                if known.len() >= 256 {
                    known.clear();
                }
                known.insert(key, shape.clone());
                Some(shape.on(floor))
            }
            AssetRef::Id(id) => match self.uploaded(Kind::Scene, id, "scene.id").ok()? {
                Asset::Scene(loaded) => Some(loaded.shape(floor)),
                Asset::Light(_) => None,
            },
            AssetRef::Path(_) => None,
        }
    }

    /// The cache key of a job's scene: its asset's, and its floor.
    pub(super) fn scene_key(&self, scene: &SceneRef) -> JobResult<String> {
        let key = self.asset_key(&scene.asset, Kind::Scene, "scene")?;
        Ok(match &scene.floor {
            Some(floor) => format!("{key}:floor:{:?}:{}", floor.albedo, floor.margin),
            None => key,
        })
    }

    /// A cache key that changes whenever the asset's content may have changed.
    pub(super) fn asset_key(&self, asset: &AssetRef, kind: Kind, field: &str) -> JobResult<String> {
        match asset {
            AssetRef::Builtin { name, params } => Ok(format!("builtin:{name}:{}", serde_json::Value::Object(params.clone()))),
            AssetRef::Id(id) if self.holds_upload(kind, id) => Ok(format!("id:{id}")),
            AssetRef::Id(id) => Err(not_uploaded(id, &format!("{field}.id"))),
            AssetRef::Path(path) => {
                let resolved = self.resolve_path(path, &format!("{field}.path"))?;
                let meta = std::fs::metadata(&resolved).map_err(|_| not_readable(&format!("{field}.path")))?;
                let mut key = format!("path:{}:{}", resolved.display(), stamp(&meta));
                // A .gltf's files change without it: each one it names is part of the key.
                if kind == Kind::Scene && resolved.extension().is_some_and(|e| e.eq_ignore_ascii_case("gltf")) {
                    let bytes = std::fs::read(&resolved).map_err(|_| not_readable(&format!("{field}.path")))?;
                    let folder = resolved.parent().unwrap_or(Path::new("/"));
                    for file in scene::gltf::files_named(&bytes, folder) {
                        let stamp = std::fs::metadata(&file).map_or_else(|_| "missing".to_owned(), |meta| stamp(&meta));
                        key.push_str(&format!("|{}:{stamp}", file.display()));
                    }
                }
                Ok(key)
            }
        }
    }

    /// Applies the path policy: canonical path inside the allowed directory, or an error
    /// that does not reveal whether the file exists.
    pub(super) fn resolve_path(&self, path: &Path, field: &str) -> JobResult<PathBuf> {
        match &self.paths {
            PathPolicy::Deny => {
                Err(JobError::field(ErrorCode::PathNotAllowed, field, "this server reads no paths (start it with --scene-dir)"))
            }
            PathPolicy::Any => std::fs::canonicalize(path).map_err(|_| not_readable(field)),
            PathPolicy::Under(dir) => {
                let dir = std::fs::canonicalize(dir).map_err(|_| not_readable(field))?;
                let joined = if path.is_absolute() { path.to_path_buf() } else { dir.join(path) };
                match std::fs::canonicalize(&joined) {
                    Ok(resolved) if resolved.starts_with(&dir) && resolved.is_file() => Ok(resolved),
                    _ => Err(not_readable(field)),
                }
            }
        }
    }

    /// Reads a file the path policy allows; answers its canonical path with its bytes.
    fn read_path(&self, path: &Path, field: &str) -> JobResult<(PathBuf, Vec<u8>)> {
        let resolved = self.resolve_path(path, field)?;
        let meta = std::fs::metadata(&resolved).map_err(|_| not_readable(field))?;
        if meta.len() > self.limits.max_body_bytes as u64 {
            return Err(JobError::field(ErrorCode::LimitExceeded, field, format!("the file exceeds {} bytes", self.limits.max_body_bytes)));
        }
        let bytes = std::fs::read(&resolved).map_err(|_| not_readable(field))?;
        Ok((resolved, bytes))
    }
}

/// A file's length and modification time: they change when its content does.
fn stamp(meta: &std::fs::Metadata) -> String {
    let modified = meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).map_or(0, |d| d.as_nanos());
    format!("{}:{modified}", meta.len())
}

fn not_readable(field: &str) -> JobError {
    JobError::field(ErrorCode::PathNotAllowed, field, "no readable file at this path in the allowed directory")
}

/// The error for an id this server does not hold (never uploaded, evicted or deleted).
pub(super) fn not_uploaded(id: &str, field: &str) -> JobError {
    JobError::field(
        ErrorCode::NotUploaded,
        field,
        format!("no uploaded asset with id `{id}` of this kind on this server (never uploaded, evicted or deleted); upload it again"),
    )
}
