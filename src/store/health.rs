//! The job store as the server uses it: `Store` runs each blocking store call off the async
//! workers and learns from its outcome whether the store answers; `StoreHealth` holds that
//! state, the room left on a local store's disk and the bytes promised to accepted jobs'
//! results, for admission (503 `store_unavailable`, 507 `insufficient_storage`), readiness,
//! `/v1/stats` and `/metrics`. A probe asks the store every second, so recovery is noticed
//! without a request, and drops old results when the disk runs below its margin.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use super::{JobStore, StoreError, StoreResult};

/// How often the probe asks the store whether it answers and measures its disk.
pub const PROBE_EVERY: Duration = Duration::from_secs(1);

/// What is known of the store: reachable or not, and its disk.
pub struct StoreHealth {
    kind: &'static str,
    available: AtomicBool,
    /// Bytes free on a local store's disk as last measured (`u64::MAX`: not limited by one).
    free_bytes: AtomicU64,
    /// The margin kept free on that disk: results are dropped, and jobs refused, to keep it.
    min_free_bytes: u64,
    /// Bytes promised to the results of accepted jobs not yet stored.
    reserved_bytes: AtomicU64,
    /// Times the store went from answering to not answering.
    outages: AtomicU64,
    /// Finished jobs whose outcome waits to be stored (retried while the store cannot take it).
    waiting_writes: AtomicU64,
}

/// The store's state as `/v1/stats` reports it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StoreStatus {
    /// `embedded` or `redis`.
    pub kind: &'static str,
    /// Whether the last call (or probe) reached the store.
    pub available: bool,
    /// Bytes free on the store's disk (absent: not limited by a local disk).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub free_bytes: Option<u64>,
    pub min_free_bytes: u64,
    pub reserved_bytes: u64,
    /// Whether the disk is above its margin: new submitted jobs can be stored.
    pub room: bool,
    pub outages: u64,
    /// Finished jobs whose outcome waits for the store (retried until it takes them).
    pub waiting_writes: u64,
}

impl StoreHealth {
    pub fn new(kind: &'static str, min_free_bytes: u64) -> Self {
        Self {
            kind,
            available: AtomicBool::new(true),
            free_bytes: AtomicU64::new(u64::MAX),
            min_free_bytes,
            reserved_bytes: AtomicU64::new(0),
            outages: AtomicU64::new(0),
            waiting_writes: AtomicU64::new(0),
        }
    }

    /// Learns from a store call's outcome: an answer means the store is up, a transient
    /// failure that it is down (logged once per outage, not per call).
    pub fn observe<T>(&self, result: &StoreResult<T>) {
        match result {
            Ok(_) | Err(StoreError::Exists(_) | StoreError::Other(_)) => self.set_available(true, None),
            Err(error @ StoreError::Unavailable(_)) => self.set_available(false, Some(error)),
            Err(StoreError::Full(_)) => {
                // It answered, without room: no room until the probe measures some.
                self.set_available(true, None);
                if self.free_bytes.load(Ordering::Relaxed) != u64::MAX {
                    self.free_bytes.store(0, Ordering::Relaxed);
                }
            }
        }
    }

    fn set_available(&self, up: bool, error: Option<&StoreError>) {
        let was = self.available.swap(up, Ordering::SeqCst);
        if was && !up {
            self.outages.fetch_add(1, Ordering::Relaxed);
            let error = error.map(ToString::to_string).unwrap_or_default();
            tracing::warn!(store = self.kind, %error, "job store unavailable: new submitted jobs get 503 store_unavailable; finished results wait for it");
        } else if !was && up {
            tracing::info!(store = self.kind, "job store available again");
        }
    }

    pub fn available(&self) -> bool {
        self.available.load(Ordering::SeqCst)
    }

    /// Whether the store's disk is above its margin (always, for a store without one).
    pub fn room(&self) -> bool {
        let free = self.free_bytes.load(Ordering::Relaxed);
        free == u64::MAX || free >= self.min_free_bytes
    }

    pub fn status(&self) -> StoreStatus {
        let free = self.free_bytes.load(Ordering::Relaxed);
        StoreStatus {
            kind: self.kind,
            available: self.available(),
            free_bytes: (free != u64::MAX).then_some(free),
            min_free_bytes: self.min_free_bytes,
            reserved_bytes: self.reserved_bytes.load(Ordering::Relaxed),
            room: self.room(),
            outages: self.outages.load(Ordering::Relaxed),
            waiting_writes: self.waiting_writes.load(Ordering::Relaxed),
        }
    }

    /// Counts a finished job's outcome as waiting for the store until the guard drops.
    pub fn waiting_write(self: &Arc<Self>) -> WaitingWrite {
        self.waiting_writes.fetch_add(1, Ordering::Relaxed);
        WaitingWrite(self.clone())
    }
}

/// One outcome waiting for the store (see `StoreHealth::waiting_write`).
pub struct WaitingWrite(Arc<StoreHealth>);

impl Drop for WaitingWrite {
    fn drop(&mut self) {
        self.0.waiting_writes.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Bytes promised to one accepted job's result, given back when it is dropped (the result
/// stored, or the job failed).
pub struct Reservation {
    health: Arc<StoreHealth>,
    bytes: u64,
}

impl Drop for Reservation {
    fn drop(&mut self) {
        self.health.reserved_bytes.fetch_sub(self.bytes, Ordering::Relaxed);
    }
}

/// The durable store with its health: the server's one way in.
#[derive(Clone)]
pub struct Store {
    inner: Arc<dyn JobStore>,
    health: Arc<StoreHealth>,
}

impl Store {
    /// `min_free_bytes`: the margin kept free on a local store's disk.
    pub fn new(inner: Arc<dyn JobStore>, kind: &'static str, min_free_bytes: u64) -> Self {
        Self { inner, health: Arc::new(StoreHealth::new(kind, min_free_bytes)) }
    }

    pub fn health(&self) -> &Arc<StoreHealth> {
        &self.health
    }

    /// Whether the store is the queue shared by several replicas.
    pub fn shared(&self) -> bool {
        self.inner.shared()
    }

    /// The store itself, for what needs no answer (the heartbeat's period).
    pub fn blocking(&self) -> &dyn JobStore {
        self.inner.as_ref()
    }

    /// One store call from code already on the blocking pool, learning from its outcome.
    pub fn call_blocking<T>(&self, f: impl FnOnce(&dyn JobStore) -> StoreResult<T>) -> StoreResult<T> {
        let result = f(self.inner.as_ref());
        self.health.observe(&result);
        result
    }

    /// Runs one blocking store call on the blocking pool and learns from its outcome.
    pub async fn call<T: Send + 'static>(&self, f: impl FnOnce(&dyn JobStore) -> StoreResult<T> + Send + 'static) -> StoreResult<T> {
        let store = self.clone();
        tokio::task::spawn_blocking(move || store.call_blocking(f))
            .await
            .unwrap_or_else(|e| Err(StoreError::Other(anyhow::anyhow!("the store task failed: {e}"))))
    }

    /// Promises room for a result of `bytes` to a job being admitted: refused (`Full`) when
    /// the store's disk cannot take it, the results already promised and the margin, even
    /// after dropping the oldest stored results. Stores without a disk of their own always
    /// promise.
    pub async fn reserve(&self, bytes: u64) -> StoreResult<Reservation> {
        let health = &self.health;
        let total = health.reserved_bytes.fetch_add(bytes, Ordering::Relaxed) + bytes;
        let reservation = Reservation { health: self.health.clone(), bytes };
        let wanted = total.saturating_add(health.min_free_bytes);
        let Some(free) = self.call(|s| Ok(s.free_bytes())).await? else { return Ok(reservation) };
        if free >= wanted {
            return Ok(reservation);
        }
        let dropped = self.call(move |s| s.make_room(wanted)).await?;
        if dropped > 0 {
            tracing::info!(dropped, "dropped the oldest stored results to make room for a new job");
        }
        let free = self.call(|s| Ok(s.free_bytes())).await?.unwrap_or(u64::MAX);
        health.free_bytes.store(free, Ordering::Relaxed);
        if free >= wanted {
            return Ok(reservation);
        }
        Err(StoreError::Full(format!(
            "the data directory has {free} bytes free: not enough for this job's images (up to {bytes} bytes: its result, and a \
             progressive job's rounds), the {} bytes promised to accepted jobs and the {}-byte margin",
            total - bytes,
            health.min_free_bytes
        )))
    }

    /// A promise for a job accepted before a restart: counted, never refused.
    pub fn reserve_accepted(&self, bytes: u64) -> Reservation {
        self.health.reserved_bytes.fetch_add(bytes, Ordering::Relaxed);
        Reservation { health: self.health.clone(), bytes }
    }

    /// Asks the store whether it answers (reopening or reconnecting it), measures its disk,
    /// and drops the oldest results while the disk is below its margin.
    pub async fn probe(&self) {
        let _ = self.call(|s| s.ping()).await;
        let Ok(Some(mut free)) = self.call(|s| Ok(s.free_bytes())).await else { return };
        let wanted = self.health.min_free_bytes.saturating_add(self.health.reserved_bytes.load(Ordering::Relaxed));
        if free < wanted && self.health.available() {
            if let Ok(dropped @ 1..) = self.call(move |s| s.make_room(wanted)).await {
                tracing::info!(
                    dropped,
                    free,
                    wanted,
                    "the data directory ran below its free-space margin: dropped the oldest stored results"
                );
                free = self.call(|s| Ok(s.free_bytes())).await.ok().flatten().unwrap_or(free);
            }
        }
        self.health.free_bytes.store(free, Ordering::Relaxed);
    }

    /// Probes the store every `PROBE_EVERY`, for as long as the process runs.
    pub fn spawn_probe(&self) {
        let store = self.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(PROBE_EVERY);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tick.tick().await;
                store.probe().await;
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_outage_is_counted_once_and_ends_with_the_next_answer() {
        let health = StoreHealth::new("redis", 0);
        let down: StoreResult<()> = Err(StoreError::Unavailable("connection refused".into()));
        health.observe(&down);
        health.observe(&down);
        assert!(!health.available());
        // A record that does not parse is an answer: the store is up.
        health.observe::<()>(&Err(StoreError::Other(anyhow::anyhow!("bad record"))));
        assert!(health.available());
        health.observe(&down);
        health.observe(&Ok(()));
        assert_eq!((health.available(), health.status().outages), (true, 2));
    }

    #[test]
    fn a_full_disk_has_no_room_until_measured_again() {
        let health = StoreHealth::new("embedded", 100);
        assert!(health.room(), "unmeasured: not limited");
        health.free_bytes.store(1000, Ordering::Relaxed);
        health.observe::<()>(&Err(StoreError::Full("no space left on device".into())));
        assert!(health.available() && !health.room());
        health.free_bytes.store(1000, Ordering::Relaxed);
        assert!(health.room());
        assert_eq!(health.status().free_bytes, Some(1000));
    }
}
