//! The server's state and its lifecycle: the engine, the queue, results and submitted jobs,
//! the durable store, metrics and recent jobs; admission, shutdown, resuming the jobs a
//! stopped daemon had accepted, and the background tasks (shared-queue workers, expiry).

use super::*;

pub struct AppState {
    pub(super) engine: Arc<Engine>,
    pub(super) metrics: metrics::Metrics,
    pub(super) queue: JobQueue,
    pub(super) queue_config: QueueConfig,
    pub(super) jobs: LiveJobs,
    pub(super) results_kept: usize,
    /// The last finished jobs, for `/v1/stats` and the dashboard.
    pub(super) recent: RecentJobs,
    /// Where submitted jobs and their results are kept durably (None: memory only).
    pub(super) store: Option<Store>,
    /// How long a finished job's outcome is retried while the store cannot take it.
    pub(super) store_retry: std::time::Duration,
    /// Set at shutdown: event streams end (clients reconnect elsewhere or after the restart),
    /// and with a durable store, jobs still waiting for the device stay queued there for the
    /// next start instead of holding the shutdown up.
    pub(super) stopping: tokio::sync::watch::Sender<bool>,
    /// Bearer tokens (None: the API is open).
    pub(super) auth: Option<auth::Auth>,
    /// Allowed cross-origin callers (None: CORS closed).
    pub(super) cors: Option<tower_http::cors::CorsLayer>,
    pub(super) ready: AtomicBool,
    pub(super) started: std::time::SystemTime,
    /// The client connections of `serve` (None: the router is driven directly).
    pub(super) connections: Option<Arc<connections::Tracker>>,
    /// How long idempotency keys last, and the keys themselves when there is no store.
    pub(super) idempotency: Idempotency,
    /// This replica: its name, its finished jobs and its heartbeat in a shared store.
    pub(super) replica: Replica,
    /// The shared store's backlog as last read, and when (read at most once a second).
    backlog: tokio::sync::Mutex<Option<(std::time::Instant, Option<crate::store::Backlog>)>>,
    /// The device's cost and quality model, for `auto` and estimates.
    pub(super) model: super::auto::ModelState,
}

/// The least time between two reads of a shared store's backlog.
const BACKLOG_READ_EVERY: std::time::Duration = std::time::Duration::from_secs(1);

/// Idempotent submission's settings: how long a key names its job, and, for a daemon without
/// a job store, the keys (a store keeps them for every replica and across restarts).
pub struct Idempotency {
    pub(super) ttl: std::time::Duration,
    pub(super) keys: IdempotencyKeys,
}

impl Idempotency {
    /// Keys that last `ttl`; at most `max_keys` held at once.
    pub fn new(ttl: std::time::Duration, max_keys: usize) -> Self {
        Self { ttl, keys: IdempotencyKeys::new(max_keys) }
    }

    pub(super) fn ttl_ms(&self) -> u64 {
        self.ttl.as_millis() as u64
    }
}

impl AppState {
    pub fn new(engine: Arc<Engine>, results_kept: usize) -> Self {
        Self {
            metrics: metrics::Metrics::new(&engine.adapter()),
            queue: JobQueue::new(QueueConfig::default()),
            queue_config: QueueConfig::default(),
            jobs: LiveJobs::new(results_kept, DEFAULT_RESULTS_TTL),
            results_kept,
            recent: RecentJobs::new(RECENT_JOBS),
            store: None,
            store_retry: DEFAULT_STORE_RETRY,
            stopping: tokio::sync::watch::channel(false).0,
            auth: None,
            cors: None,
            engine,
            ready: AtomicBool::new(false),
            connections: None,
            started: std::time::SystemTime::now(),
            idempotency: Idempotency::new(DEFAULT_IDEMPOTENCY_TTL, crate::job::submission::DEFAULT_MAX_KEYS),
            backlog: tokio::sync::Mutex::new(None),
            model: super::auto::ModelState::shipped(),
            replica: Replica::new("penumbra", DEFAULT_HEARTBEAT),
        }
    }

    /// The store, where it is the queue shared by several replicas.
    pub(super) fn shared_store(&self) -> Option<&Store> {
        self.store.as_ref().filter(|s| s.shared())
    }

    /// Jobs accepted and not yet started across the service: with a shared store, its queue
    /// (the same on every replica; read at most once a second, however often it is scraped),
    /// else the submitted jobs waiting here. None while the store cannot be read: unknown,
    /// not zero.
    pub(super) async fn backlog(&self) -> Option<crate::store::Backlog> {
        let Some(store) = self.shared_store().cloned() else {
            let (jobs, oldest_unix_ms) = self.jobs.waiting();
            return Some(crate::store::Backlog { jobs, oldest_unix_ms });
        };
        let mut cached = self.backlog.lock().await;
        if let Some((read, backlog)) = *cached {
            if read.elapsed() < BACKLOG_READ_EVERY {
                return backlog;
            }
        }
        let backlog = store.call(|s| s.backlog()).await.ok().flatten();
        *cached = Some((std::time::Instant::now(), backlog));
        backlog
    }

    /// Names this replica, and sets how often it reports itself to a shared store.
    pub fn with_replica(self, replica: Replica) -> Self {
        Self { replica, ..self }
    }

    /// Idempotency keys that last `idempotency.ttl`.
    pub fn with_idempotency(self, idempotency: Idempotency) -> Self {
        Self { idempotency, ..self }
    }

    pub fn with_queue(self, queue: QueueConfig) -> Self {
        Self { queue: JobQueue::new(queue), queue_config: queue, ..self }
    }

    /// Keeps submitted jobs and their results in `store`, so that they survive a restart.
    pub fn with_store(self, store: Store) -> Self {
        Self { store: Some(store), ..self }
    }

    /// Reports these connections in `/metrics` and `/v1/stats`.
    pub fn with_connections(self, tracker: Arc<connections::Tracker>) -> Self {
        Self { connections: Some(tracker), ..self }
    }

    /// Retries storing a finished job's outcome for up to `retry` while the store cannot take
    /// it (then gives up: see `worker::persist`).
    pub fn with_store_retry(self, retry: std::time::Duration) -> Self {
        Self { store_retry: retry, ..self }
    }

    /// Requires one of these bearer tokens on `/v1` (and `/metrics` unless it is open).
    pub fn with_auth(self, auth: auth::Auth) -> Self {
        Self { auth: Some(auth), ..self }
    }

    /// Lets browsers on these origins call the API (CORS); none: closed.
    pub fn with_cors_origins(self, origins: &[String]) -> anyhow::Result<Self> {
        if origins.is_empty() {
            return Ok(self);
        }
        use axum::http::{HeaderName, Method};
        let origins: Vec<HeaderValue> = origins
            .iter()
            .map(|o| HeaderValue::from_str(o).map_err(|_| anyhow::anyhow!("bad CORS origin `{o}`")))
            .collect::<Result<_, _>>()?;
        let cors = tower_http::cors::CorsLayer::new()
            .allow_origin(origins)
            .allow_methods([Method::GET, Method::POST, Method::PUT, Method::DELETE, Method::HEAD])
            .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE, header::ACCEPT, HeaderName::from_static("x-penumbra-scene")])
            .expose_headers([
                header::LOCATION,
                header::RETRY_AFTER,
                HeaderName::from_static("server-timing"),
                HeaderName::from_static("x-penumbra-job-id"),
            ]);
        Ok(Self { cors: Some(cors), ..self })
    }

    /// Finished jobs (results, records and events) are dropped `ttl` after they finished.
    pub fn with_results_ttl(self, ttl: std::time::Duration) -> Self {
        Self { jobs: LiveJobs::new(self.results_kept, ttl), ..self }
    }

    /// Records a finished job in the metrics and in the recent jobs the dashboard shows.
    pub(super) fn job_finished(&self, id: &str, method: &str, outcome: &str, seconds: f64, rendered: Option<&Rendered>) {
        self.metrics.job_finished(method, outcome, seconds, rendered.map(|r| &r.timings));
        if method.is_empty() {
            return; // Not a job yet (unparseable body): the metrics count it, the dashboard does not.
        }
        self.replica.count(outcome);
        let summary = JobSummary {
            id: id.to_string(),
            method: method.to_string(),
            outcome: outcome.to_string(),
            replica: self.replica.name.clone(),
            finished_unix_ms: unix_ms(),
            wall_ms: seconds * 1e3,
            phases: rendered.map(|r| r.timings.phases.iter().map(|p| (p.name.to_string(), p.cpu_ms)).collect()).unwrap_or_default(),
            width: rendered.map_or(0, |r| r.width),
            height: rendered.map_or(0, |r| r.height),
        };
        self.share_finished(&summary);
        self.recent.record(summary);
    }

    /// See `JobQueue::try_hold_device`.
    pub fn try_hold_device(&self) -> Option<tokio::sync::OwnedSemaphorePermit> {
        self.queue.try_hold_device()
    }

    /// See `JobQueue::drain`: for a shutdown that finishes the work it accepted. With a durable
    /// store, jobs that have not reached the device stay queued there for the next start.
    pub async fn drain(&self, limit: std::time::Duration) -> bool {
        self.begin_shutdown();
        self.queue.drain(limit).await
    }

    /// A place in the queue for a new job: none once the daemon is stopping (503, so a load
    /// balancer retries elsewhere), none when the queue is full (429).
    pub(super) fn admit(&self) -> Result<tokio::sync::OwnedSemaphorePermit, JobError> {
        if *self.stopping.borrow() {
            return Err(JobError::new(
                ErrorCode::ShuttingDown,
                "the daemon is shutting down; retry on another replica or after it restarts",
            ));
        }
        self.queue.admit()
    }

    /// Tells waiting jobs and event streams that the daemon is stopping.
    pub fn begin_shutdown(&self) {
        self.stopping.send_replace(true);
    }

    /// Submits again every job the store holds unfinished (queued, or running when the last
    /// daemon stopped), oldest first; one started `MAX_ATTEMPTS` times already fails instead.
    /// Returns how many were resumed.
    pub async fn resume_unfinished(self: &Arc<Self>) -> anyhow::Result<usize> {
        let Some(store) = self.store.clone() else { return Ok(0) };
        let unfinished = store.call(|s| s.unfinished()).await?;
        let mut resumed = 0;
        for stored in unfinished {
            let job = Job::from_json_limited(stored.job.to_string().as_bytes(), self.engine.limits());
            let failure = match job {
                Ok(_) if stored.attempts >= MAX_ATTEMPTS => Some(abandoned(stored.attempts)),
                Ok(job) => {
                    let admitted = self.queue.admit_waiting().await?;
                    let reservation = store.reserve_accepted(super::job_routes::promised_bytes(&job, self.engine.limits()));
                    self.spawn_submitted(stored.listed(), job, (admitted, Some(reservation)));
                    resumed += 1;
                    None
                }
                Err(error) => Some(failure_detail(&error)),
            };
            if let Some(detail) = failure {
                tracing::warn!(id = %stored.id, %detail, "stored job failed at resumption");
                store.call(move |s| s.fail(&stored.id, &detail)).await?;
            }
        }
        Ok(resumed)
    }

    /// Registers a submitted job's event channel and starts its life in the background; it
    /// holds its place in the queue and the room promised to its result until its outcome is
    /// stored.
    /// Its life runs in a span that names the request that submitted it.
    pub(super) fn spawn_submitted(self: &Arc<Self>, listed: ListedJob, job: Job, admitted: Admitted) {
        use tracing::Instrument as _;
        let (events, _) = tokio::sync::watch::channel(JobEvent::status(JobStatus::Queued));
        let span = submitted_span(listed.request_id.as_deref());
        let id = listed.id.clone();
        let cancel = self.jobs.submit(listed, events.clone());
        let state = self.clone();
        tokio::spawn(async move { run_submitted(state, id, job, admitted, events, cancel).await }.instrument(span));
    }

    /// With a shared store, one worker per device slot takes jobs from the shared queue, as
    /// consumer `REPLICA/SLOT` (REPLICA: this replica's name), so a job's record says where
    /// it ran.
    pub fn spawn_workers(self: &Arc<Self>) {
        if self.shared_store().is_none() {
            return;
        }
        for worker in 0..self.queue_config.concurrency {
            let consumer = format!("{}/{worker}", self.replica.name);
            tokio::spawn(work_shared_queue(self.clone(), consumer));
        }
    }

    /// Drops stored results past their age or beyond the byte budget, now and then forever.
    pub(super) fn spawn_expiry(self: &Arc<Self>, ttl: std::time::Duration, max_image_bytes: u64) {
        let Some(store) = self.store.clone() else { return };
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(std::time::Duration::from_secs(30));
            loop {
                tick.tick().await;
                match store.call(move |s| s.expire(ttl, max_image_bytes)).await {
                    Ok((0, 0)) => {}
                    Ok((records, images)) => tracing::info!(records, images, "expired stored results"),
                    // An outage is logged once by the store's health; other failures here.
                    Err(StoreError::Unavailable(_)) => {}
                    Err(error) => tracing::warn!(%error, "expiring stored results failed"),
                }
            }
        });
    }

    pub fn set_ready(&self) {
        self.ready.store(true, Ordering::SeqCst);
    }

    /// Why the daemon cannot take submitted jobs now, if it cannot: its store does not
    /// answer, or its disk is at the free-space margin.
    pub(super) fn store_trouble(&self) -> Option<&'static str> {
        let health = self.store.as_ref()?.health();
        if !health.available() {
            Some("store unavailable")
        } else if !health.room() {
            Some("insufficient storage")
        } else {
            None
        }
    }
}

/// What a submitted job holds until its outcome is stored: its place in the queue, and the
/// room promised to its result on a local store's disk.
pub(super) type Admitted = (tokio::sync::OwnedSemaphorePermit, Option<crate::store::health::Reservation>);

/// The span of a submitted job's life: the request that submitted it (the job's own span,
/// with its id, opens inside when it renders).
pub(super) fn submitted_span(request_id: Option<&str>) -> tracing::Span {
    tracing::info_span!(parent: None, "request", request_id = request_id.unwrap_or("-"))
}
