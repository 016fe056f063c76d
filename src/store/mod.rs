//! The durable job store behind `POST /v1/jobs`: every accepted job is written before its
//! 202 is answered, and every finished one with its record and image. `JobStore` is the
//! interface; `embedded` keeps it on one machine's disk, `redis` shares it between replicas (a
//! stream with a consumer group as the queue, records and images with a TTL, uploads stored
//! once for all of them). `health` watches a store for outages and a full disk and is the
//! async way in for the server.

pub mod embedded;
pub mod health;
pub mod redis;

use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_json::Value;

pub use embedded::EmbeddedStore;
pub use health::{Store, StoreHealth, StoreStatus};
pub use redis::RedisStore;

use crate::job::submission::{Cursor, JobFilter, KeyedJob, ListedJob};
use crate::job::summary::JobSummary;
use crate::job::{JobStatus, DEFAULT_METHOD};
use crate::upload_store::Kind;

/// Times a job may be started by a daemon that then died before finishing it; the next start
/// fails it with a reason instead of taking a daemon down again and again.
pub const MAX_ATTEMPTS: u32 = 3;

/// A job as the store keeps it.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct StoredJob {
    pub id: String,
    pub status: JobStatus,
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
    /// The id of the request that submitted it (`x-request-id`), for the logs of its life.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub request_id: Option<String>,
    /// A progressive job's rounds so far, as its events report them (shared stores: for
    /// readers on other replicas).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rounds: Vec<crate::job::progressive::Round>,
}

impl StoredJob {
    /// A job just accepted: queued, submitted now.
    pub fn queued(id: &str, job: &Value) -> Self {
        Self { id: id.to_owned(), status: JobStatus::Queued, job: job.clone(), submitted_unix_ms: unix_ms(), ..Self::default() }
    }

    pub fn finished(&self) -> bool {
        self.status.finished()
    }

    /// The method the job asked for (`hard` when it named none), as `GET /v1/jobs` lists and
    /// filters it.
    pub fn method(&self) -> &str {
        self.job["method"]["name"].as_str().unwrap_or(DEFAULT_METHOD)
    }

    /// The job as `GET /v1/jobs` lists it.
    pub fn listed(&self) -> ListedJob {
        let mut listed = ListedJob::new(&self.id, self.status, self.method(), self.submitted_unix_ms);
        listed.finished_unix_ms = self.finished_unix_ms;
        listed.request_id = self.request_id.clone();
        listed
    }

    /// The status a job ends in with `error`: `cancelled` for a cancellation, else `failed`.
    pub fn status_after(error: &Value) -> JobStatus {
        if error["code"] == "cancelled" {
            JobStatus::Cancelled
        } else {
            JobStatus::Failed
        }
    }
}

/// Jobs accepted and not yet started across the whole service, and when the oldest of them
/// was accepted: what an autoscaler scales on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Backlog {
    pub jobs: u64,
    pub oldest_unix_ms: Option<u64>,
}

impl Backlog {
    /// Seconds the oldest waiting job has waited at `now_unix_ms` (None without one).
    pub fn oldest_age_seconds(&self, now_unix_ms: u64) -> Option<f64> {
        self.oldest_unix_ms.map(|oldest| now_unix_ms.saturating_sub(oldest) as f64 / 1e3)
    }
}

/// What a replica says of itself in its heartbeat: its row in the cluster view.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ReplicaReport {
    /// Its name (`--replica-name`: the pod's name under Kubernetes).
    pub replica: String,
    /// The adapter it renders on, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)`.
    pub adapter: String,
    pub version: String,
    pub started_unix_ms: u64,
    /// When this report was written.
    pub heartbeat_unix_ms: u64,
    /// Jobs rendering there now, and waiting there for its device.
    pub jobs_in_flight: u64,
    pub jobs_queued: u64,
    /// Jobs it finished since it started, by outcome.
    pub jobs_succeeded: u64,
    pub jobs_failed: u64,
    /// Its device slots (`--concurrency`).
    pub concurrency: u32,
}

/// Why a store operation failed. The server answers each kind differently: an unavailable
/// store is retried (503 `store_unavailable` at admission, results kept and stored later), a
/// full one refuses new work (507 `insufficient_storage`), an existing id is never
/// overwritten.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The store cannot be reached or cannot write right now (connection refused or dropped,
    /// an I/O error, Redis loading its data): the same call may succeed later.
    #[error("the job store is unavailable: {0}")]
    Unavailable(String),
    /// The store has no room for the write (no space left on its disk, Redis out of memory).
    #[error("the job store is out of space: {0}")]
    Full(String),
    /// A job record with this id exists already; it is never overwritten.
    #[error("a job `{0}` exists already")]
    Exists(String),
    /// Anything else: a record that does not parse, a job the store does not hold.
    #[error(transparent)]
    Other(#[from] anyhow::Error),
}

impl StoreError {
    /// Whether the same call may succeed later, once the store is back or has room.
    pub fn is_transient(&self) -> bool {
        matches!(self, StoreError::Unavailable(_) | StoreError::Full(_))
    }
}

impl From<serde_json::Error> for StoreError {
    fn from(error: serde_json::Error) -> Self {
        StoreError::Other(error.into())
    }
}

pub type StoreResult<T> = Result<T, StoreError>;

/// A new job id: 128 random bits (a UUIDv4 in its 32-digit hex form), so that replicas
/// started in the same millisecond, and daemons restarted on the same store, never issue the
/// same id; stores refuse an id they hold anyway (`StoreError::Exists`).
pub fn new_job_id() -> String {
    uuid::Uuid::new_v4().simple().to_string()
}

pub use crate::job::submission::unix_ms;

/// Where accepted jobs and finished results live. Every method is a short blocking call (a
/// local commit or a round trip): call it off the async workers.
pub trait JobStore: Send + Sync {
    /// Records an accepted job (`StoredJob::queued`, and, in a shared store, queues it);
    /// durable when it returns. An id the store holds already is refused
    /// (`StoreError::Exists`), never overwritten.
    fn accept_record(&self, record: &StoredJob) -> StoreResult<()>;
    /// `accept_record` of a job just sent.
    fn accept(&self, id: &str, job: &Value) -> StoreResult<()> {
        self.accept_record(&StoredJob::queued(id, job))
    }
    /// The job an idempotency key names (`key` as the client sent it), unless the key expired
    /// or the job's record did: a key names its job while both last.
    fn keyed(&self, key: &str) -> StoreResult<Option<KeyedJob>>;
    /// Accepts `record` under an idempotency key: when the key names a job already (a twin
    /// sent at the same time), nothing is written and that job is answered; else the key is
    /// claimed for the record (until `claim.expires_unix_ms`) and the record accepted. A key
    /// whose job's record expired is claimed anew: the first job's result is gone, and a
    /// retry gets a job that renders it again rather than an id that answers 404.
    fn accept_keyed(&self, record: &StoredJob, key: &str, claim: &KeyedJob) -> StoreResult<Option<KeyedJob>>;
    /// Submitted jobs newest first (ties by id), those after `after` that `filter` admits, at
    /// most `limit`; with the cursor of the next page when more may remain. Every replica of a
    /// shared store lists the same jobs.
    fn list(&self, filter: &JobFilter, after: Option<&Cursor>, limit: usize) -> StoreResult<(Vec<ListedJob>, Option<Cursor>)>;
    /// Marks a job `running` and counts the attempt.
    fn start(&self, id: &str) -> StoreResult<()>;
    /// Stores a success: its record and its image (and takes it off a shared queue). A job
    /// cancelled meanwhile (by a `DELETE` another replica received) stays cancelled — the
    /// client was told so — and the answer is `false`.
    fn succeed(&self, id: &str, result: &Value, image: &[u8]) -> StoreResult<bool>;
    /// Stores a failure with its error body — `cancelled` when the error's code says so
    /// (`StoredJob::status_after`) — and takes it off a shared queue, so no worker takes it.
    fn fail(&self, id: &str, error: &Value) -> StoreResult<()>;
    fn get(&self, id: &str) -> StoreResult<Option<StoredJob>>;
    fn image(&self, id: &str) -> StoreResult<Option<Vec<u8>>>;
    /// Jobs accepted but not finished (queued, or running when a daemon stopped), oldest
    /// first, for a restarted daemon to run. Shared stores answer none: their queue hands
    /// such jobs out again by itself.
    fn unfinished(&self) -> StoreResult<Vec<StoredJob>>;
    /// Drops finished jobs older than `max_age`, then the images of the oldest finished jobs
    /// until the images fit in `max_image_bytes`. Returns how many records and images went.
    fn expire(&self, max_age: Duration, max_image_bytes: u64) -> StoreResult<(usize, usize)>;

    /// Checks that the store answers (reconnecting or reopening it when it had failed).
    fn ping(&self) -> StoreResult<()>;
    /// Bytes free for results on the store's own disk; None for a store that is not limited
    /// by a local disk (Redis, whose memory is its operator's to size).
    fn free_bytes(&self) -> Option<u64> {
        None
    }
    /// Drops the oldest finished jobs (images first, then records) until `free_bytes` is at
    /// least `wanted`, or nothing finished is left. Returns how many results went.
    fn make_room(&self, _wanted: u64) -> StoreResult<usize> {
        Ok(0)
    }

    /// Whether the store is the queue, shared by several replicas: jobs are then taken with
    /// `next` by each replica's workers instead of being run where they were submitted.
    fn shared(&self) -> bool {
        false
    }
    /// Jobs accepted and not yet taken, across all replicas (shared stores).
    fn queued(&self) -> StoreResult<u64> {
        Ok(0)
    }
    /// The service's backlog, the same on every replica (shared stores); None where the
    /// store is not the queue and the server counts its own.
    fn backlog(&self) -> StoreResult<Option<Backlog>> {
        Ok(None)
    }
    /// The next job for `consumer`: one that a consumer which stopped answering left
    /// unfinished first, else a new one, waiting up to `wait` (shared stores).
    fn next(&self, _consumer: &str, _wait: Duration) -> StoreResult<Option<StoredJob>> {
        Ok(None)
    }
    /// How often a worker must call `heartbeat` to keep a job.
    fn heartbeat_every(&self) -> Duration {
        Duration::from_secs(3)
    }
    /// Keeps a job that `consumer` is rendering claimed by it (shared stores).
    fn heartbeat(&self, _consumer: &str, _job: &StoredJob) -> StoreResult<()> {
        Ok(())
    }
    /// Whether a job was cancelled through the store (by a replica other than the one that
    /// runs it: shared stores).
    fn cancelled(&self, _id: &str) -> StoreResult<bool> {
        Ok(false)
    }
    /// Records progress for readers on other replicas (shared stores).
    fn progress(&self, _id: &str, _done: u64, _total: u64) -> StoreResult<()> {
        Ok(())
    }
    /// Tells the other replicas that `report.replica` is alive, until `ttl` passes without
    /// another report (shared stores).
    fn announce(&self, _report: &ReplicaReport, _ttl: Duration) -> StoreResult<()> {
        Ok(())
    }
    /// Takes a replica that is stopping out of the cluster view at once (shared stores).
    fn withdraw(&self, _replica: &str) -> StoreResult<()> {
        Ok(())
    }
    /// The replicas whose last report has not expired, by name (shared stores).
    fn replicas(&self) -> StoreResult<Vec<ReplicaReport>> {
        Ok(Vec::new())
    }
    /// Keeps a finished job among the service's last `keep` (shared stores).
    fn record_finished(&self, _summary: &JobSummary, _keep: usize) -> StoreResult<()> {
        Ok(())
    }
    /// The service's last `n` finished jobs, newest first (shared stores).
    fn recent_finished(&self, _n: usize) -> StoreResult<Vec<JobSummary>> {
        Ok(Vec::new())
    }
    /// Uploaded bytes stored once for every replica (shared stores; the others keep none).
    fn put_upload(&self, _kind: Kind, _id: &str, _bytes: &[u8]) -> StoreResult<()> {
        Ok(())
    }
    fn get_upload(&self, _kind: Kind, _id: &str) -> StoreResult<Option<Vec<u8>>> {
        Ok(None)
    }
    /// The bytes of a shared upload, when the store holds it.
    fn upload_size(&self, _kind: Kind, _id: &str) -> StoreResult<Option<u64>> {
        Ok(None)
    }
    fn delete_upload(&self, _kind: Kind, _id: &str) -> StoreResult<bool> {
        Ok(false)
    }
    /// Keeps a running progressive job's round image until `drop_rounds`: on the store's own
    /// disk (contract §5: the rounds count against the disk's promise), or in a shared store
    /// for every replica to serve. Ok(false): this store keeps none, and the caller keeps the
    /// image in memory.
    fn put_round(&self, _id: &str, _round: usize, _image: &[u8]) -> StoreResult<bool> {
        Ok(false)
    }
    /// Records a progressive job's round for readers on other replicas (shared stores).
    fn round_drawn(&self, _id: &str, _round: &crate::job::progressive::Round) -> StoreResult<()> {
        Ok(())
    }
    /// A round image `put_round` kept.
    fn round(&self, _id: &str, _round: usize) -> StoreResult<Option<Vec<u8>>> {
        Ok(None)
    }
    /// Lets a job's round images go: it has ended.
    fn drop_rounds(&self, _id: &str) -> StoreResult<()> {
        Ok(())
    }
}
