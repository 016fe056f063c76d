//! The HTTP service (DESIGN.md §3): `app(state)` builds the router, `serve` binds it, warms
//! the engine up and shuts down gracefully. Rendering runs on the blocking pool so the
//! async workers keep answering health checks while the device is busy.

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
use crate::scene::builtin::BUILTIN_SCENES;
use error::ApiError;

pub use crate::jobs::QueueConfig;

/// How long finished jobs stay readable unless configured (`--results-ttl-secs`).
pub const DEFAULT_RESULTS_TTL: std::time::Duration = std::time::Duration::from_secs(3600);

/// Finished jobs remembered for the dashboard's charts.
const RECENT_JOBS: usize = 200;
use crate::jobs::{JobEvent, JobQueue, JobStore, JobSummary, RecentJobs};

pub struct AppState {
    engine: Arc<Engine>,
    metrics: crate::metrics::Metrics,
    queue: JobQueue,
    queue_config: QueueConfig,
    jobs: JobStore,
    results_kept: usize,
    /// The last finished jobs, for `/v1/stats` and the dashboard.
    recent: RecentJobs,
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
            engine,
            ready: AtomicBool::new(false),
            next_id: AtomicU64::new(1),
            started: std::time::SystemTime::now(),
        }
    }

    pub fn with_queue(self, queue: QueueConfig) -> Self {
        Self { queue: JobQueue::new(queue), queue_config: queue, ..self }
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

    /// See `JobQueue::drain`: for a shutdown that finishes the work it accepted.
    pub async fn drain(&self, limit: std::time::Duration) -> bool {
        self.queue.drain(limit).await
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
    Router::new()
        .route("/v1/render", post(render))
        .route("/v1/methods", get(methods))
        .route("/v1/scenes", post(upload_scene))
        .route("/v1/lights", post(upload_light))
        .route("/v1/scenes/{id}", axum::routing::delete(delete_upload))
        .route("/v1/lights/{id}", axum::routing::delete(delete_upload))
        .route("/v1/jobs", post(submit_job))
        .route("/v1/jobs/{id}", get(job_record))
        .route("/v1/jobs/{id}/events", get(job_events))
        .route("/v1/jobs/{id}/image", get(job_image))
        .route("/v1/jobs/{id}/thumbnail", get(job_thumbnail))
        .route("/", get(dashboard::page))
        .route("/dashboard/{asset}", get(dashboard::asset))
        .route("/v1/stats", get(stats))
        .route("/metrics", get(metrics))
        .route("/healthz", get(|| async { Json(json!({"status": "ok"})) }))
        .route("/readyz", get(readyz))
        .fallback(|| async { ApiError(JobError::new(ErrorCode::NotFound, "no such route")) })
        .layer(DefaultBodyLimit::max(body_limit))
        .with_state(state)
}

/// Binds, warms up, serves until SIGINT or SIGTERM, then finishes requests in flight.
pub async fn serve(config: ServeConfig, engine: Arc<Engine>) -> anyhow::Result<()> {
    let queue = QueueConfig {
        capacity: config.queue,
        concurrency: config.concurrency,
        deadline: std::time::Duration::from_secs_f64(config.deadline_secs.max(0.0)),
    };
    let state = Arc::new(
        AppState::new(engine.clone(), config.results_kept)
            .with_queue(queue)
            .with_results_ttl(std::time::Duration::from_secs_f64(config.results_ttl_secs.max(0.0))),
    );
    let listener = tokio::net::TcpListener::bind(config.listen).await?;
    tracing::info!(address = %listener.local_addr()?, "listening");
    let warm = state.clone();
    let no_warm_up = config.no_warm_up;
    tokio::task::spawn_blocking(move || {
        let started = std::time::Instant::now();
        if !no_warm_up {
            if let Err(error) = warm.engine.warm_up() {
                tracing::error!(%error, "warm-up failed");
                return;
            }
        }
        warm.set_ready();
        tracing::info!(duration_ms = started.elapsed().as_millis() as u64, "ready: pipelines compiled, default scene uploaded");
    });
    axum::serve(listener, app(state.clone())).with_graceful_shutdown(shutdown_signal()).await?;
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
    upload(state, body, |engine, bytes| engine.upload_scene(bytes)).await
}

/// `POST /v1/lights`: a PNG or EXR body → its content id.
async fn upload_light(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Response {
    upload(state, body, |engine, bytes| engine.upload_light(bytes)).await
}

async fn upload(
    state: Arc<AppState>,
    body: Result<Bytes, BytesRejection>,
    store: fn(&Engine, &[u8]) -> crate::error::JobResult<crate::engine::UploadReceipt>,
) -> Response {
    let bytes = match body {
        Ok(bytes) => bytes,
        Err(rejection) => return ApiError(body_error(&state, rejection, ErrorCode::InvalidAsset)).into_response(),
    };
    let engine = state.engine.clone();
    // Decoding a large scene takes a while: off the async workers.
    match tokio::task::spawn_blocking(move || store(&engine, &bytes)).await {
        Ok(Ok(receipt)) => {
            let status = if receipt.created { StatusCode::CREATED } else { StatusCode::OK };
            (status, Json(receipt)).into_response()
        }
        Ok(Err(error)) => ApiError(error).into_response(),
        Err(_) => ApiError(JobError::new(ErrorCode::Internal, "the upload failed")).into_response(),
    }
}

/// `DELETE /v1/scenes/{id}`, `DELETE /v1/lights/{id}`: 204, or 404 when there was none.
async fn delete_upload(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Response {
    if state.engine.delete_upload(&id) {
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
    let job = body.and_then(|body| Job::from_json(&body));
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

/// Renders a job on the blocking pool and keeps the result for `/v1/jobs/{id}`. The queue
/// permits live in the render task: a client that goes away mid-render frees its place only
/// when the device does.
async fn render_job(
    state: &Arc<AppState>,
    job: Job,
    permits: (tokio::sync::OwnedSemaphorePermit, tokio::sync::OwnedSemaphorePermit),
) -> Result<(String, Arc<Rendered>), JobError> {
    let id = state.new_id();
    let span = tracing::info_span!("job", %id, method = %job.method.name);
    let engine = state.engine.clone();
    let rendered = tokio::task::spawn_blocking(move || {
        let _permits = permits;
        span.in_scope(|| engine.render_observed(&job, &|done, total| tracing::debug!(done, total, "progress")))
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
    let events = state.jobs.submitted(&id).ok_or_else(|| unknown_job(&id))?;
    let event = events.borrow().clone();
    Ok(Json(json!({"id": id, "status": event.status, "progress": {"done": event.done, "total": event.total}, "error": event.error})))
}

/// `POST /v1/jobs`: validates and admits the job (4xx, or 429 when the queue is full), answers
/// 202 with its id at once, and renders it in the background: `GET /v1/jobs/{id}` for its
/// state, `/events` for server-sent progress, `/image` once it succeeded.
async fn submit_job(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Result<Response, ApiError> {
    let body = body.map_err(|rejection| body_error(&state, rejection, ErrorCode::InvalidJson));
    let job = body.and_then(|body| Job::from_json(&body)).and_then(|job| job.validate(state.engine.limits()).map(|_| job));
    let job = job.inspect_err(|error| state.job_finished("", "", error.code.as_str(), 0.0, None))?;
    let admitted = state.queue.admit().inspect_err(|error| state.job_finished("", &job.method.name, error.code.as_str(), 0.0, None))?;
    let id = state.new_id();
    let (events, _) = tokio::sync::watch::channel(JobEvent::status("queued"));
    state.jobs.submit(id.clone(), events.clone());
    let task_state = state.clone();
    let task_id = id.clone();
    tokio::spawn(async move { run_submitted(task_state, task_id, job, admitted, events).await });
    let links = json!({"id": id, "status": "queued", "record": format!("/v1/jobs/{id}"), "events": format!("/v1/jobs/{id}/events")});
    Ok((StatusCode::ACCEPTED, [(header::LOCATION, format!("/v1/jobs/{id}"))], Json(links)).into_response())
}

/// A submitted job's life: wait for the device (up to the deadline), render with progress
/// events, keep the result.
async fn run_submitted(
    state: Arc<AppState>,
    id: String,
    job: Job,
    admitted: tokio::sync::OwnedSemaphorePermit,
    events: tokio::sync::watch::Sender<JobEvent>,
) {
    let started = std::time::Instant::now();
    let method = job.method.name.clone();
    let waiting = state.metrics.job_queued();
    let device = state.queue.device().await;
    drop(waiting);
    let outcome = match device {
        Ok(device) => {
            events.send_replace(JobEvent::status("running"));
            let _running = state.metrics.job_running();
            let engine = state.engine.clone();
            let progress = events.clone();
            let span = tracing::info_span!("job", %id, method = %method);
            tokio::task::spawn_blocking(move || {
                let _permits = (admitted, device);
                let report = |done, total| {
                    progress.send_modify(|event| {
                        event.done = done;
                        event.total = total;
                    })
                };
                span.in_scope(|| engine.render_observed(&job, &report))
            })
            .await
            .unwrap_or_else(|e| Err(JobError::internal(format!("render task failed: {e}"))))
        }
        Err(error) => Err(error),
    };
    let seconds = started.elapsed().as_secs_f64();
    match outcome {
        Ok(rendered) => {
            state.job_finished(&id, &method, "ok", seconds, Some(&rendered));
            tracing::info!(%id, total_ms = rendered.timings.total_ms, "job done");
            state.jobs.keep(id, Arc::new(rendered));
            events.send_modify(|event| event.finish("succeeded", None));
        }
        Err(error) => {
            state.job_finished(&id, &method, error.code.as_str(), seconds, None);
            let mut detail = error::error_body(&error);
            detail["status"] = json!(error::status_of(error.code).as_u16());
            events.send_modify(|event| event.finish("failed", Some(detail)));
        }
    }
}

/// `GET /v1/jobs/{id}/events`: server-sent events — `progress` with the job's state at once and
/// on every change, then one `succeeded` or `failed`, and the stream ends.
async fn job_events(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    use axum::response::sse::{Event, KeepAlive, Sse};
    let events = state.jobs.submitted(&id).ok_or_else(|| unknown_job(&id))?;
    let receiver = events.subscribe();
    // (receiver, ended): the current state first, then each change, until a final one.
    let stream = futures_util::stream::unfold((receiver, false, true), |(mut receiver, ended, first)| async move {
        if ended {
            return None;
        }
        if !first && receiver.changed().await.is_err() {
            return None;
        }
        let event = receiver.borrow_and_update().clone();
        let name = if event.finished() { event.status } else { "progress" };
        let sse = Event::default().event(name).json_data(&event).unwrap_or_else(|_| Event::default().event(name));
        Some((Ok::<_, std::convert::Infallible>(sse), (receiver, event.finished(), false)))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()).into_response())
}

async fn job_image(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    let rendered = state.jobs.find(&id).ok_or_else(|| unknown_job(&id))?;
    Ok(image_response(&id, &rendered))
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
