//! The HTTP service (DESIGN.md §3): `app(state)` builds the router, `serve` binds it, warms
//! the engine up and shuts down gracefully. Rendering runs on the blocking pool so the
//! async workers keep answering health checks while the device is busy.

pub mod auth;
mod dashboard;
pub mod error;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
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
use crate::light::BUILTIN_LIGHT_IMAGES;
use crate::methods::REGISTRY;
use crate::render::Cancellable;
use crate::scene::builtin::BUILTIN_SCENES;
use crate::uploads::{content_id, is_content_id, Kind};
use error::ApiError;

pub use crate::jobs::QueueConfig;

/// How long finished jobs stay readable unless configured (`--results-ttl-secs`).
pub const DEFAULT_RESULTS_TTL: std::time::Duration = std::time::Duration::from_secs(3600);

/// How often an idle worker of a shared store asks the queue for a job (the most an async job
/// waits for an idle replica).
const SHARED_QUEUE_POLL: std::time::Duration = std::time::Duration::from_millis(50);

/// Finished jobs remembered for the dashboard's charts.
const RECENT_JOBS: usize = 200;
use crate::jobs::{JobEvent, JobQueue, JobStore, JobSummary, RecentJobs};
use crate::store::{JobStore as DurableStore, StoredJob, MAX_ATTEMPTS};

pub struct AppState {
    engine: Arc<Engine>,
    metrics: crate::metrics::Metrics,
    queue: JobQueue,
    queue_config: QueueConfig,
    jobs: JobStore,
    results_kept: usize,
    /// The last finished jobs, for `/v1/stats` and the dashboard.
    recent: RecentJobs,
    /// Where submitted jobs and their results are kept durably (None: memory only).
    store: Option<Arc<dyn DurableStore>>,
    /// Set at shutdown: event streams end (clients reconnect elsewhere or after the restart),
    /// and with a durable store, jobs still waiting for the device stay queued there for the
    /// next start instead of holding the shutdown up.
    stopping: tokio::sync::watch::Sender<bool>,
    /// Bearer tokens (None: the API is open).
    auth: Option<auth::Auth>,
    /// Allowed cross-origin callers (None: CORS closed).
    cors: Option<tower_http::cors::CorsLayer>,
    ready: AtomicBool,
    next_id: AtomicU64,
    started: std::time::SystemTime,
}

impl AppState {
    pub fn new(engine: Arc<Engine>, results_kept: usize) -> Self {
        Self {
            metrics: crate::metrics::Metrics::new(&engine.gpu().adapter),
            queue: JobQueue::new(QueueConfig::default()),
            queue_config: QueueConfig::default(),
            jobs: JobStore::new(results_kept, DEFAULT_RESULTS_TTL),
            results_kept,
            recent: RecentJobs::new(RECENT_JOBS),
            store: None,
            stopping: tokio::sync::watch::channel(false).0,
            auth: None,
            cors: None,
            engine,
            ready: AtomicBool::new(false),
            next_id: AtomicU64::new(1),
            started: std::time::SystemTime::now(),
        }
    }

    pub fn with_queue(self, queue: QueueConfig) -> Self {
        Self { queue: JobQueue::new(queue), queue_config: queue, ..self }
    }

    /// Keeps submitted jobs and their results in `store`, so that they survive a restart.
    pub fn with_store(self, store: Arc<dyn DurableStore>) -> Self {
        Self { store: Some(store), ..self }
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

    /// Tells waiting jobs and event streams that the daemon is stopping.
    pub fn begin_shutdown(&self) {
        self.stopping.send_replace(true);
    }

    /// Submits again every job the store holds unfinished (queued, or running when the last
    /// daemon stopped), oldest first; one started `MAX_ATTEMPTS` times already fails instead.
    /// Returns how many were resumed.
    pub async fn resume_unfinished(self: &Arc<Self>) -> anyhow::Result<usize> {
        let Some(store) = self.store.clone() else { return Ok(0) };
        let unfinished = tokio::task::spawn_blocking(move || store.unfinished()).await??;
        let mut resumed = 0;
        for stored in unfinished {
            let job = Job::from_json_limited(stored.job.to_string().as_bytes(), self.engine.limits());
            let failure = match job {
                Ok(_) if stored.attempts >= MAX_ATTEMPTS => Some(abandoned(stored.attempts)),
                Ok(job) => {
                    let admitted = self.queue.admit_waiting().await?;
                    self.spawn_submitted(stored.id.clone(), job, admitted);
                    resumed += 1;
                    None
                }
                Err(error) => Some(failure_detail(&error)),
            };
            if let Some(detail) = failure {
                tracing::warn!(id = %stored.id, %detail, "stored job failed at resumption");
                let store = self.store.clone();
                tokio::task::spawn_blocking(move || store.map(|s| s.fail(&stored.id, &detail))).await?.transpose()?;
            }
        }
        Ok(resumed)
    }

    /// Registers a submitted job's event channel and starts its life in the background.
    fn spawn_submitted(self: &Arc<Self>, id: String, job: Job, admitted: tokio::sync::OwnedSemaphorePermit) {
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
                let store = store.clone();
                match tokio::task::spawn_blocking(move || store.expire(ttl, max_image_bytes)).await {
                    Ok(Ok((0, 0))) => {}
                    Ok(Ok((records, images))) => tracing::info!(records, images, "expired stored results"),
                    Ok(Err(error)) => tracing::warn!(%error, "expiring stored results failed"),
                    Err(_) => {}
                }
            }
        });
    }

    pub fn set_ready(&self) {
        self.ready.store(true, Ordering::SeqCst);
    }

    /// A job id unique to this process: start time and a counter.
    fn new_id(&self) -> String {
        let epoch = self.started.duration_since(std::time::UNIX_EPOCH).map(|d| d.as_millis()).unwrap_or(0);
        format!("{epoch:012x}{:08x}", self.next_id.fetch_add(1, Ordering::Relaxed))
    }
}

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
        if let (Some((cap, _)), Some(max)) = (limits.param_cap(spec.name), listed["max"].as_i64()) {
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
            tracing::info!(data_dir = %config.data_dir.display(), "job store: embedded");
            state = state.with_store(Arc::new(store));
        }
        url if url.starts_with("redis://") => {
            let claim_idle = std::time::Duration::from_secs_f64(config.claim_idle_secs.max(0.5));
            let store = crate::store::RedisStore::open(url, ttl, claim_idle)?;
            tracing::info!("job store: redis (shared queue; this replica takes jobs from it)");
            state = state.with_store(Arc::new(store));
        }
        other => anyhow::bail!("unknown --job-store `{other}` (embedded, memory or redis://HOST:PORT/DB)"),
    }
    let state = Arc::new(state);
    let resumed = state.resume_unfinished().await?;
    if resumed > 0 {
        tracing::info!(resumed, "resumed jobs accepted before the last stop");
    }
    state.spawn_expiry(ttl, config.results_bytes);
    let listener = tokio::net::TcpListener::bind(config.listen).await?;
    let lavapipe_threads = std::env::var("LP_NUM_THREADS").unwrap_or_else(|_| "unset".into());
    tracing::info!(address = %listener.local_addr()?, lavapipe_threads, "listening");
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
    axum::serve(listener, app(state.clone())).with_graceful_shutdown(signal).await?;
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

/// `POST /v1/scenes`: a glTF (JSON with `data:` buffers) or GLB body → its content id. 201
/// when stored now, 200 when the same bytes were already there.
async fn upload_scene(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Response {
    upload(state, body, Kind::Scene).await
}

/// `POST /v1/lights`: a PNG or EXR body → its content id.
async fn upload_light(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Response {
    upload(state, body, Kind::Light).await
}

async fn upload(state: Arc<AppState>, body: Result<Bytes, BytesRejection>, kind: Kind) -> Response {
    let bytes = match body {
        Ok(bytes) => bytes,
        Err(rejection) => return ApiError(body_error(&state, rejection, ErrorCode::InvalidAsset)).into_response(),
    };
    let engine = state.engine.clone();
    let shared = state.store.clone().filter(|s| s.shared());
    // Decoding a large scene takes a while: off the async workers. A shared store keeps the
    // bytes once for every replica (after they decoded: a bad file is refused, not shared).
    let stored = move || {
        let receipt = engine.upload(kind, &bytes)?;
        if let Some(store) = shared {
            store.put_upload(kind, &receipt.id, &bytes).map_err(|e| JobError::internal(format!("cannot share the upload: {e}")))?;
        }
        Ok(receipt)
    };
    match tokio::task::spawn_blocking(stored).await {
        Ok(Ok(receipt)) => {
            let status = if receipt.created { StatusCode::CREATED } else { StatusCode::OK };
            (status, Json(receipt)).into_response()
        }
        Ok(Err(error)) => ApiError(error).into_response(),
        Err(_) => ApiError(JobError::new(ErrorCode::Internal, "the upload failed")).into_response(),
    }
}

/// `PUT`, `HEAD` and `DELETE` on `/v1/scenes/{id}` or `/v1/lights/{id}`.
fn upload_routes(kind: Kind) -> axum::routing::MethodRouter<Arc<AppState>> {
    axum::routing::put(move |state: State<Arc<AppState>>, id: Path<String>, body: Result<Bytes, BytesRejection>| {
        put_upload(kind, state, id, body)
    })
    .head(move |state: State<Arc<AppState>>, Path(id): Path<String>| async move {
        if state.engine.holds_upload(kind, &id) {
            return StatusCode::OK;
        }
        let Some(store) = state.store.clone().filter(|s| s.shared()) else { return StatusCode::NOT_FOUND };
        match tokio::task::spawn_blocking(move || store.has_upload(kind, &id)).await {
            Ok(Ok(true)) => StatusCode::OK,
            _ => StatusCode::NOT_FOUND,
        }
    })
    .delete(move |state: State<Arc<AppState>>, id: Path<String>| delete_upload(kind, state, id))
}

/// `PUT /v1/scenes/{id}`, `PUT /v1/lights/{id}`: an idempotent upload under the id the client
/// computed (the SHA-256 of the body, checked here); 201 when stored now, 200 when held.
async fn put_upload(
    kind: Kind,
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    body: Result<Bytes, BytesRejection>,
) -> Response {
    if !is_content_id(&id) {
        let message = "an upload id is the lowercase hex SHA-256 of the bytes (64 digits)";
        return ApiError(JobError::field(ErrorCode::InvalidField, "id", message)).into_response();
    }
    let bytes = match body {
        Ok(bytes) => bytes,
        Err(rejection) => return ApiError(body_error(&state, rejection, ErrorCode::InvalidAsset)).into_response(),
    };
    let actual = content_id(&bytes);
    if actual != id {
        let message = format!("the body's SHA-256 is {actual}, not the id in the path");
        return ApiError(JobError::field(ErrorCode::InvalidField, "id", message)).into_response();
    }
    upload(state, Ok(bytes), kind).await
}

/// `DELETE /v1/scenes/{id}`, `DELETE /v1/lights/{id}`: 204, or 404 when there was none.
async fn delete_upload(kind: Kind, State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Response {
    let mut deleted = state.engine.delete_upload(kind, &id);
    if let Some(store) = state.store.clone().filter(|s| s.shared()) {
        let shared_id = id.clone();
        deleted |= matches!(tokio::task::spawn_blocking(move || store.delete_upload(kind, &shared_id)).await, Ok(Ok(true)));
    }
    if deleted {
        StatusCode::NO_CONTENT.into_response()
    } else {
        ApiError(JobError::field(ErrorCode::NotUploaded, "id", format!("no uploaded asset with id `{id}`"))).into_response()
    }
}

async fn readyz(State(state): State<Arc<AppState>>) -> Response {
    if state.ready.load(Ordering::SeqCst) {
        Json(json!({"status": "ready", "adapter": state.engine.gpu().adapter})).into_response()
    } else {
        (StatusCode::SERVICE_UNAVAILABLE, Json(json!({"status": "warming up"}))).into_response()
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
    let admitted = state.queue.admit()?;
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
    let id = state.new_id();
    let span = tracing::info_span!("job", %id, method = %job.method.name);
    let cancel = Arc::new(AtomicBool::new(false));
    let _client = CancelOnDrop(cancel.clone());
    let task_state = state.clone();
    let rendered = tokio::task::spawn_blocking(move || {
        let _permits = permits;
        span.in_scope(|| {
            let started = std::time::Instant::now();
            let state = task_state;
            fetch_shared_uploads(&state.engine, state.store.as_deref(), &job)?;
            let observer = Cancellable {
                progress: |done, total| tracing::debug!(done, total, "progress"),
                cancelled: || cancel.load(Ordering::Relaxed),
            };
            let rendered = state.engine.render_observed(&job, &observer);
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

async fn job_record(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<Value>, ApiError> {
    if let Some(rendered) = state.jobs.find(&id) {
        return Ok(Json(job_json(&id, &rendered)));
    }
    if let Some(events) = state.jobs.submitted(&id) {
        let event = events.borrow().clone();
        return Ok(Json(
            json!({"id": id, "status": event.status, "progress": {"done": event.done, "total": event.total}, "error": event.error}),
        ));
    }
    let stored = stored_job(&state, &id).await?.ok_or_else(|| unknown_job(&id))?;
    Ok(Json(match stored.result {
        Some(result) if stored.status == "succeeded" => result,
        _ => json!({"id": id, "status": stored.status, "progress": {"done": stored.done, "total": stored.total}, "error": stored.error}),
    }))
}

/// A job from the durable store (one this process did not run, or no longer holds).
async fn stored_job(state: &AppState, id: &str) -> Result<Option<StoredJob>, ApiError> {
    let Some(store) = state.store.clone() else { return Ok(None) };
    let id = id.to_owned();
    let stored = tokio::task::spawn_blocking(move || store.get(&id)).await.map_err(|e| JobError::internal(e.to_string()))?;
    Ok(stored.map_err(|error| JobError::internal(format!("the job store failed: {error}")))?)
}

/// `POST /v1/jobs`: validates and admits the job (4xx, or 429 when the queue is full), answers
/// 202 with its id at once, and renders it in the background: `GET /v1/jobs/{id}` for its
/// state, `/events` for server-sent progress, `/image` once it succeeded.
async fn submit_job(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Result<Response, ApiError> {
    let body = body.map_err(|rejection| body_error(&state, rejection, ErrorCode::InvalidJson));
    let parsed = body.and_then(|body| {
        let job = Job::from_json_limited(&body, state.engine.limits())?;
        job.validate(state.engine.limits())?;
        // The job as sent (it parsed, so it is JSON): what the store keeps and resumes.
        let sent: Value = serde_json::from_slice(&body).map_err(|e| JobError::new(ErrorCode::InvalidJson, e.to_string()))?;
        Ok((job, sent))
    });
    let (job, sent) = parsed.inspect_err(|error| state.job_finished("", "", error.code.as_str(), 0.0, None))?;
    let shared = state.store.clone().filter(|s| s.shared());
    if let Some(store) = &shared {
        // The shared queue is bounded as a whole, by the same --queue.
        let store = store.clone();
        let queued = tokio::task::spawn_blocking(move || store.queued()).await.map_err(|e| JobError::internal(e.to_string()))?;
        let queued = queued.map_err(|error| JobError::internal(format!("the job store failed: {error}")))?;
        if queued >= u64::from(state.queue_config.capacity) {
            let error = JobError::new(ErrorCode::QueueFull, "the shared job queue is full; retry after the Retry-After seconds");
            state.job_finished("", &job.method.name, error.code.as_str(), 0.0, None);
            return Err(ApiError(error));
        }
    }
    // A local place in the queue, unless the shared queue holds the job (its workers take one
    // when they take the job).
    let admitted = match shared {
        Some(_) => None,
        None => Some(state.queue.admit().inspect_err(|error| state.job_finished("", &job.method.name, error.code.as_str(), 0.0, None))?),
    };
    let id = state.new_id();
    // Durable before the 202: an accepted job survives a crash from here on.
    if let Some(store) = state.store.clone() {
        let stored_id = id.clone();
        tokio::task::spawn_blocking(move || store.accept(&stored_id, &sent))
            .await
            .map_err(|e| JobError::internal(e.to_string()))?
            .map_err(|error| {
                tracing::error!(%error, "cannot record a submitted job");
                JobError::internal("the job store failed; the job was not accepted")
            })?;
    }
    if let Some(admitted) = admitted {
        state.spawn_submitted(id.clone(), job, admitted);
    }
    let links = json!({"id": id, "status": "queued", "record": format!("/v1/jobs/{id}"), "events": format!("/v1/jobs/{id}/events")});
    Ok((StatusCode::ACCEPTED, [(header::LOCATION, format!("/v1/jobs/{id}"))], Json(links)).into_response())
}

/// A submitted job's life: wait for the device (up to the deadline; at shutdown with a
/// durable store, stop waiting and stay queued there; cancelled, leave the queue), then
/// render and store it.
async fn run_submitted(
    state: Arc<AppState>,
    id: String,
    job: Job,
    admitted: tokio::sync::OwnedSemaphorePermit,
    events: tokio::sync::watch::Sender<JobEvent>,
    cancel: tokio::sync::watch::Receiver<bool>,
) {
    let started = std::time::Instant::now();
    let waiting = state.metrics.job_queued();
    let mut stopping = state.stopping.subscribe();
    let mut cancelled = cancel.clone();
    let durable = state.store.is_some();
    let device = tokio::select! {
        device = state.queue.device() => device,
        _ = stopping.wait_for(|stop| *stop), if durable => {
            tracing::info!(%id, "shutting down: the job stays queued in the store for the next start");
            return;
        }
        Ok(_) = cancelled.wait_for(|c| *c) => Err(crate::render::cancelled_error()),
    };
    drop(waiting);
    match device {
        Ok(device) => render_and_store(&state, id, job, vec![admitted, device], events, cancel, started).await,
        Err(error) => finish_failed(&state, &id, &job.method.name, error, started, &events).await,
    }
}

/// One worker of a replica on a shared store: with a free device slot, takes the next job
/// (a dead replica's first), keeps it claimed while it renders, stores the outcome.
async fn work_shared_queue(state: Arc<AppState>, consumer: String) {
    let Some(store) = state.store.clone() else { return };
    let mut stopping = state.stopping.subscribe();
    loop {
        let device = tokio::select! {
            device = state.queue.device_slot() => device,
            _ = stopping.wait_for(|stop| *stop) => return,
        };
        let Some(device) = device.filter(|_| !*stopping.borrow()) else { return };
        // Asked without waiting: an idle worker must not sit on the device slot that a
        // synchronous render needs, so when the queue is empty it lets go and asks again soon.
        let (taker, name) = (store.clone(), consumer.clone());
        let taken = tokio::task::spawn_blocking(move || taker.next(&name, std::time::Duration::ZERO)).await;
        let stored = match taken {
            Ok(Ok(Some(stored))) => stored,
            Ok(Ok(None)) => {
                drop(device);
                tokio::time::sleep(SHARED_QUEUE_POLL).await;
                continue;
            }
            Ok(Err(error)) => {
                tracing::warn!(%error, "cannot take a job from the shared queue; retrying in 1 s");
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
                continue;
            }
            Err(_) => continue,
        };
        let Ok(admitted) = state.queue.admit_waiting().await else { return };
        let started = std::time::Instant::now();
        let (events, _) = tokio::sync::watch::channel(JobEvent::status("queued"));
        let cancel = state.jobs.submit(stored.id.clone(), events.clone());
        let method = stored.job["method"]["name"].as_str().unwrap_or("hard").to_owned();
        let job = match Job::from_json_limited(stored.job.to_string().as_bytes(), state.engine.limits()) {
            Ok(_) if stored.attempts >= MAX_ATTEMPTS => {
                let detail = abandoned(stored.attempts);
                store_failure(&state, &stored.id, detail.clone()).await;
                events.send_modify(|event| event.finish("failed", Some(detail)));
                continue;
            }
            Ok(job) => job,
            Err(error) => {
                finish_failed(&state, &stored.id, &method, error, started, &events).await;
                continue;
            }
        };
        // Renew the claim while the job renders, so no other replica takes it over, and stop
        // it if a replica that got its `DELETE` marked it cancelled in the store.
        let (beat_store, beat_consumer, beat_job, beat_state) = (store.clone(), consumer.clone(), stored.clone(), state.clone());
        let heartbeat = tokio::spawn(async move {
            let mut tick = tokio::time::interval(beat_store.heartbeat_every());
            loop {
                tick.tick().await;
                let (s, c, j) = (beat_store.clone(), beat_consumer.clone(), beat_job.clone());
                match tokio::task::spawn_blocking(move || s.heartbeat(&c, &j).and_then(|()| s.get(&j.id))).await {
                    Ok(Ok(Some(record))) if record.status == "cancelled" => {
                        beat_state.jobs.cancel(&beat_job.id);
                    }
                    Ok(Err(error)) => tracing::warn!(%error, "cannot renew the claim on a job"),
                    _ => {}
                }
            }
        });
        render_and_store(&state, stored.id.clone(), job, vec![admitted, device], events, cancel, started).await;
        heartbeat.abort();
    }
}

/// The error of a job that daemons kept dying on: said in full, since the reason is the
/// point and reveals nothing internal.
fn abandoned(attempts: u32) -> Value {
    json!({
        "code": "internal",
        "status": 500,
        "message": format!("the job was started {attempts} times by daemons that stopped before it finished; it is not retried again"),
    })
}

/// Renders a job that holds its device slot (`permits`), reporting progress (to the shared
/// store too, at most every 250 ms), and stores the outcome.
async fn render_and_store(
    state: &Arc<AppState>,
    id: String,
    job: Job,
    permits: Vec<tokio::sync::OwnedSemaphorePermit>,
    events: tokio::sync::watch::Sender<JobEvent>,
    cancel: tokio::sync::watch::Receiver<bool>,
    started: std::time::Instant,
) {
    let method = job.method.name.clone();
    events.send_replace(JobEvent::status("running"));
    let running = state.metrics.job_running();
    let engine = state.engine.clone();
    let store = state.store.clone();
    let progress = events.clone();
    let span = tracing::info_span!("job", %id, method = %method);
    let job_id = id.clone();
    let outcome = tokio::task::spawn_blocking(move || {
        span.in_scope(|| {
            if let Some(store) = &store {
                if let Err(error) = store.start(&job_id) {
                    tracing::warn!(%error, "cannot mark the job running in the store");
                }
            }
            fetch_shared_uploads(&engine, store.as_deref(), &job)?;
            let last_shared = std::sync::Mutex::new(std::time::Instant::now());
            let report = |done, total| {
                progress.send_modify(|event| {
                    event.done = done;
                    event.total = total;
                });
                if let Some(store) = store.as_ref().filter(|s| s.shared()) {
                    let mut last = last_shared.lock().unwrap_or_else(|p| p.into_inner());
                    if last.elapsed() >= std::time::Duration::from_millis(250) {
                        *last = std::time::Instant::now();
                        let _ = store.progress(&job_id, done, total);
                    }
                }
            };
            let rendered = engine.render_observed(&job, &Cancellable { progress: report, cancelled: || *cancel.borrow() })?;
            if let Some(store) = &store {
                store
                    .succeed(&job_id, &job_json(&job_id, &rendered), &rendered.bytes)
                    .map_err(|error| JobError::internal(format!("cannot store the result: {error}")))?;
            }
            Ok(rendered)
        })
    })
    .await
    .unwrap_or_else(|e| Err(JobError::internal(format!("render task failed: {e}"))));
    drop(running);
    match outcome {
        Ok(rendered) => {
            state.job_finished(&id, &method, "ok", started.elapsed().as_secs_f64(), Some(&rendered));
            tracing::info!(%id, total_ms = rendered.timings.total_ms, "job done");
            state.jobs.keep(id, Arc::new(rendered));
            events.send_modify(|event| event.finish("succeeded", None));
        }
        Err(error) => finish_failed(state, &id, &method, error, started, &events).await,
    }
    // The queue places go only now: a drain that sees them back finds the job recorded.
    drop(permits);
}

/// Records, stores and announces a job's failure (or cancellation).
async fn finish_failed(
    state: &Arc<AppState>,
    id: &str,
    method: &str,
    error: JobError,
    started: std::time::Instant,
    events: &tokio::sync::watch::Sender<JobEvent>,
) {
    state.job_finished(id, method, error.code.as_str(), started.elapsed().as_secs_f64(), None);
    let detail = failure_detail(&error);
    let status = StoredJob::status_after(&detail);
    if status == "cancelled" {
        tracing::info!(%id, "job cancelled");
    }
    store_failure(state, id, detail.clone()).await;
    events.send_modify(|event| event.finish(status, Some(detail)));
}

async fn store_failure(state: &AppState, id: &str, detail: Value) {
    let Some(store) = state.store.clone() else { return };
    let stored_id = id.to_owned();
    if !matches!(tokio::task::spawn_blocking(move || store.fail(&stored_id, &detail)).await, Ok(Ok(()))) {
        tracing::warn!(%id, "cannot store the job's failure");
    }
}

/// Loads into the engine's cache the uploads a job names that this replica does not hold but
/// the shared store does (another replica received them).
fn fetch_shared_uploads(engine: &Engine, store: Option<&dyn DurableStore>, job: &Job) -> Result<(), JobError> {
    let Some(store) = store.filter(|s| s.shared()) else { return Ok(()) };
    let light = job.light.image.as_ref();
    for (kind, asset) in [(Kind::Scene, Some(&job.scene)), (Kind::Light, light)] {
        let Some(crate::job::AssetRef::Id(id)) = asset else { continue };
        if engine.holds_upload(kind, id) {
            continue;
        }
        match store.get_upload(kind, id) {
            Ok(Some(bytes)) => {
                engine.upload(kind, &bytes)?;
            }
            Ok(None) => {} // The render reports `not_uploaded` for the field.
            Err(error) => tracing::warn!(%error, "cannot read a shared upload"),
        }
    }
    Ok(())
}

/// A failed job's error as its record and events carry it: the error body with its status.
fn failure_detail(error: &JobError) -> Value {
    let mut detail = error::error_body(error);
    detail["status"] = json!(error::status_of(error.code).as_u16());
    detail
}

/// `GET /v1/jobs/{id}/events`: server-sent events — `progress` with the job's state at once and
/// on every change, then one `succeeded` or `failed`, and the stream ends.
async fn job_events(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    use axum::response::sse::{Event, KeepAlive, Sse};
    let events = match state.jobs.submitted(&id) {
        Some(events) => events,
        // Finished under an earlier process, or running on another replica of a shared store:
        // its stored state, followed by polling the store until it finishes.
        None => {
            let stored = stored_job(&state, &id).await?.ok_or_else(|| unknown_job(&id))?;
            let (events, _) = tokio::sync::watch::channel(event_of(&stored));
            if let Some(store) = state.store.clone().filter(|_| !stored.finished()) {
                tokio::spawn(follow_stored(store, id.clone(), events.clone()));
            }
            events
        }
    };
    let receiver = events.subscribe();
    // (receiver, ended): the current state first, then each change, until a final one.
    let stopping = state.stopping.subscribe();
    let stream = futures_util::stream::unfold((receiver, stopping, false, true), |(mut receiver, mut stopping, ended, first)| async move {
        if ended {
            return None;
        }
        if !first {
            tokio::select! {
                changed = receiver.changed() => changed.ok()?,
                // A shutdown ends the stream: graceful shutdown waits for open responses.
                _ = stopping.wait_for(|stop| *stop) => return None,
            }
        }
        let event = receiver.borrow_and_update().clone();
        let name = if event.finished() { event.status } else { "progress" };
        let sse = Event::default().event(name).json_data(&event).unwrap_or_else(|_| Event::default().event(name));
        Some((Ok::<_, std::convert::Infallible>(sse), (receiver, stopping, event.finished(), false)))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()).into_response())
}

/// A stored job's state as an event.
fn event_of(stored: &StoredJob) -> JobEvent {
    let status = match stored.status.as_str() {
        "running" => "running",
        "succeeded" => "succeeded",
        "failed" => "failed",
        "cancelled" => "cancelled",
        _ => "queued",
    };
    let mut event = JobEvent::status(status);
    (event.done, event.total) = (stored.done, stored.total);
    if event.finished() {
        event.finish(status, stored.error.clone());
    }
    event
}

/// Polls the store for a job another replica runs, every 50 ms (one small GET: cheap for
/// Redis, and what a client waits at most beyond the job), until it finishes, its record
/// goes, or nobody listens any more.
async fn follow_stored(store: Arc<dyn DurableStore>, id: String, events: tokio::sync::watch::Sender<JobEvent>) {
    loop {
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        if events.receiver_count() == 0 {
            return;
        }
        let (reader, job) = (store.clone(), id.clone());
        let Ok(Ok(Some(stored))) = tokio::task::spawn_blocking(move || reader.get(&job)).await else { return };
        let event = event_of(&stored);
        let finished = event.finished();
        events.send_if_modified(|current| {
            let changed = (current.status, current.done, current.total) != (event.status, event.done, event.total);
            *current = event;
            changed
        });
        if finished {
            return;
        }
    }
}

/// `DELETE /v1/jobs/{id}`: cancels a submitted job that has not finished. A waiting job leaves
/// the queue at once; a running one stops at its next phase or sample batch (on another
/// replica of a shared store: at its next heartbeat). Answers 202 with the job's record as it
/// is now; its events end with `cancelled`. A finished job answers 409.
async fn cancel_job(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    let already_finished = || ApiError(JobError::new(ErrorCode::Conflict, format!("job `{id}` has already finished")));
    match state.jobs.cancel(&id) {
        Some(true) => {}
        Some(false) => return Err(already_finished()),
        // Not held here: a job in the shared store that another replica runs or will run.
        None => {
            let stored = stored_job(&state, &id).await?.ok_or_else(|| unknown_job(&id))?;
            if stored.finished() {
                return Err(already_finished());
            }
            let error = crate::render::cancelled_error();
            // A running job is counted where it runs, when it stops; a waiting one only here.
            if stored.status == "queued" {
                state.job_finished(&id, stored.job["method"]["name"].as_str().unwrap_or(""), error.code.as_str(), 0.0, None);
            }
            store_failure(&state, &id, failure_detail(&error)).await;
        }
    }
    tracing::info!(%id, "job cancellation requested");
    let record = job_record(State(state), Path(id)).await?;
    Ok((StatusCode::ACCEPTED, record).into_response())
}

async fn job_image(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    if let Some(rendered) = state.jobs.find(&id) {
        return Ok(image_response(&id, &rendered));
    }
    // A result from the durable store: the bytes and the format its record names.
    let stored = stored_job(&state, &id).await?.filter(|job| job.image_bytes > 0).ok_or_else(|| unknown_job(&id))?;
    let Some(store) = state.store.clone() else { return Err(unknown_job(&id)) };
    let image_id = id.clone();
    let bytes = tokio::task::spawn_blocking(move || store.image(&image_id))
        .await
        .map_err(|e| JobError::internal(e.to_string()))?
        .map_err(|error| JobError::internal(format!("the job store failed: {error}")))?
        .ok_or_else(|| unknown_job(&id))?;
    let mime = if stored.result.as_ref().is_some_and(|r| r["format"] == "exr") { "image/x-exr" } else { "image/png" };
    Ok(([(header::CONTENT_TYPE, mime)], bytes).into_response())
}

/// `GET /v1/jobs/{id}/thumbnail`: a small PNG of a kept result (the dashboard's previews).
/// Results never change under their id, so browsers may cache it for good.
async fn job_thumbnail(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    let rendered = state.jobs.find(&id).ok_or_else(|| unknown_job(&id))?;
    let png = tokio::task::spawn_blocking(move || crate::output::thumbnail(&rendered.bytes, THUMBNAIL_SIZE))
        .await
        .map_err(|e| JobError::internal(format!("thumbnail task failed: {e}")))??;
    Ok(([(header::CONTENT_TYPE, "image/png"), (header::CACHE_CONTROL, "private, max-age=86400, immutable")], png).into_response())
}

/// Longest side of a thumbnail, pixels.
const THUMBNAIL_SIZE: u32 = 160;

fn unknown_job(id: &str) -> ApiError {
    ApiError(JobError::new(ErrorCode::NotFound, format!("no finished job `{id}` is kept on this server")))
}
