//! Jobs between the HTTP layer and the engine: the bounded queue (admission, device slots, a
//! deadline — the documented semaphores that bound GPU work), and the store of finished
//! renders and submitted jobs' events (and, without a job store, their listing and
//! idempotency keys). Nothing here speaks HTTP; `server/` maps the errors.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;
use tokio::sync::{watch, OwnedSemaphorePermit, Semaphore};

use crate::engine::Rendered;
use crate::error::{ErrorCode, JobError};
use crate::job::submission::{self, Cursor, JobFilter, KeyedJob, ListedJob};
use crate::job::summary::JobSummary;
use crate::job::JobStatus;

/// The queue's shape: jobs admitted at once (waiting or running), jobs on the device at once,
/// and how long a job may wait for the device.
#[derive(Debug, Clone, Copy)]
pub struct QueueConfig {
    pub capacity: u32,
    pub concurrency: u32,
    pub deadline: Duration,
}

impl Default for QueueConfig {
    fn default() -> Self {
        Self { capacity: 64, concurrency: 1, deadline: Duration::from_secs(120) }
    }
}

/// Admission (one permit per admitted job; none left → `queue_full`) and device slots (one
/// permit per job rendering; waiting past the deadline → `deadline_exceeded`).
pub struct JobQueue {
    admission: Arc<Semaphore>,
    capacity: u32,
    device: Arc<Semaphore>,
    pub deadline: Duration,
}

impl JobQueue {
    pub fn new(config: QueueConfig) -> Self {
        Self {
            admission: Arc::new(Semaphore::new(config.capacity as usize)),
            capacity: config.capacity,
            device: Arc::new(Semaphore::new(config.concurrency as usize)),
            deadline: config.deadline,
        }
    }

    /// A place in the queue, or `queue_full` at once.
    pub fn admit(&self) -> Result<OwnedSemaphorePermit, JobError> {
        self.admission
            .clone()
            .try_acquire_owned()
            .map_err(|_| JobError::new(ErrorCode::QueueFull, "the job queue is full; retry after the Retry-After seconds"))
    }

    /// A place in the queue, waiting for one: for jobs accepted before a restart, which were
    /// admitted once already and must not be refused now.
    pub async fn admit_waiting(&self) -> anyhow::Result<OwnedSemaphorePermit> {
        Ok(self.admission.clone().acquire_owned().await?)
    }

    /// A device slot, waiting at most the deadline.
    pub async fn device(&self) -> Result<OwnedSemaphorePermit, JobError> {
        match tokio::time::timeout(self.deadline, self.device.clone().acquire_owned()).await {
            Ok(Ok(permit)) => Ok(permit),
            Ok(Err(_)) => Err(JobError::internal("the device queue is closed")),
            Err(_) => Err(JobError::new(
                ErrorCode::DeadlineExceeded,
                format!("the job waited {:.1} s in the queue without reaching the device", self.deadline.as_secs_f64()),
            )),
        }
    }

    /// A device slot, waiting as long as it takes (a shared-queue worker, which takes a job
    /// only once it can start it).
    pub async fn device_slot(&self) -> Option<OwnedSemaphorePermit> {
        self.device.clone().acquire_owned().await.ok()
    }

    /// Takes a device slot as a job would, until the permit drops: jobs queue behind it. For
    /// tests of the queue (and for an operator draining the device), not for jobs.
    pub fn try_hold_device(&self) -> Option<OwnedSemaphorePermit> {
        self.device.clone().try_acquire_owned().ok()
    }

    /// Waits (up to `limit`) until no job is admitted — none waiting, none rendering, submitted
    /// ones included — and admits no more. Returns whether it drained.
    pub async fn drain(&self, limit: Duration) -> bool {
        // Every admission permit back means every admitted job has finished; keeping them all
        // keeps new ones out.
        tokio::time::timeout(limit, self.admission.acquire_many(self.capacity)).await.is_ok_and(|permits| {
            permits.is_ok_and(|p| {
                p.forget();
                true
            })
        })
    }
}

/// The state of a submitted job as its events report it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct JobEvent {
    pub status: JobStatus,
    /// Progress of long methods: steps done of all (samples for `reference`); 0 of 0 otherwise.
    pub done: u64,
    pub total: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<Value>,
    /// A progressive job's latest round (contract §5).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub round: Option<crate::job::progressive::Round>,
    /// Every round so far, so that an event stream that fell behind still sends each one.
    #[serde(skip)]
    pub rounds: Vec<crate::job::progressive::Round>,
    /// When the job reached `succeeded`, `failed` or `cancelled`: its record expires a while
    /// after.
    #[serde(skip)]
    pub finished_at: Option<Instant>,
}

impl JobEvent {
    pub fn status(status: JobStatus) -> Self {
        Self { status, done: 0, total: 0, error: None, round: None, rounds: Vec::new(), finished_at: None }
    }

    /// Marks the job `succeeded`, `failed` or `cancelled` as of now.
    pub fn finish(&mut self, status: JobStatus, error: Option<Value>) {
        self.status = status;
        self.error = error;
        self.finished_at = Some(Instant::now());
    }

    pub fn finished(&self) -> bool {
        self.status.finished()
    }
}

/// A running progressive job's round image: its format, and its bytes where they are kept in
/// memory (`None`: on the job store's disk, `JobStore::put_round`).
#[derive(Clone)]
pub struct KeptRound {
    pub format: crate::job::OutputFormat,
    pub bytes: Option<Arc<Vec<u8>>>,
}

/// Finished renders (newest last) and submitted jobs' event channels. Both are bounded by the
/// number of results kept (finished submissions go first, unfinished ones stay) and by age: a
/// finished job is dropped `ttl` after it finished.
pub struct LiveJobs {
    results: Mutex<VecDeque<(String, Arc<Rendered>, Instant)>>,
    submitted: Mutex<VecDeque<Submitted>>,
    /// Running progressive jobs' round images, by job: each job's are dropped when it ends
    /// (`drop_rounds`), so they are bounded by the jobs running and their rounds.
    rounds: Mutex<HashMap<String, Vec<KeptRound>>>,
    capacity: usize,
    ttl: Duration,
}

impl LiveJobs {
    pub fn new(results_kept: usize, ttl: Duration) -> Self {
        let (results, submitted, rounds) = (Mutex::default(), Mutex::default(), Mutex::default());
        Self { results, submitted, rounds, capacity: results_kept.max(1), ttl }
    }

    /// Keeps a progressive job's next round (numbered from 0 in the order kept).
    pub fn keep_round(&self, id: &str, round: KeptRound) {
        self.rounds.lock().unwrap_or_else(|p| p.into_inner()).entry(id.to_owned()).or_default().push(round);
    }

    /// Round `round` of a running progressive job, while the job runs.
    pub fn round(&self, id: &str, round: usize) -> Option<KeptRound> {
        self.rounds.lock().unwrap_or_else(|p| p.into_inner()).get(id)?.get(round).cloned()
    }

    /// Lets a progressive job's rounds go: it has ended.
    pub fn drop_rounds(&self, id: &str) {
        self.rounds.lock().unwrap_or_else(|p| p.into_inner()).remove(id);
    }

    pub fn keep(&self, id: String, rendered: Arc<Rendered>) {
        let mut results = self.results();
        if results.len() >= self.capacity {
            results.pop_front();
        }
        results.push_back((id, rendered, Instant::now()));
    }

    pub fn find(&self, id: &str) -> Option<Arc<Rendered>> {
        self.results().iter().find(|(k, _, _)| k == id).map(|(_, r, _)| r.clone())
    }

    /// Registers a submitted job's events, and how it is listed; the answer says (once true)
    /// that it was cancelled.
    pub fn submit(&self, listed: ListedJob, events: watch::Sender<JobEvent>) -> watch::Receiver<bool> {
        let mut submitted = self.submitted_jobs();
        while submitted.len() >= self.capacity {
            match submitted.iter().position(|s| s.events.borrow().finished()) {
                Some(at) => {
                    submitted.remove(at);
                }
                None => break,
            }
        }
        let (cancel, cancelled) = watch::channel(false);
        submitted.push_back(Submitted { id: listed.id.clone(), listed, events, cancel });
        cancelled
    }

    /// The submitted jobs held here, as `GET /v1/jobs` lists them without a job store: newest
    /// first, filtered, a page of `limit` and the cursor of the next.
    pub fn list(&self, filter: &JobFilter, after: Option<&Cursor>, limit: usize) -> (Vec<ListedJob>, Option<Cursor>) {
        let now_ms = crate::job::submission::unix_ms();
        let jobs = self
            .submitted_jobs()
            .iter()
            .map(|s| {
                let event = s.events.borrow();
                let mut listed = s.listed.clone();
                listed.status = event.status;
                listed.finished_unix_ms = event.finished_at.map(|at| now_ms.saturating_sub(at.elapsed().as_millis() as u64));
                listed
            })
            .collect();
        submission::page(jobs, filter, after, limit)
    }

    /// Submitted jobs held here that wait for the device: how many, and when the oldest was
    /// submitted (the backlog of a daemon that is its own queue).
    pub fn waiting(&self) -> (u64, Option<u64>) {
        let submitted = self.submitted_jobs();
        let waiting = submitted.iter().filter(|s| s.events.borrow().status == JobStatus::Queued);
        waiting.fold((0, None), |(count, oldest), s| {
            (count + 1, Some(oldest.map_or(s.listed.submitted_unix_ms, |o: u64| o.min(s.listed.submitted_unix_ms))))
        })
    }

    /// How a submitted job held here is listed (its submission time, method, request id).
    pub fn listed(&self, id: &str) -> Option<ListedJob> {
        self.submitted_jobs().iter().find(|s| s.id == id).map(|s| s.listed.clone())
    }

    /// The event channel of a submitted job.
    pub fn submitted(&self, id: &str) -> Option<watch::Sender<JobEvent>> {
        self.submitted_jobs().iter().find(|s| s.id == id).map(|s| s.events.clone())
    }

    /// Stops holding a submitted job's events here (its state is then read from the store).
    pub fn forget(&self, id: &str) {
        self.submitted_jobs().retain(|s| s.id != id);
    }

    /// Asks a submitted job held here to stop: a waiting one leaves the queue, a running one
    /// stops at its next phase or batch. `None`: not held here; `Some(false)`: it had
    /// already finished.
    pub fn cancel(&self, id: &str) -> Option<bool> {
        let submitted = self.submitted_jobs();
        let job = submitted.iter().find(|s| s.id == id)?;
        if job.events.borrow().finished() {
            return Some(false);
        }
        job.cancel.send_replace(true);
        Some(true)
    }

    /// Kept results, expired ones dropped first (they are in finishing order).
    fn results(&self) -> std::sync::MutexGuard<'_, VecDeque<(String, Arc<Rendered>, Instant)>> {
        let mut results = self.results.lock().unwrap_or_else(|p| p.into_inner());
        while results.front().is_some_and(|(_, _, at)| at.elapsed() > self.ttl) {
            results.pop_front();
        }
        results
    }

    /// Submitted jobs, those finished longer than `ttl` ago dropped first.
    fn submitted_jobs(&self) -> std::sync::MutexGuard<'_, VecDeque<Submitted>> {
        let mut submitted = self.submitted.lock().unwrap_or_else(|p| p.into_inner());
        submitted.retain(|s| s.events.borrow().finished_at.is_none_or(|at| at.elapsed() <= self.ttl));
        submitted
    }
}

/// A submitted job held by this process: its events, and the flag that cancels it.
struct Submitted {
    id: String,
    listed: ListedJob,
    events: watch::Sender<JobEvent>,
    cancel: watch::Sender<bool>,
}

/// The idempotency keys of a daemon without a job store (`--job-store memory`): what a store
/// keeps for every replica, kept here for this process, bounded in count (past it, expired
/// keys go, then those that expire soonest).
pub struct IdempotencyKeys {
    keys: Mutex<HashMap<String, KeyedJob>>,
    capacity: usize,
}

impl IdempotencyKeys {
    pub fn new(capacity: usize) -> Self {
        Self { keys: Mutex::new(HashMap::new()), capacity: capacity.max(1) }
    }

    fn keys(&self) -> std::sync::MutexGuard<'_, HashMap<String, KeyedJob>> {
        self.keys.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The job `key` names, unless the key expired or `held(id)` says the job is gone.
    pub fn find(&self, key: &str, held: impl Fn(&str) -> bool) -> Option<KeyedJob> {
        let now = submission::unix_ms();
        self.keys().get(key).filter(|k| names_job(k, now, &held)).cloned()
    }

    /// Claims `key` for `claim` unless it names a job still held (answered: a twin's).
    /// Under one lock, so that of two twins the second sees the first's claim.
    pub fn claim(&self, key: &str, claim: KeyedJob, held: impl Fn(&str) -> bool) -> Option<KeyedJob> {
        let now = submission::unix_ms();
        let mut keys = self.keys();
        if let Some(twin) = keys.get(key).filter(|k| names_job(k, now, &held)) {
            return Some(twin.clone());
        }
        if keys.len() >= self.capacity {
            keys.retain(|_, k| k.expires_unix_ms > now);
        }
        if keys.len() >= self.capacity {
            let soonest = keys.iter().min_by_key(|(_, k)| k.expires_unix_ms).map(|(key, _)| key.clone());
            if let Some(soonest) = soonest {
                tracing::warn!(capacity = self.capacity, "the idempotency key store is full: the oldest key goes before it expires");
                keys.remove(&soonest);
            }
        }
        keys.insert(key.to_owned(), claim);
        None
    }

    /// Frees a key claimed for a job that was then not admitted.
    pub fn release(&self, key: &str, id: &str) {
        let mut keys = self.keys();
        if keys.get(key).is_some_and(|k| k.id == id) {
            keys.remove(key);
        }
    }
}

/// Whether a held key still names its job at `now`: not expired, and the job still `held`.
fn names_job(key: &KeyedJob, now: u64, held: &impl Fn(&str) -> bool) -> bool {
    key.expires_unix_ms > now && held(&key.id)
}

/// The last finished jobs of this daemon (newest last), for `/v1/stats` and the dashboard
/// when no shared store holds the whole service's.
pub struct RecentJobs {
    jobs: Mutex<VecDeque<JobSummary>>,
    capacity: usize,
}

impl RecentJobs {
    pub fn new(capacity: usize) -> Self {
        Self { jobs: Mutex::new(VecDeque::new()), capacity: capacity.max(1) }
    }

    pub fn record(&self, summary: JobSummary) {
        let mut jobs = self.jobs.lock().unwrap_or_else(|p| p.into_inner());
        if jobs.len() >= self.capacity {
            jobs.pop_front();
        }
        jobs.push_back(summary);
    }

    /// The newest `n` jobs, newest first.
    pub fn newest(&self, n: usize) -> Vec<JobSummary> {
        let jobs = self.jobs.lock().unwrap_or_else(|p| p.into_inner());
        jobs.iter().rev().take(n).cloned().collect()
    }
}
