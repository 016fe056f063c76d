//! Jobs between the HTTP layer and the engine: the bounded queue (admission, device slots, a
//! deadline — the documented semaphores that bound GPU work), and the store of finished
//! renders and submitted jobs' events. Nothing here speaks HTTP; `server/` maps the errors.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::Value;
use tokio::sync::{watch, OwnedSemaphorePermit, Semaphore};

use crate::engine::Rendered;
use crate::error::{ErrorCode, JobError};

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
    /// `queued`, `running`, `succeeded` or `failed`.
    pub status: &'static str,
    /// Progress of long methods: steps done of all (samples for `reference`); 0 of 0 otherwise.
    pub done: u64,
    pub total: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<Value>,
}

impl JobEvent {
    pub fn status(status: &'static str) -> Self {
        Self { status, done: 0, total: 0, error: None }
    }

    pub fn finished(&self) -> bool {
        matches!(self.status, "succeeded" | "failed")
    }
}

/// Finished renders (newest last) and submitted jobs' event channels, each bounded by the
/// number of results kept; finished submissions go first, unfinished ones stay.
pub struct JobStore {
    results: Mutex<VecDeque<(String, Arc<Rendered>)>>,
    submitted: Mutex<VecDeque<(String, watch::Sender<JobEvent>)>>,
    capacity: usize,
}

impl JobStore {
    pub fn new(results_kept: usize) -> Self {
        Self { results: Mutex::new(VecDeque::new()), submitted: Mutex::new(VecDeque::new()), capacity: results_kept.max(1) }
    }

    pub fn keep(&self, id: String, rendered: Arc<Rendered>) {
        let mut results = self.results.lock().unwrap_or_else(|p| p.into_inner());
        if results.len() >= self.capacity {
            results.pop_front();
        }
        results.push_back((id, rendered));
    }

    pub fn find(&self, id: &str) -> Option<Arc<Rendered>> {
        let results = self.results.lock().unwrap_or_else(|p| p.into_inner());
        results.iter().find(|(k, _)| k == id).map(|(_, r)| r.clone())
    }

    pub fn submit(&self, id: String, events: watch::Sender<JobEvent>) {
        let mut submitted = self.submitted.lock().unwrap_or_else(|p| p.into_inner());
        while submitted.len() >= self.capacity {
            match submitted.iter().position(|(_, tx)| tx.borrow().finished()) {
                Some(at) => {
                    submitted.remove(at);
                }
                None => break,
            }
        }
        submitted.push_back((id, events));
    }

    /// The event channel of a submitted job.
    pub fn submitted(&self, id: &str) -> Option<watch::Sender<JobEvent>> {
        let submitted = self.submitted.lock().unwrap_or_else(|p| p.into_inner());
        submitted.iter().find(|(k, _)| k == id).map(|(_, tx)| tx.clone())
    }
}
