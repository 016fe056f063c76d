//! The durable job store behind `POST /v1/jobs` (issue 10): every accepted job is written
//! before its 202 is answered, and every finished one with its record and image. `JobStore`
//! is the interface; `embedded` keeps it in a file on one machine, `redis` shares it between
//! replicas (a stream with a consumer group as the queue, records and images with a TTL,
//! uploads stored once for all of them).

pub mod embedded;
pub mod redis;

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use serde_json::Value;

pub use embedded::EmbeddedStore;
pub use redis::RedisStore;

use crate::uploads::Kind;

/// Times a job may be started by a daemon that then died before finishing it; the next start
/// fails it with a reason instead of taking a daemon down again and again.
pub const MAX_ATTEMPTS: u32 = 3;

/// A job as the store keeps it.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct StoredJob {
    pub id: String,
    /// `queued`, `running`, `succeeded`, `failed` or `cancelled` (DESIGN.md §3).
    pub status: String,
    /// The job as the client sent it (validated at submission).
    pub job: Value,
    pub submitted_unix_ms: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finished_unix_ms: Option<u64>,
    /// Times a daemon started rendering it.
    pub attempts: u32,
    /// The record `GET /v1/jobs/{id}` answers once it succeeded (timings, counters, quality).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub result: Option<Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<Value>,
    /// Bytes of the stored image (0 until it succeeded, and after the image was dropped).
    #[serde(default)]
    pub image_bytes: u64,
    /// Progress as last reported (shared stores: for readers on other replicas).
    #[serde(default)]
    pub done: u64,
    #[serde(default)]
    pub total: u64,
    /// The queue entry that carries the job (shared stores).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub entry: Option<String>,
    /// The worker (replica and slot) that took it last (shared stores).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worker: Option<String>,
}

impl StoredJob {
    /// A job just accepted: queued, submitted now.
    pub fn queued(id: &str, job: &Value) -> Self {
        Self { id: id.to_owned(), status: "queued".into(), job: job.clone(), submitted_unix_ms: unix_ms(), ..Self::default() }
    }

    pub fn finished(&self) -> bool {
        matches!(self.status.as_str(), "succeeded" | "failed" | "cancelled")
    }

    /// The status a job ends in with `error`: `cancelled` for a cancellation, else `failed`.
    pub fn status_after(error: &Value) -> &'static str {
        if error["code"] == "cancelled" {
            "cancelled"
        } else {
            "failed"
        }
    }
}

/// Milliseconds since the Unix epoch, now.
pub fn unix_ms() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_millis() as u64).unwrap_or(0)
}

/// Where accepted jobs and finished results live. Every method is a short blocking call (a
/// local commit or a round trip): call it off the async workers.
pub trait JobStore: Send + Sync {
    /// Records an accepted job as `queued` (and, in a shared store, queues it); durable when
    /// it returns.
    fn accept(&self, id: &str, job: &Value) -> anyhow::Result<()>;
    /// Marks a job `running` and counts the attempt.
    fn start(&self, id: &str) -> anyhow::Result<()>;
    /// Stores a success: its record and its image (and takes it off a shared queue). A job
    /// cancelled meanwhile (by a `DELETE` another replica received) stays cancelled — the
    /// client was told so — and the answer is `false`.
    fn succeed(&self, id: &str, result: &Value, image: &[u8]) -> anyhow::Result<bool>;
    /// Stores a failure with its error body — `cancelled` when the error's code says so
    /// (`StoredJob::status_after`) — and takes it off a shared queue, so no worker takes it.
    fn fail(&self, id: &str, error: &Value) -> anyhow::Result<()>;
    fn get(&self, id: &str) -> anyhow::Result<Option<StoredJob>>;
    fn image(&self, id: &str) -> anyhow::Result<Option<Vec<u8>>>;
    /// Jobs accepted but not finished (queued, or running when a daemon stopped), oldest
    /// first, for a restarted daemon to run. Shared stores answer none: their queue hands
    /// such jobs out again by itself.
    fn unfinished(&self) -> anyhow::Result<Vec<StoredJob>>;
    /// Drops finished jobs older than `max_age`, then the images of the oldest finished jobs
    /// until the images fit in `max_image_bytes`. Returns how many records and images went.
    fn expire(&self, max_age: Duration, max_image_bytes: u64) -> anyhow::Result<(usize, usize)>;

    /// Whether the store is the queue, shared by several replicas: jobs are then taken with
    /// `next` by each replica's workers instead of being run where they were submitted.
    fn shared(&self) -> bool {
        false
    }
    /// Jobs accepted and not yet taken, across all replicas (shared stores).
    fn queued(&self) -> anyhow::Result<u64> {
        Ok(0)
    }
    /// The next job for `consumer`: one that a consumer which stopped answering left
    /// unfinished first, else a new one, waiting up to `wait` (shared stores).
    fn next(&self, _consumer: &str, _wait: Duration) -> anyhow::Result<Option<StoredJob>> {
        Ok(None)
    }
    /// How often a worker must call `heartbeat` to keep a job.
    fn heartbeat_every(&self) -> Duration {
        Duration::from_secs(3)
    }
    /// Keeps a job that `consumer` is rendering claimed by it (shared stores).
    fn heartbeat(&self, _consumer: &str, _job: &StoredJob) -> anyhow::Result<()> {
        Ok(())
    }
    /// Whether a job was cancelled through the store (by a replica other than the one that
    /// runs it: shared stores).
    fn cancelled(&self, _id: &str) -> anyhow::Result<bool> {
        Ok(false)
    }
    /// Records progress for readers on other replicas (shared stores).
    fn progress(&self, _id: &str, _done: u64, _total: u64) -> anyhow::Result<()> {
        Ok(())
    }
    /// Uploaded bytes stored once for every replica (shared stores; the others keep none).
    fn put_upload(&self, _kind: Kind, _id: &str, _bytes: &[u8]) -> anyhow::Result<()> {
        Ok(())
    }
    fn get_upload(&self, _kind: Kind, _id: &str) -> anyhow::Result<Option<Vec<u8>>> {
        Ok(None)
    }
    fn has_upload(&self, _kind: Kind, _id: &str) -> anyhow::Result<bool> {
        Ok(false)
    }
    fn delete_upload(&self, _kind: Kind, _id: &str) -> anyhow::Result<bool> {
        Ok(false)
    }
}
