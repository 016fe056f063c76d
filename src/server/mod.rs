//! The HTTP service (DESIGN.md §3): `app(state)` builds the router, `serve` binds it, warms
//! the engine up and shuts down gracefully; synchronous renders, limits, stats and metrics
//! are here, submitted jobs in `jobs`, uploads in `uploads`. Rendering runs on the blocking
//! pool so the async workers keep answering health checks while the device is busy.

pub mod auth;
pub mod connections;
mod dashboard;
pub mod error;
mod jobs;
pub mod metrics;
mod uploads;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{DefaultBodyLimit, Path, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde_json::{json, Value};

use crate::config::ServeConfig;
use crate::engine::{Engine, Rendered};
use crate::error::{ErrorCode, JobError};
use crate::job::Job;
use crate::jobs::{JobEvent, JobQueue, JobStore, JobSummary, RecentJobs};
use crate::light::BUILTIN_LIGHT_IMAGES;
use crate::methods::REGISTRY;
use crate::scene::builtin::BUILTIN_SCENES;
use crate::store::{new_job_id, JobStore as DurableStore, Store, StoreError, StoredJob, MAX_ATTEMPTS};
use crate::supervise::Supervise;
use crate::uploads::{content_id, is_content_id, Kind};
use error::{store_error, ApiError};
use jobs::{
    abandoned, cancel_job, failure_detail, job_events, job_image, job_record, job_thumbnail, run_submitted, submit_job, work_shared_queue,
};
use uploads::{fetch_shared_uploads, upload_light, upload_routes, upload_scene};

pub use crate::jobs::QueueConfig;

/// How long finished jobs stay readable unless configured (`--results-ttl-secs`).
pub const DEFAULT_RESULTS_TTL: std::time::Duration = std::time::Duration::from_secs(3600);

/// How often an idle worker of a shared store asks the queue for a job (the most an async job
/// waits for an idle replica).
const SHARED_QUEUE_POLL: std::time::Duration = std::time::Duration::from_millis(50);

/// How long a finished render's outcome is retried while the store cannot take it, unless
/// configured (`--store-retry-secs`).
pub const DEFAULT_STORE_RETRY: std::time::Duration = std::time::Duration::from_secs(600);

/// Finished jobs remembered for the dashboard's charts.
const RECENT_JOBS: usize = 200;

pub struct AppState {
    engine: Arc<Engine>,
    metrics: metrics::Metrics,
    queue: JobQueue,
    queue_config: QueueConfig,
    jobs: JobStore,
    results_kept: usize,
    /// The last finished jobs, for `/v1/stats` and the dashboard.
    recent: RecentJobs,
    /// Where submitted jobs and their results are kept durably (None: memory only).
    store: Option<Store>,
    /// How long a finished job's outcome is retried while the store cannot take it.
    store_retry: std::time::Duration,
    /// Set at shutdown: event streams end (clients reconnect elsewhere or after the restart),
    /// and with a durable store, jobs still waiting for the device stay queued there for the
    /// next start instead of holding the shutdown up.
    stopping: tokio::sync::watch::Sender<bool>,
    /// Bearer tokens (None: the API is open).
    auth: Option<auth::Auth>,
    /// Allowed cross-origin callers (None: CORS closed).
    cors: Option<tower_http::cors::CorsLayer>,
    ready: AtomicBool,
    started: std::time::SystemTime,
    /// The client connections of `serve` (None: the router is driven directly).
    connections: Option<Arc<connections::Tracker>>,
}

impl AppState {
    pub fn new(engine: Arc<Engine>, results_kept: usize) -> Self {
        Self {
            metrics: metrics::Metrics::new(&engine.gpu().adapter),
            queue: JobQueue::new(QueueConfig::default()),
            queue_config: QueueConfig::default(),
            jobs: JobStore::new(results_kept, DEFAULT_RESULTS_TTL),
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
        }
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
    /// it (then gives up: see `jobs::persist`).
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
        Self { jobs: JobStore::new(self.results_kept, ttl), ..self }
    }

    /// Records a finished job in the metrics and in the recent jobs the dashboard shows.
    fn job_finished(&self, id: &str, method: &str, outcome: &str, seconds: f64, rendered: Option<&Rendered>) {
        self.metrics.job_finished(method, outcome, seconds, rendered.map(|r| &r.timings));
        if method.is_empty() {
            return; // Not a job yet (unparseable body): the metrics count it, the dashboard does not.
        }
        let finished_unix_ms =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_millis() as u64).unwrap_or(0);
        self.recent.record(JobSummary {
            id: id.to_string(),
            method: method.to_string(),
            outcome: outcome.to_string(),
            finished_unix_ms,
            wall_ms: seconds * 1e3,
            phases: rendered.map(|r| r.timings.phases.iter().map(|p| (p.name, p.cpu_ms)).collect()).unwrap_or_default(),
            width: rendered.map_or(0, |r| r.width),
            height: rendered.map_or(0, |r| r.height),
        });
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
    fn admit(&self) -> Result<tokio::sync::OwnedSemaphorePermit, JobError> {
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
                    let reservation =
                        store.reserve_accepted(crate::output::max_result_bytes(job.output.width, job.output.height, job.output.format));
                    self.spawn_submitted(stored.id.clone(), job, (admitted, Some(reservation)));
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
    fn spawn_submitted(self: &Arc<Self>, id: String, job: Job, admitted: Admitted) {
        let (events, _) = tokio::sync::watch::channel(JobEvent::status("queued"));
        let cancel = self.jobs.submit(id.clone(), events.clone());
        let state = self.clone();
        tokio::spawn(async move { run_submitted(state, id, job, admitted, events, cancel).await });
    }

    /// With a shared store, one worker per device slot takes jobs from the shared queue, as
    /// consumer `REPLICA/SLOT` (REPLICA: `$HOSTNAME` — the pod name under Kubernetes — else
    /// the listen address), so a job's record says where it ran.
    pub fn spawn_workers(self: &Arc<Self>, replica: &str) {
        if !self.store.as_ref().is_some_and(|s| s.shared()) {
            return;
        }
        for worker in 0..self.queue_config.concurrency {
            let consumer = format!("{replica}/{worker}");
            tokio::spawn(work_shared_queue(self.clone(), consumer));
        }
    }

    /// Drops stored results past their age or beyond the byte budget, now and then forever.
    fn spawn_expiry(self: &Arc<Self>, ttl: std::time::Duration, max_image_bytes: u64) {
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
    fn store_trouble(&self) -> Option<&'static str> {
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
pub(crate) type Admitted = (tokio::sync::OwnedSemaphorePermit, Option<crate::store::health::Reservation>);

pub fn app(state: Arc<AppState>) -> Router {
    let body_limit = state.engine.limits().max_body_bytes;
    let guard = || axum::middleware::from_fn_with_state(state.clone(), auth::require_token);
    // Everything under /v1 needs a token when tokens are configured.
    let v1 = Router::new()
        .route("/v1/render", post(render))
        .route("/v1/methods", get(methods))
        .route("/v1/limits", get(limits))
        .route("/v1/scenes", post(upload_scene))
        .route("/v1/lights", post(upload_light))
        .route("/v1/scenes/{id}", upload_routes(Kind::Scene))
        .route("/v1/lights/{id}", upload_routes(Kind::Light))
        .route("/v1/jobs", post(submit_job))
        .route("/v1/jobs/{id}", get(job_record).delete(cancel_job))
        .route("/v1/jobs/{id}/events", get(job_events))
        .route("/v1/jobs/{id}/image", get(job_image))
        .route("/v1/jobs/{id}/thumbnail", get(job_thumbnail))
        .route("/v1/stats", get(stats))
        .route_layer(guard());
    // /metrics has its own setting: scrapers often cannot send a token.
    let mut metrics_route = Router::new().route("/metrics", get(metrics));
    if !state.auth.as_ref().is_none_or(|a| a.metrics_open) {
        metrics_route = metrics_route.route_layer(guard());
    }
    let router = Router::new()
        .merge(v1)
        .merge(metrics_route)
        .route("/", get(dashboard::page))
        .route("/dashboard/{asset}", get(dashboard::asset))
        .route("/healthz", get(|| async { Json(json!({"status": "ok"})) }))
        .route("/readyz", get(readyz))
        .fallback(|| async { ApiError(JobError::new(ErrorCode::NotFound, "no such route")) })
        .layer(DefaultBodyLimit::max(body_limit));
    // CORS is closed unless origins are configured; the layer answers preflights before auth.
    let router = match &state.cors {
        Some(cors) => router.layer(cors.clone()),
        None => router,
    };
    router.with_state(state)
}

/// `GET /v1/limits`: every limit the server enforces, with its value (all configurable).
async fn limits(State(state): State<Arc<AppState>>) -> Json<Value> {
    let limits = state.engine.limits();
    Json(json!({
        "max_body_bytes": limits.max_body_bytes,
        "max_output_dim": limits.max_output_dim,
        "max_output_pixels": limits.max_output_pixels,
        "max_shadow_map_resolution": limits.max_shadow_map_resolution,
        "max_triangles": limits.max_triangles,
        "max_light_image_dim": limits.max_light_image_dim,
        "max_texture_dim": limits.max_texture_dim,
        "max_json_depth": limits.max_json_depth,
        "max_vertices": limits.max_vertices,
        "max_samples": limits.max_samples,
        "max_rounds": limits.max_rounds,
        "queue": state.queue_config.capacity,
        "concurrency": state.queue_config.concurrency,
        "deadline_secs": state.queue_config.deadline.as_secs_f64(),
        "upload_cache_bytes": state.engine.upload_stats().budget_bytes,
        "method_params": REGISTRY.iter().map(|m| (m.name().to_owned(), capped_params(m.params(), limits))).collect::<serde_json::Map<_, _>>(),
    }))
}

/// A method's parameters as `/v1/limits` lists them: ranges ending at the operator's caps.
fn capped_params(specs: &[crate::methods::ParamSpec], limits: &crate::job::Limits) -> Value {
    let mut listed = json!(specs);
    for (spec, listed) in specs.iter().zip(listed.as_array_mut().into_iter().flatten()) {
        if let (Some((cap, _)), Some(max)) = (spec.cap.map(|c| limits.cap(c)), listed["max"].as_i64()) {
            listed["max"] = json!(max.min(cap));
        }
    }
    listed
}

/// Binds, warms up, serves until SIGINT or SIGTERM, then finishes requests in flight.
pub async fn serve(config: ServeConfig, engine: Arc<Engine>) -> anyhow::Result<()> {
    let queue = QueueConfig {
        capacity: config.queue,
        concurrency: config.concurrency,
        deadline: std::time::Duration::from_secs_f64(config.deadline_secs.max(0.0)),
    };
    let ttl = std::time::Duration::from_secs_f64(config.results_ttl_secs.max(0.0));
    let mut state = AppState::new(engine.clone(), config.results_kept)
        .with_queue(queue)
        .with_results_ttl(ttl)
        .with_cors_origins(&config.cors_origins)?;
    if let Some(path) = &config.auth_token_file {
        let auth = auth::Auth::from_file(path, config.metrics_open)?;
        tracing::info!(metrics_open = auth.metrics_open, "bearer tokens required on /v1");
        state = state.with_auth(auth);
    }
    match config.job_store.as_str() {
        "memory" => tracing::warn!("job store in memory: submitted jobs are lost when the daemon stops"),
        "embedded" => {
            let store = crate::store::EmbeddedStore::open(&config.data_dir)?;
            tracing::info!(data_dir = %config.data_dir.display(), min_free_bytes = config.min_free_bytes, "job store: embedded");
            state = state.with_store(Store::new(Arc::new(store), "embedded", config.min_free_bytes));
        }
        url if url.starts_with("redis://") => {
            let claim_idle = std::time::Duration::from_secs_f64(config.claim_idle_secs.max(0.5));
            let store = crate::store::RedisStore::open(url, ttl, claim_idle)?;
            tracing::info!("job store: redis (shared queue; this replica takes jobs from it)");
            state = state.with_store(Store::new(Arc::new(store), "redis", 0));
        }
        other => anyhow::bail!("unknown --job-store `{other}` (embedded, memory or redis://HOST:PORT/DB)"),
    }
    let tracker = connections::Tracker::new(connections::ConnectionLimits::from_config(&config).within_fd_limit());
    let state = Arc::new(
        state.with_store_retry(std::time::Duration::from_secs_f64(config.store_retry_secs.max(0.0))).with_connections(tracker.clone()),
    );
    if let Some(store) = &state.store {
        store.probe().await;
        store.spawn_probe();
    }
    let resumed = state.resume_unfinished().await?;
    if resumed > 0 {
        tracing::info!(resumed, "resumed jobs accepted before the last stop");
    }
    state.spawn_expiry(ttl, config.results_bytes);
    let listener = tokio::net::TcpListener::bind(config.listen).await?;
    let lavapipe_threads = std::env::var("LP_NUM_THREADS").unwrap_or_else(|_| "unset".into());
    tracing::info!(address = %listener.local_addr()?, lavapipe_threads, max_connections = tracker.stats().max, "listening");
    tracker.spawn_sweeper();
    let listener = connections::TrackedListener::new(listener, tracker);
    let warm = state.clone();
    let no_warm_up = config.no_warm_up;
    let replica = std::env::var("HOSTNAME").ok().filter(|h| !h.is_empty()).unwrap_or_else(|| config.listen.to_string());
    tokio::spawn(async move {
        let started = std::time::Instant::now();
        if !no_warm_up {
            let engine = warm.engine.clone();
            if let Err(error) =
                tokio::task::spawn_blocking(move || engine.warm_up()).await.unwrap_or_else(|e| Err(JobError::internal(e.to_string())))
            {
                tracing::error!(%error, "warm-up failed");
                return;
            }
        }
        warm.set_ready();
        tracing::info!(duration_ms = started.elapsed().as_millis() as u64, "ready: pipelines compiled, default scene uploaded");
        // A replica of a shared store takes jobs only once it is warm.
        warm.spawn_workers(&replica);
    });
    let stopping = state.clone();
    let signal = async move {
        shutdown_signal().await;
        stopping.begin_shutdown();
    };
    let service = app(state.clone())
        .layer(axum::middleware::from_fn(connections::track))
        .into_make_service_with_connect_info::<connections::ConnRef>();
    axum::serve(listener, service).with_graceful_shutdown(signal).await?;
    // Requests in flight have finished; jobs submitted with POST /v1/jobs may still run.
    if !state.drain(state.queue.deadline + std::time::Duration::from_secs(600)).await {
        tracing::warn!("shut down with submitted jobs unfinished");
    }
    tracing::info!("shut down");
    Ok(())
}

async fn shutdown_signal() {
    let interrupt = tokio::signal::ctrl_c();
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = interrupt => {},
        _ = terminate => {},
    }
    tracing::info!("shutdown signal received; finishing requests in flight");
}

/// A body that could not be read: too large (413), or unreadable, as `unreadable`.
fn body_error(state: &AppState, rejection: BytesRejection, unreadable: ErrorCode) -> JobError {
    if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE {
        JobError::new(ErrorCode::PayloadTooLarge, format!("the body exceeds {} bytes", state.engine.limits().max_body_bytes))
    } else {
        JobError::new(unreadable, format!("cannot read the body: {rejection}"))
    }
}

/// `GET /readyz`: 200 once warm, 503 while warming up, stopping, or unable to take submitted
/// jobs (the store does not answer, or its disk is at the margin) — so a load balancer sends
/// work elsewhere while `/healthz` stays 200 and nothing restarts a healthy process.
async fn readyz(State(state): State<Arc<AppState>>) -> Response {
    let unavailable = |status: &str| (StatusCode::SERVICE_UNAVAILABLE, Json(json!({"status": status}))).into_response();
    if *state.stopping.borrow() {
        unavailable("stopping")
    } else if !state.ready.load(Ordering::SeqCst) {
        unavailable("warming up")
    } else if let Some(trouble) = state.store_trouble() {
        let mut response = unavailable(trouble);
        response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from_static("2"));
        response
    } else {
        Json(json!({"status": "ready", "adapter": state.engine.gpu().adapter})).into_response()
    }
}

async fn methods() -> Json<Value> {
    let methods: Vec<Value> = REGISTRY.iter().map(|m| json!({"name": m.name(), "summary": m.summary(), "params": m.params()})).collect();
    Json(json!({
        "methods": methods,
        "scenes": BUILTIN_SCENES,
        "light_images": BUILTIN_LIGHT_IMAGES,
    }))
}

fn wants_json(headers: &HeaderMap) -> bool {
    headers
        .get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|accept| accept.split(',').any(|t| t.trim().starts_with("application/json")))
}

async fn render(State(state): State<Arc<AppState>>, headers: HeaderMap, body: Result<Bytes, BytesRejection>) -> Result<Response, ApiError> {
    let started = std::time::Instant::now();
    let body = body.map_err(|rejection| body_error(&state, rejection, ErrorCode::InvalidJson));
    let job = body.and_then(|body| Job::from_json_limited(&body, state.engine.limits()));
    let method = job.as_ref().map(|j| j.method.name.clone()).unwrap_or_default();
    let outcome = match job {
        Ok(job) => queue_and_render(&state, &method, job).await,
        Err(error) => Err(error),
    };
    let seconds = started.elapsed().as_secs_f64();
    match outcome {
        Ok((id, rendered)) => {
            state.job_finished(&id, &method, "ok", seconds, Some(&rendered));
            if wants_json(&headers) {
                Ok(Json(job_json(&id, &rendered)).into_response())
            } else {
                Ok(image_response(&id, &rendered))
            }
        }
        Err(error) => {
            state.job_finished("", &method, error.code.as_str(), seconds, None);
            Err(ApiError(error))
        }
    }
}

/// Counts a queued job as `cancelled` if its request goes away (the client disconnected and
/// axum dropped the handler) before the job reaches the device.
struct CancelWatch<'a> {
    state: &'a AppState,
    method: &'a str,
    armed: bool,
}

impl Drop for CancelWatch<'_> {
    fn drop(&mut self) {
        if self.armed {
            tracing::info!(method = self.method, "client went away: queued job cancelled");
            self.state.job_finished("", self.method, "cancelled", 0.0, None);
        }
    }
}

/// Admits the job (or answers 429), waits for the device up to the deadline (or 503), renders.
async fn queue_and_render(state: &Arc<AppState>, method: &str, job: Job) -> Result<(String, Arc<Rendered>), JobError> {
    let admitted = state.admit()?;
    let mut watch = CancelWatch { state, method, armed: true };
    let waiting = state.metrics.job_queued();
    let device = state.queue.device().await;
    watch.armed = false;
    drop(waiting);
    let device = device?;
    let _running = state.metrics.job_running();
    render_job(state, job, (admitted, device)).await
}

/// Raises a job's cancel flag when dropped: held by a request handler, which axum drops when
/// its client disconnects.
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Renders a job on the blocking pool and keeps the result for `/v1/jobs/{id}`. A client
/// that goes away mid-render cancels the job: the render stops at its next phase or batch
/// and the device goes to the next job. The queue permits live in the render task, so the
/// place is freed only when the device is.
async fn render_job(
    state: &Arc<AppState>,
    job: Job,
    permits: (tokio::sync::OwnedSemaphorePermit, tokio::sync::OwnedSemaphorePermit),
) -> Result<(String, Arc<Rendered>), JobError> {
    let id = new_job_id();
    let span = tracing::info_span!("job", %id, method = %job.method.name);
    let cancel = Arc::new(AtomicBool::new(false));
    let _client = CancelOnDrop(cancel.clone());
    let task_state = state.clone();
    let rendered = tokio::task::spawn_blocking(move || {
        let _permits = permits;
        span.in_scope(|| {
            let started = std::time::Instant::now();
            let state = task_state;
            fetch_shared_uploads(&state.engine, state.store.as_ref(), &job)?;
            let observer = Supervise {
                progress: |done, total| tracing::debug!(done, total, "progress"),
                cancelled: || cancel.load(Ordering::Relaxed),
            };
            let rendered = state.engine.render(&job, &observer);
            // Its handler is gone with its client: the outcome is counted here.
            if matches!(&rendered, Err(error) if error.code == ErrorCode::Cancelled) {
                tracing::info!("client went away: job cancelled mid-render");
                state.job_finished("", &job.method.name, "cancelled", started.elapsed().as_secs_f64(), None);
            }
            rendered
        })
    })
    .await
    .map_err(|e| JobError::internal(format!("render task failed: {e}")))??;
    tracing::info!(%id, total_ms = rendered.timings.total_ms, "job done");
    let rendered = Arc::new(rendered);
    state.jobs.keep(id.clone(), rendered.clone());
    Ok((id, rendered))
}

/// `GET /metrics`: Prometheus text format.
async fn metrics(State(state): State<Arc<AppState>>) -> Response {
    state.metrics.observe_service(state.store.as_ref().map(|s| s.health().status()), state.connections.as_ref().map(|c| c.stats()));
    let text = state.metrics.encode(&state.engine.stats());
    ([(header::CONTENT_TYPE, HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"))], text).into_response()
}

/// Jobs listed in `/v1/stats` (newest first).
const STATS_RECENT: usize = 40;

/// `GET /v1/stats`: what the dashboard draws — the engine's caches, pools and uploads, the
/// queue, and the recent jobs with throughput, latency per method and phase breakdowns.
async fn stats(State(state): State<Arc<AppState>>) -> Json<Value> {
    let uptime_s = state.started.elapsed().map(|d| d.as_secs_f64()).unwrap_or(0.0);
    Json(json!({
        "adapter": state.engine.gpu().adapter,
        "uptime_s": uptime_s,
        "jobs_in_flight": state.metrics.in_flight(),
        "jobs_queued": state.metrics.queued(),
        "queue": {"capacity": state.queue_config.capacity, "concurrency": state.queue_config.concurrency},
        "store": state.store.as_ref().map(|s| s.health().status()),
        "connections": state.connections.as_ref().map(|c| c.stats()),
        "engine": state.engine.stats(),
        "jobs": {
            "per_minute": state.recent.per_minute(std::time::Duration::from_secs(60)),
            "by_method": state.recent.latency_by_method(),
            "recent": state.recent.newest(STATS_RECENT),
        },
    }))
}

fn job_json(id: &str, rendered: &Rendered) -> Value {
    json!({
        "id": id,
        "status": "succeeded",
        "method": rendered.method,
        "width": rendered.width,
        "height": rendered.height,
        "format": rendered.format,
        "bytes": rendered.bytes.len(),
        "timings": rendered.timings,
        "counters": rendered.counters,
        "quality": rendered.quality,
        "image": format!("/v1/jobs/{id}/image"),
    })
}

fn image_response(id: &str, rendered: &Rendered) -> Response {
    let mut response = rendered.bytes.clone().into_response();
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(rendered.format.mime()));
    if let Ok(timing) = HeaderValue::from_str(&rendered.timings.server_timing()) {
        headers.insert("server-timing", timing);
    }
    if let Ok(id) = HeaderValue::from_str(id) {
        headers.insert("x-penumbra-job-id", id);
    }
    response
}
