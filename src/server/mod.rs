//! The HTTP service (contract §3): `app(state)` builds the router, `serve` binds it, warms
//! the engine up and shuts down gracefully; synchronous renders, limits, stats and metrics
//! are here, submitted jobs in `jobs`, uploads in `uploads`. Rendering runs on the blocking
//! pool so the async workers keep answering health checks while the device is busy.

pub mod auth;
mod auto;
mod cluster;
pub mod connections;
mod dashboard;
pub mod error;
mod job_routes;
mod meta;
pub mod metrics;
pub mod openapi;
mod progressive;
mod render;
pub mod requests;
mod serve;
mod state;
mod upload_routes;
mod worker;

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
use crate::job::submission::{
    fingerprint, idempotency_key, unix_ms, Cursor, JobFilter, KeyedJob, ListedJob, DEFAULT_PAGE, IDEMPOTENCY_KEY, MAX_PAGE,
};
use crate::job::summary::JobSummary;
use crate::job::{Job, JobStatus};
use crate::light::BUILTIN_LIGHT_IMAGES;
use crate::methods::REGISTRY;
use crate::queue::{IdempotencyKeys, JobEvent, JobQueue, LiveJobs, RecentJobs};
use crate::scene::builtin::BUILTIN_SCENES;
use crate::store::{new_job_id, JobStore as DurableStore, Store, StoreError, StoredJob, MAX_ATTEMPTS};
use crate::supervise::Supervise;
use crate::upload_store::{content_id, is_content_id, Kind};
use auto::estimate;
pub use cluster::Replica;
use error::{store_error, ApiError};
use job_routes::{
    cancel_job, immutable, job_events, job_image, job_record, job_thumbnail, list_jobs, not_modified, round_image, submit_job, unchanged,
};
use meta::{limits, methods, metrics, readyz, stats};
use render::{image_response, job_json, render, render_blocking};
use requests::REQUEST_ID;
pub use serve::serve;
use state::Admitted;
pub use state::{AppState, Idempotency};
use upload_routes::{fetch_shared_uploads, upload_light, upload_routes, upload_scene};
use worker::{abandoned, failure_detail, run_submitted, store_failure, work_shared_queue};

pub use crate::queue::QueueConfig;

/// How long finished jobs stay readable unless configured (`--results-ttl-secs`).
pub const DEFAULT_RESULTS_TTL: std::time::Duration = std::time::Duration::from_secs(3600);

/// How often an idle worker of a shared store asks the queue for a job (the most an async job
/// waits for an idle replica).
const SHARED_QUEUE_POLL: std::time::Duration = std::time::Duration::from_millis(50);

/// How long a finished render's outcome is retried while the store cannot take it, unless
/// configured (`--store-retry-secs`).
pub const DEFAULT_STORE_RETRY: std::time::Duration = std::time::Duration::from_secs(600);

/// How long an idempotency key names its job unless configured (`--idempotency-ttl-secs`).
pub const DEFAULT_IDEMPOTENCY_TTL: std::time::Duration = std::time::Duration::from_secs(24 * 3600);

/// How often a replica of a shared store reports itself unless configured (`--heartbeat-secs`).
pub const DEFAULT_HEARTBEAT: std::time::Duration = std::time::Duration::from_secs(5);

/// Finished jobs remembered for the dashboard's charts.
const RECENT_JOBS: usize = 200;

pub fn app(state: Arc<AppState>) -> Router {
    let body_limit = state.engine.limits().max_body_bytes;
    let guard = || axum::middleware::from_fn_with_state(state.clone(), auth::require_token);
    // Everything under /v1 needs a token when tokens are configured.
    let v1 = Router::new()
        .route("/v1/render", post(render))
        .route("/v1/estimate", post(estimate))
        .route("/v1/methods", get(methods))
        .route("/v1/limits", get(limits))
        .route("/v1/scenes", post(upload_scene))
        .route("/v1/lights", post(upload_light))
        .route("/v1/scenes/{id}", upload_routes(Kind::Scene))
        .route("/v1/lights/{id}", upload_routes(Kind::Light))
        .route("/v1/jobs", post(submit_job).get(list_jobs))
        .route("/v1/jobs/{id}", get(job_record).delete(cancel_job))
        .route("/v1/jobs/{id}/events", get(job_events))
        .route("/v1/jobs/{id}/image", get(job_image))
        .route("/v1/jobs/{id}/rounds/{round}", get(round_image))
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
        .route_layer(axum::middleware::from_fn(requests::note_route))
        .fallback(|| async { ApiError(JobError::new(ErrorCode::NotFound, "no such route")) })
        .layer(DefaultBodyLimit::max(body_limit));
    // CORS is closed unless origins are configured; the layer answers preflights before auth.
    let router = match &state.cors {
        Some(cors) => router.layer(cors.clone()),
        None => router,
    };
    // Outermost: every answer, a 401 or a preflight's included, carries the request's id.
    router.layer(axum::middleware::from_fn_with_state(state.clone(), requests::track)).with_state(state)
}

/// A body that could not be read: too large (413), or unreadable, as `unreadable`.
fn body_error(state: &AppState, rejection: BytesRejection, unreadable: ErrorCode) -> JobError {
    if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE {
        JobError::new(ErrorCode::PayloadTooLarge, format!("the body exceeds {} bytes", state.engine.limits().max_body_bytes))
    } else {
        JobError::new(unreadable, format!("cannot read the body: {rejection}"))
    }
}
