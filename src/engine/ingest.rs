//! The engine's side of uploads (contract §3): decoding and validating an uploaded scene or
//! light image, keeping it under its content id in the byte-budgeted `UploadStore`, and
//! dropping the GPU copies of uploads that were evicted or deleted.

use std::sync::Arc;

use serde::Serialize;

use super::assets::not_uploaded;
use super::{Engine, RenderState};
use crate::error::JobResult;
use crate::light::LightImage;
use crate::scene;
use crate::upload_store::{content_id, Asset, Kind, UploadStats, UploadStore};

/// What an upload answers: the asset's id, whether this upload stored it (false: the same
/// bytes were already there), what it costs the cache, and a scene's warnings (what penumbra
/// will leave out of it or repaired: `Scene::warnings`).
#[derive(Debug, Clone, Serialize)]
pub struct UploadReceipt {
    pub id: String,
    pub created: bool,
    pub cache_bytes: u64,
    pub warnings: Vec<String>,
}

fn warnings_of(asset: &Asset) -> Vec<String> {
    match asset {
        Asset::Scene(scene) => scene.warnings.clone(),
        Asset::Light(_) => Vec::new(),
    }
}

impl Engine {
    /// Stores a glTF (JSON with `data:` buffers) or GLB scene; validated now, so a bad file
    /// is refused at upload, not at its first render.
    pub fn upload_scene(&self, bytes: &[u8]) -> JobResult<UploadReceipt> {
        self.upload(Kind::Scene, bytes)
    }

    /// Stores a PNG or EXR light image.
    pub fn upload_light(&self, bytes: &[u8]) -> JobResult<UploadReceipt> {
        self.upload(Kind::Light, bytes)
    }

    /// Stores an upload of either kind under its content id (`content_id(bytes)`).
    pub fn upload(&self, kind: Kind, bytes: &[u8]) -> JobResult<UploadReceipt> {
        let id = content_id(bytes);
        if self.lock_uploads().touch(kind, &id) {
            let warnings = self.lock_uploads().get(kind, &id).map(|asset| warnings_of(&asset)).unwrap_or_default();
            return Ok(UploadReceipt { id, created: false, cache_bytes: 0, warnings });
        }
        let asset = match kind {
            Kind::Scene => Asset::Scene(Arc::new(scene::gltf::load(bytes, &self.limits, "body")?)),
            Kind::Light => Asset::Light(Arc::new(LightImage::decode(bytes, self.limits.max_light_image_dim, "body")?)),
        };
        let warnings = warnings_of(&asset);
        if self.lock_uploads().touch(asset.kind(), &id) {
            return Ok(UploadReceipt { id, created: false, cache_bytes: 0, warnings });
        }
        let cache_bytes = asset.cost();
        self.lock_uploads().insert(id.clone(), asset, bytes.len() as u64)?;
        self.prune_if_free();
        Ok(UploadReceipt { id, created: true, cache_bytes, warnings })
    }

    /// Whether the server holds the upload `id` of this kind (`HEAD /v1/scenes/{id}`).
    pub fn holds_upload(&self, kind: Kind, id: &str) -> bool {
        self.lock_uploads().contains(kind, id)
    }

    /// The bytes of the upload `id` as it came, when held (`HEAD`'s `Content-Length`).
    pub fn upload_size(&self, kind: Kind, id: &str) -> Option<u64> {
        self.lock_uploads().size(kind, id)
    }

    /// Removes an upload; false when there was none under `id`.
    pub fn delete_upload(&self, kind: Kind, id: &str) -> bool {
        let removed = self.lock_uploads().remove(kind, id);
        self.prune_if_free();
        removed
    }

    pub fn upload_stats(&self) -> UploadStats {
        self.lock_uploads().stats()
    }

    fn lock_uploads(&self) -> std::sync::MutexGuard<'_, UploadStore> {
        self.uploads.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The uploaded asset under `id`, or `not_uploaded` naming `field`.
    pub(super) fn uploaded(&self, kind: Kind, id: &str, field: &str) -> JobResult<Asset> {
        self.lock_uploads().get(kind, id).ok_or_else(|| not_uploaded(id, field))
    }

    /// Drops the GPU copies of evicted or deleted uploads now when the renderer is free; while
    /// it renders, the next job's `prune_gone_uploads` does (an upload never waits for a render).
    fn prune_if_free(&self) {
        let mut state = match self.state.try_lock() {
            Ok(state) => state,
            Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => return,
        };
        self.prune_gone_uploads(&mut state);
    }

    /// Drops cached copies of uploads that were evicted or deleted: the upload budget counts
    /// them, so they must not outlive their upload. Runs before every scene look-up, so the
    /// GPU copy of a gone upload lasts at most until the next job.
    pub(super) fn prune_gone_uploads(&self, state: &mut RenderState) {
        let uploads = self.lock_uploads();
        state.scenes.retain(|key| key.strip_prefix("id:").is_none_or(|id| uploads.contains(Kind::Scene, id)));
        state.lights.retain(|key| key.strip_prefix("id:").is_none_or(|id| uploads.contains(Kind::Light, id)));
    }
}
