//! The engine's counts for `/v1/stats`, `/metrics` and logs: caches, pools, uploads, device
//! resets — read without ever waiting for a render in progress.

use serde::Serialize;

use super::{Engine, RenderState};
use crate::upload_store::UploadStats;

/// Counts for `/v1/stats` and logs.
#[derive(Debug, Clone, Default, Serialize)]
pub struct EngineStats {
    pub scenes_cached: usize,
    pub scene_cache_hits: u64,
    pub scene_cache_misses: u64,
    pub pipelines: usize,
    pub pipelines_compiled: u64,
    pub targets_created: u64,
    pub targets_reused: u64,
    /// Look-up tables and other resources derived from a job's light, built or reused.
    pub derived_created: u64,
    pub derived_reused: u64,
    /// Readback buffers allocated or taken from the pool.
    pub readbacks_created: u64,
    pub readbacks_reused: u64,
    pub reference_cache_hits: u64,
    pub reference_cache_misses: u64,
    pub uploads: UploadStats,
    /// Times the GPU device was lost and replaced.
    pub device_resets: u64,
}

impl Engine {
    /// The engine's counts. Never waits for a render in progress (a scrape must not block on
    /// a ten-second reference): while the device is busy it answers the counts as of the last
    /// time it was free, with fresh upload figures.
    pub fn stats(&self) -> EngineStats {
        let state = match self.state.try_lock() {
            Ok(state) => state,
            Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => {
                let last = self.last_stats.lock().unwrap_or_else(|p| p.into_inner()).clone();
                return EngineStats { uploads: self.upload_stats(), ..last };
            }
        };
        let stats = self.stats_of(&state);
        *self.last_stats.lock().unwrap_or_else(|p| p.into_inner()) = stats.clone();
        stats
    }

    fn stats_of(&self, state: &RenderState) -> EngineStats {
        let r = &state.renderer;
        let references = self.references.lock().unwrap_or_else(|p| p.into_inner());
        EngineStats {
            scenes_cached: state.scenes.len(),
            scene_cache_hits: state.scenes.hits,
            scene_cache_misses: state.scenes.misses,
            pipelines: r.pipelines.len(),
            pipelines_compiled: r.pipelines.stats.created,
            targets_created: r.textures.stats.created + r.buffers.stats.created,
            targets_reused: r.textures.stats.reused + r.buffers.stats.reused,
            derived_created: r.derived.stats.created,
            derived_reused: r.derived.stats.reused,
            readbacks_created: r.readbacks.stats.created,
            readbacks_reused: r.readbacks.stats.reused,
            reference_cache_hits: references.hits,
            reference_cache_misses: references.misses,
            uploads: self.upload_stats(),
            device_resets: self.device_resets(),
        }
    }
}
