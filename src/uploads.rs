//! Uploaded scenes and light images (DESIGN.md §3): content-addressed — the id is a hash of
//! the bytes, so the same upload twice is one entry and costs nothing the second time — and
//! kept in one least-recently-used store under a byte budget, so memory stays bounded however
//! many assets arrive. A scene counts its CPU copy and the GPU copy it will get (the engine
//! uploads it on first use); an evicted or deleted id answers `not_uploaded`.

use std::collections::HashMap;
use std::sync::Arc;

use sha2::{Digest, Sha256};

use crate::error::{ErrorCode, JobError, JobResult};
use crate::light::LightImage;
use crate::scene::Scene;

/// What an upload is.
#[derive(Clone)]
pub enum Asset {
    Scene(Arc<Scene>),
    Light(Arc<LightImage>),
}

impl Asset {
    /// Bytes the asset holds while cached: CPU copy, plus the GPU copy for a scene.
    pub fn cost(&self) -> u64 {
        match self {
            Asset::Scene(scene) => 2 * scene.gpu_bytes(),
            Asset::Light(image) => u64::from(image.width) * u64::from(image.height) * 16,
        }
    }
}

struct Entry {
    asset: Asset,
    cost: u64,
    last_used: u64,
}

/// Counts for `/v1/stats` and `/metrics`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct UploadStats {
    pub entries: usize,
    pub bytes: u64,
    pub budget_bytes: u64,
    pub hits: u64,
    pub misses: u64,
    pub evictions: u64,
}

pub struct UploadStore {
    entries: HashMap<String, Entry>,
    budget: u64,
    used: u64,
    clock: u64,
    stats: UploadStats,
}

/// The content address of `bytes`: the first 128 bits of their SHA-256, in hex, with a prefix
/// naming the kind (a scene and a light never share an id).
pub fn content_id(kind: &str, bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    let hex: String = digest[..16].iter().map(|b| format!("{b:02x}")).collect();
    format!("{kind}-{hex}")
}

impl UploadStore {
    pub fn new(budget: u64) -> Self {
        Self { entries: HashMap::new(), budget, used: 0, clock: 0, stats: UploadStats { budget_bytes: budget, ..Default::default() } }
    }

    /// Whether `id` is stored (and marks it used), for an upload of the same bytes.
    pub fn touch(&mut self, id: &str) -> bool {
        self.clock += 1;
        match self.entries.get_mut(id) {
            Some(entry) => {
                entry.last_used = self.clock;
                true
            }
            None => false,
        }
    }

    /// Stores `asset` under `id`, evicting the least recently used until it fits. Returns the
    /// ids evicted (their GPU copies must go too). An asset larger than the whole budget is
    /// refused.
    pub fn insert(&mut self, id: String, asset: Asset) -> JobResult<Vec<String>> {
        let cost = asset.cost();
        if cost > self.budget {
            return Err(JobError::field(
                ErrorCode::LimitExceeded,
                "body",
                format!("the asset needs {cost} bytes of cache, more than the cache budget of {} bytes", self.budget),
            ));
        }
        let mut evicted = Vec::new();
        while self.used + cost > self.budget {
            let Some(oldest) = self.entries.iter().min_by_key(|(_, e)| e.last_used).map(|(k, _)| k.clone()) else {
                break;
            };
            self.remove(&oldest);
            self.stats.evictions += 1;
            evicted.push(oldest);
        }
        self.clock += 1;
        self.used += cost;
        self.entries.insert(id, Entry { asset, cost, last_used: self.clock });
        Ok(evicted)
    }

    /// The asset under `id`, counted as a hit or a miss.
    pub fn get(&mut self, id: &str) -> Option<Asset> {
        self.clock += 1;
        match self.entries.get_mut(id) {
            Some(entry) => {
                entry.last_used = self.clock;
                self.stats.hits += 1;
                Some(entry.asset.clone())
            }
            None => {
                self.stats.misses += 1;
                None
            }
        }
    }

    pub fn contains(&self, id: &str) -> bool {
        self.entries.contains_key(id)
    }

    pub fn remove(&mut self, id: &str) -> bool {
        match self.entries.remove(id) {
            Some(entry) => {
                self.used -= entry.cost;
                true
            }
            None => false,
        }
    }

    pub fn stats(&self) -> UploadStats {
        UploadStats { entries: self.entries.len(), bytes: self.used, ..self.stats }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn light(side: u32) -> Asset {
        Asset::Light(Arc::new(LightImage::from_fn(side, side, |_, _| [1.0; 4])))
    }

    #[test]
    fn ids_follow_the_content_and_the_kind() {
        assert_eq!(content_id("scene", b"abc"), content_id("scene", b"abc"));
        assert_ne!(content_id("scene", b"abc"), content_id("scene", b"abd"));
        assert_ne!(content_id("scene", b"abc"), content_id("light", b"abc"));
        assert_eq!(content_id("light", b"").len(), "light-".len() + 32);
    }

    #[test]
    fn the_least_recently_used_goes_when_the_budget_is_full() {
        // Each 8×8 light costs 1 KiB; the budget holds three.
        let mut store = UploadStore::new(3 * 1024);
        for id in ["a", "b", "c"] {
            assert!(store.insert(id.into(), light(8)).unwrap().is_empty());
        }
        assert!(store.get("a").is_some());
        // "b" is now the least recently used.
        assert_eq!(store.insert("d".into(), light(8)).unwrap(), vec!["b".to_owned()]);
        assert!(store.get("b").is_none() && store.contains("a") && store.contains("d"));
        let stats = store.stats();
        assert_eq!((stats.entries, stats.bytes, stats.evictions, stats.hits, stats.misses), (3, 3 * 1024, 1, 1, 1));
        assert!(store.remove("a") && !store.remove("a"));
        assert_eq!(store.stats().bytes, 2 * 1024);
        // Larger than the whole budget: refused, nothing evicted.
        assert_eq!(store.insert("huge".into(), light(64)).unwrap_err().code, ErrorCode::LimitExceeded);
        assert_eq!(store.stats().entries, 2);
    }
}
