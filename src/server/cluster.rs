//! The service as a whole, seen from any replica: each replica's heartbeat in the shared store
//! (what it is doing, expiring when it dies), the finished jobs of every replica, and the view
//! `/v1/stats` and the dashboard draw from them. Without a shared store the cluster is this
//! daemon alone.

use std::sync::atomic::AtomicU64;
use std::sync::Mutex;
use std::time::Duration;

use super::*;
use crate::job::summary::{latency_by_method, per_minute};
use crate::store::ReplicaReport;

/// Heartbeats a replica may miss before it leaves the cluster view: one lost write (a network
/// blip, a long pause) does not make it vanish.
const MISSED_HEARTBEATS: u32 = 3;

/// Finished jobs the shared store keeps for the cluster view (as this daemon keeps its own).
const CLUSTER_RECENT: usize = RECENT_JOBS;

/// This replica as the cluster knows it: its name, its counts, and how its heartbeat fares.
pub struct Replica {
    pub(super) name: String,
    pub(super) heartbeat_every: Duration,
    succeeded: AtomicU64,
    failed: AtomicU64,
    /// The last heartbeat's outcome: when it was written, or why it could not be.
    heartbeat: Mutex<Heartbeat>,
}

#[derive(Debug, Clone, Default, serde::Serialize)]
struct Heartbeat {
    /// When the last heartbeat was written (None before the first).
    last_unix_ms: Option<u64>,
    /// Why the last one failed (None after a success).
    error: Option<String>,
}

impl Replica {
    pub fn new(name: impl Into<String>, heartbeat_every: Duration) -> Self {
        Self {
            name: name.into(),
            heartbeat_every: heartbeat_every.max(Duration::from_millis(100)),
            succeeded: AtomicU64::new(0),
            failed: AtomicU64::new(0),
            heartbeat: Mutex::new(Heartbeat::default()),
        }
    }

    /// How long a heartbeat names a live replica.
    fn heartbeat_ttl(&self) -> Duration {
        self.heartbeat_every * MISSED_HEARTBEATS
    }

    pub(super) fn count(&self, outcome: &str) {
        let counter = if outcome == "ok" { &self.succeeded } else { &self.failed };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    fn note_heartbeat(&self, result: Result<(), String>) {
        let mut heartbeat = self.heartbeat.lock().unwrap_or_else(|p| p.into_inner());
        match result {
            Ok(()) => *heartbeat = Heartbeat { last_unix_ms: Some(unix_ms()), error: None },
            Err(error) => heartbeat.error = Some(error),
        }
    }

    /// The heartbeat's state for `/readyz`: a failing heartbeat is said there, and the replica
    /// keeps serving and rendering (others merely do not see it in the cluster view).
    pub(super) fn heartbeat_detail(&self) -> Value {
        let heartbeat = self.heartbeat.lock().unwrap_or_else(|p| p.into_inner()).clone();
        json!({"ok": heartbeat.error.is_none(), "last_unix_ms": heartbeat.last_unix_ms, "error": heartbeat.error})
    }
}

impl AppState {
    /// This replica's report of itself, as its heartbeat carries it.
    fn report(&self) -> ReplicaReport {
        ReplicaReport {
            replica: self.replica.name.clone(),
            adapter: self.engine.adapter().name.clone(),
            version: env!("CARGO_PKG_VERSION").to_owned(),
            started_unix_ms: self.started.duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64),
            heartbeat_unix_ms: unix_ms(),
            jobs_in_flight: self.metrics.in_flight().max(0) as u64,
            jobs_queued: self.metrics.queued().max(0) as u64,
            jobs_succeeded: self.replica.succeeded.load(Ordering::Relaxed),
            jobs_failed: self.replica.failed.load(Ordering::Relaxed),
            concurrency: self.queue_config.concurrency,
        }
    }

    /// With a shared store, reports this replica every `--heartbeat-secs` until the daemon
    /// stops, then withdraws it so that it leaves the cluster view at once (a replica that
    /// dies leaves it when its last report expires).
    pub(super) fn spawn_heartbeat(self: &Arc<Self>) {
        let Some(store) = self.shared_store().cloned() else { return };
        let state = self.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(state.replica.heartbeat_every);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            let mut stopping = state.stopping.subscribe();
            loop {
                tokio::select! {
                    _ = tick.tick() => {}
                    _ = stopping.wait_for(|stopping| *stopping) => break,
                }
                let (report, ttl) = (state.report(), state.replica.heartbeat_ttl());
                let result = store.call(move |s| s.announce(&report, ttl)).await.map_err(|e| e.to_string());
                if let Err(error) = &result {
                    if state.replica.heartbeat.lock().unwrap_or_else(|p| p.into_inner()).error.is_none() {
                        tracing::warn!(%error, "cannot write this replica's heartbeat; it serves on, missing from the cluster view");
                    }
                }
                state.replica.note_heartbeat(result);
            }
            let name = state.replica.name.clone();
            if let Err(error) = store.call(move |s| s.withdraw(&name)).await {
                tracing::debug!(%error, "could not withdraw this replica from the cluster view");
            }
        });
    }

    /// Keeps a finished job among the service's recent jobs in a shared store, in the
    /// background: the job's record is what clients read, this only feeds the dashboard.
    pub(super) fn share_finished(&self, summary: &JobSummary) {
        let Some(store) = self.shared_store().cloned() else { return };
        let Ok(runtime) = tokio::runtime::Handle::try_current() else { return };
        let summary = summary.clone();
        runtime.spawn(async move {
            if let Err(error) = store.call(move |s| s.record_finished(&summary, CLUSTER_RECENT)).await {
                tracing::debug!(%error, "could not share a finished job with the cluster view");
            }
        });
    }

    /// The cluster view of `/v1/stats`: the live replicas (`cluster`), and the recent jobs of
    /// all of them (`jobs`) — of this daemon alone without a shared store, or while it cannot
    /// be read.
    pub(super) async fn cluster_view(&self, recent: usize) -> (Value, Value) {
        let local = || (vec![self.report()], self.recent.newest(CLUSTER_RECENT));
        let (scope, error, (replicas, jobs)) = match self.shared_store().cloned() {
            None => ("replica", None, local()),
            Some(store) => {
                let read = store.call(|s| Ok((s.replicas()?, s.recent_finished(CLUSTER_RECENT)?))).await;
                match read {
                    Ok((mut replicas, jobs)) => {
                        // Until its first heartbeat lands, the replica answering is in the view all the same.
                        if !replicas.iter().any(|r| r.replica == self.replica.name) {
                            replicas.push(self.report());
                            replicas.sort_by(|a, b| a.replica.cmp(&b.replica));
                        }
                        ("cluster", None, (replicas, jobs))
                    }
                    Err(error) => ("replica", Some(error.to_string()), local()),
                }
            }
        };
        let cluster = json!({"scope": scope, "error": error, "replicas": replicas});
        let jobs = json!({
            "per_minute": per_minute(&jobs, unix_ms(), Duration::from_secs(60)),
            "by_method": latency_by_method(&jobs),
            "recent": &jobs[..jobs.len().min(recent)],
        });
        (cluster, jobs)
    }
}
