//! Synchronous renders (`POST /v1/render`): admitted to the queue, rendered on the blocking
//! pool, answered with the image or its record; a client that goes away cancels its job.
//! `render_blocking` is the one orchestration of a render, shared with submitted jobs.

use super::*;
use crate::job::auto::AutoChoice;

fn wants_json(headers: &HeaderMap) -> bool {
    headers
        .get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|accept| accept.split(',').any(|t| t.trim().starts_with("application/json")))
}

pub(super) async fn render(
    State(state): State<Arc<AppState>>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let started = std::time::Instant::now();
    let body = body.map_err(|rejection| body_error(&state, rejection, ErrorCode::InvalidJson));
    let job = body.and_then(|body| Job::from_json_limited(&body, state.engine.limits()));
    // An `auto` budget nothing meets is refused before the job is queued.
    let job = job.and_then(|job| state.resolve_auto(&job, true).map(|_| job));
    // Rounds are announced as events of a submitted job: a synchronous answer has one image.
    let job = job.and_then(|job| match job.progressive {
        Some(_) => Err(JobError::invalid("progressive", "a progressive job is submitted (POST /v1/jobs), where its rounds are events")),
        None => Ok(job),
    });
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
    let cancel = Arc::new(AtomicBool::new(false));
    let _client = CancelOnDrop(cancel.clone());
    let (counting, method) = (state.clone(), job.method.name.clone());
    let started = std::time::Instant::now();
    let supervise =
        Supervise { progress: |done, total| tracing::debug!(done, total, "progress"), cancelled: move || cancel.load(Ordering::Relaxed) };
    let rendered = render_blocking(state, &id, job, supervise, permits, move |outcome| {
        // Its handler is gone with its client: the outcome is counted here.
        if matches!(outcome, Err(error) if error.code == ErrorCode::Cancelled) {
            tracing::info!("client went away: job cancelled mid-render");
            counting.job_finished("", &method, "cancelled", started.elapsed().as_secs_f64(), None);
        }
    })
    .await?;
    tracing::info!(%id, total_ms = rendered.timings.total_ms, "job done");
    let rendered = Arc::new(rendered);
    state.jobs.keep(id.clone(), rendered.clone());
    Ok((id, rendered))
}

/// Renders a job: the one way every job is rendered, synchronous or submitted. On the blocking
/// pool, in the job's span, with the uploads another replica received fetched first, under
/// `supervise` (progress, and whether to stop). `hold` (queue places) is released when the
/// render ends; `finish` sees the outcome there too — even when the caller has gone away.
pub(super) async fn render_blocking<P, C>(
    state: &Arc<AppState>,
    id: &str,
    job: Job,
    supervise: Supervise<P, C>,
    hold: impl Send + 'static,
    finish: impl FnOnce(&Result<Rendered, JobError>) + Send + 'static,
) -> Result<Rendered, JobError>
where
    P: Fn(u64, u64) + Send + 'static,
    C: Fn() -> bool + Send + 'static,
{
    let span = tracing::info_span!("job", %id, method = %job.method.name);
    // `auto`: chosen by this replica's model, which predicts this device.
    let (job, auto) = match state.resolve_auto(&job, false) {
        Ok(Some((chosen, choice))) => (chosen, Some(choice)),
        Ok(None) => (job, None),
        Err(error) => {
            let outcome = Err(error);
            finish(&outcome);
            return outcome;
        }
    };
    let (engine, store, pacing) = (state.engine.clone(), state.store.clone(), state.clone());
    tokio::task::spawn_blocking(move || {
        let _hold = hold;
        span.in_scope(|| {
            // An `auto` job is compared with the truth its model's errors were measured against.
            let reference = match auto {
                Some(_) => crate::model::measure::Suite::standard().truth_of(&job),
                None => job.reference_job(),
            };
            let outcome = fetch_shared_uploads(&engine, store.as_ref(), &job)
                .and_then(|()| engine.render_compared(&job, &reference, &supervise))
                .map(|mut rendered| {
                    let measured_ms = rendered.timings.render_ms();
                    pacing.model.observe(&job, || pacing.unpaced_features(&job), measured_ms);
                    rendered.auto = auto.map(|choice| AutoChoice { measured_ms: Some(measured_ms), ..choice });
                    rendered
                });
            finish(&outcome);
            outcome
        })
    })
    .await
    .unwrap_or_else(|e| Err(JobError::internal(format!("render task failed: {e}"))))
}

pub(super) fn job_json(id: &str, rendered: &Rendered) -> Value {
    json!({
        "id": id,
        "status": "succeeded",
        "method": rendered.method,
        "width": rendered.width,
        "height": rendered.height,
        "format": rendered.format,
        "bytes": rendered.bytes.len(),
        "image_sha256": rendered.image_sha256(),
        "timings": rendered.timings,
        "counters": rendered.counters,
        "quality": rendered.quality,
        "warnings": rendered.warnings,
        "staging": rendered.staging,
        "auto": rendered.auto,
        "progressive": rendered.progressive,
        "image": format!("/v1/jobs/{id}/image"),
    })
}

pub(super) fn image_response(id: &str, rendered: &Rendered) -> Response {
    let mut response = rendered.bytes.clone().into_response();
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(rendered.format.mime()));
    let mut timing = rendered.timings.server_timing();
    if let Some(auto) = &rendered.auto {
        // The choice and its prediction beside the measured phases.
        timing.push_str(&format!(", auto;desc=\"{}\";dur={:.3}", auto.label, auto.predicted.ms));
        if let Ok(choice) = HeaderValue::from_str(&auto.label) {
            headers.insert("x-penumbra-auto-method", choice);
        }
        headers.insert("x-penumbra-predicted-ms", HeaderValue::from(auto.predicted.ms.round() as u64));
        if let Ok(error) = HeaderValue::from_str(&format!("{:.5}", auto.predicted.error)) {
            headers.insert("x-penumbra-predicted-error", error);
        }
    }
    if let Ok(timing) = HeaderValue::from_str(&timing) {
        headers.insert("server-timing", timing);
    }
    if let Ok(id) = HeaderValue::from_str(id) {
        headers.insert("x-penumbra-job-id", id);
    }
    response
}
