//! Uploaded scenes and light images (contract §3): content-addressed — the id is a hash of
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

/// The two kinds of upload; each has its own ids (`/v1/scenes/{id}`, `/v1/lights/{id}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    Scene,
    Light,
}

impl Asset {
    pub fn kind(&self) -> Kind {
        match self {
            Asset::Scene(_) => Kind::Scene,
            Asset::Light(_) => Kind::Light,
        }
    }

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
    /// Bytes of the upload as it came (`HEAD`'s `Content-Length`).
    size: u64,
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
    entries: HashMap<(Kind, String), Entry>,
    budget: u64,
    used: u64,
    clock: u64,
    stats: UploadStats,
}

/// The content address of `bytes` (contract §3): the lowercase hex SHA-256, so a client can
/// compute it before uploading and ask whether the server holds it.
pub fn content_id(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether `id` has the shape of a content id (64 lowercase hex digits).
pub fn is_content_id(id: &str) -> bool {
    id.len() == 64 && id.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

impl UploadStore {
    pub fn new(budget: u64) -> Self {
        Self { entries: HashMap::new(), budget, used: 0, clock: 0, stats: UploadStats { budget_bytes: budget, ..Default::default() } }
    }

    /// Whether `id` is stored (and marks it used), for an upload of the same bytes.
    pub fn touch(&mut self, kind: Kind, id: &str) -> bool {
        self.clock += 1;
        match self.entries.get_mut(&(kind, id.to_owned())) {
            Some(entry) => {
                entry.last_used = self.clock;
                true
            }
            None => false,
        }
    }

    /// Stores `asset` under `id`, evicting the least recently used until it fits. Returns the
    /// entries evicted (their GPU copies must go too). An asset larger than the whole budget is
    /// refused.
    pub fn insert(&mut self, id: String, asset: Asset, size: u64) -> JobResult<Vec<(Kind, String)>> {
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
            self.remove(oldest.0, &oldest.1);
            self.stats.evictions += 1;
            evicted.push(oldest);
        }
        self.clock += 1;
        self.used += cost;
        self.entries.insert((asset.kind(), id), Entry { asset, cost, size, last_used: self.clock });
        Ok(evicted)
    }

    /// The asset under `id`, counted as a hit or a miss.
    pub fn get(&mut self, kind: Kind, id: &str) -> Option<Asset> {
        self.clock += 1;
        match self.entries.get_mut(&(kind, id.to_owned())) {
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

    pub fn contains(&self, kind: Kind, id: &str) -> bool {
        self.entries.contains_key(&(kind, id.to_owned()))
    }

    /// The bytes of the upload under `id` as it came, when held.
    pub fn size(&self, kind: Kind, id: &str) -> Option<u64> {
        self.entries.get(&(kind, id.to_owned())).map(|e| e.size)
    }

    pub fn remove(&mut self, kind: Kind, id: &str) -> bool {
        match self.entries.remove(&(kind, id.to_owned())) {
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
        assert_eq!(content_id(b"abc"), content_id(b"abc"));
        assert_ne!(content_id(b"abc"), content_id(b"abd"));
        // The SHA-256 test vector of FIPS 180-2, so clients can compute ids with any tool.
        assert_eq!(content_id(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        assert!(is_content_id(&content_id(b"")) && !is_content_id("BA78") && !is_content_id(&"g".repeat(64)));
    }

    #[test]
    fn the_least_recently_used_goes_when_the_budget_is_full() {
        // Each 8×8 light costs 1 KiB; the budget holds three.
        let mut store = UploadStore::new(3 * 1024);
        for id in ["a", "b", "c"] {
            assert!(store.insert(id.into(), light(8), 0).unwrap().is_empty());
        }
        assert!(store.get(Kind::Light, "a").is_some());
        assert!(store.get(Kind::Scene, "a").is_none(), "ids are per kind");
        // "b" is now the least recently used.
        assert_eq!(store.insert("d".into(), light(8), 0).unwrap(), vec![(Kind::Light, "b".to_owned())]);
        assert!(store.get(Kind::Light, "b").is_none() && store.contains(Kind::Light, "a") && store.contains(Kind::Light, "d"));
        let stats = store.stats();
        assert_eq!((stats.entries, stats.bytes, stats.evictions, stats.hits, stats.misses), (3, 3 * 1024, 1, 1, 2));
        assert!(store.remove(Kind::Light, "a") && !store.remove(Kind::Light, "a"));
        assert_eq!(store.stats().bytes, 2 * 1024);
        // Larger than the whole budget: refused, nothing evicted.
        assert_eq!(store.insert("huge".into(), light(64), 0).unwrap_err().code, ErrorCode::LimitExceeded);
        assert_eq!(store.stats().entries, 2);
    }
}
