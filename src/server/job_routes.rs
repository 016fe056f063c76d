//! Submitted jobs (contract §3): `POST /v1/jobs` answers 202 and renders in the background;
//! records, server-sent events, images and thumbnails; `DELETE` cancels. With a shared store,
//! each replica's workers take jobs from the store's queue and follow jobs run elsewhere.

use super::*;

pub(super) async fn job_record(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<Value>, ApiError> {
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
        Some(result) if stored.status == JobStatus::Succeeded => result,
        _ => json!({"id": id, "status": stored.status, "progress": {"done": stored.done, "total": stored.total}, "error": stored.error}),
    }))
}

/// A job from the durable store (one this process did not run, or no longer holds).
pub(super) async fn stored_job(state: &AppState, id: &str) -> Result<Option<StoredJob>, ApiError> {
    let Some(store) = state.store.clone() else { return Ok(None) };
    let id = id.to_owned();
    Ok(store.call(move |s| s.get(&id)).await.map_err(store_error)?)
}

/// `POST /v1/jobs`: validates and admits the job (4xx; 429 when the queue is full; 503 while
/// the store does not answer; 507 when its disk has no room for the result), answers 202 with
/// its id at once, and renders it in the background: `GET /v1/jobs/{id}` for its state,
/// `/events` for server-sent progress, `/image` once it succeeded.
pub(super) async fn submit_job(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Result<Response, ApiError> {
    let body = body.map_err(|rejection| body_error(&state, rejection, ErrorCode::InvalidJson));
    let parsed = body.and_then(|body| {
        let job = Job::from_json_limited(&body, state.engine.limits())?;
        let uploads_here = !state.store.as_ref().is_some_and(|s| s.shared());
        state.engine.check(&job, uploads_here)?;
        // The job as sent (it parsed, so it is JSON): what the store keeps and resumes.
        let sent: Value = serde_json::from_slice(&body).map_err(|e| JobError::new(ErrorCode::InvalidJson, e.to_string()))?;
        Ok((job, sent))
    });
    let (job, sent) = parsed.inspect_err(|error| state.job_finished("", "", error.code.as_str(), 0.0, None))?;
    let method = job.method.name.clone();
    let id = accept_job(&state, job, sent).await.inspect_err(|error| state.job_finished("", &method, error.code.as_str(), 0.0, None))?;
    let links = json!({"id": id, "status": "queued", "record": format!("/v1/jobs/{id}"), "events": format!("/v1/jobs/{id}/events")});
    Ok((StatusCode::ACCEPTED, [(header::LOCATION, format!("/v1/jobs/{id}"))], Json(links)).into_response())
}

/// Admits a valid job and records it in the store before its 202: the store must answer
/// (503) and, on a local disk, have room for the result (507); the queue must have a place
/// (429). Returns the new job's id.
async fn accept_job(state: &Arc<AppState>, job: Job, sent: Value) -> Result<String, JobError> {
    let store = state.store.clone();
    if store.as_ref().is_some_and(|s| !s.health().available()) {
        // Known down: answered at once; the probe notices when it is back.
        return Err(store_error(StoreError::Unavailable("the last call and probe failed".into())));
    }
    let shared = store.clone().filter(|s| s.shared());
    if let Some(store) = &shared {
        // The shared queue is bounded as a whole, by the same --queue.
        let queued = store.call(|s| s.queued()).await.map_err(store_error)?;
        if queued >= u64::from(state.queue_config.capacity) {
            return Err(JobError::new(ErrorCode::QueueFull, "the shared job queue is full; retry after the Retry-After seconds"));
        }
    }
    // Room for the result on a local store's disk, promised until it is stored.
    let reservation = match store.as_ref().filter(|s| !s.shared()) {
        Some(store) => {
            let bytes = crate::output::max_result_bytes(job.output.width, job.output.height, job.output.format);
            Some(store.reserve(bytes).await.map_err(store_error)?)
        }
        None => None,
    };
    // A local place in the queue, unless the shared queue holds the job (its workers take one
    // when they take the job).
    let admitted = if shared.is_some() { None } else { Some(state.admit()?) };
    let mut id = new_job_id();
    // Durable before the 202: an accepted job survives a crash from here on. Ids are random, so
    // one the store already holds is a once-in-2^122 event; a fresh one is drawn, never an
    // existing record overwritten.
    if let Some(store) = &store {
        let sent = Arc::new(sent);
        for attempt in 1.. {
            let (stored_id, sent) = (id.clone(), sent.clone());
            match store.call(move |s| s.accept(&stored_id, &sent)).await {
                Ok(()) => break,
                Err(StoreError::Exists(_)) if attempt < 3 => id = new_job_id(),
                Err(error) => {
                    tracing::warn!(%error, "cannot record a submitted job");
                    return Err(store_error(error));
                }
            }
        }
    }
    if let Some(admitted) = admitted {
        state.spawn_submitted(id.clone(), job, (admitted, reservation));
    }
    Ok(id)
}

/// `GET /v1/jobs/{id}/events`: server-sent events — `progress` with the job's state at once and
/// on every change, then one `succeeded` or `failed`, and the stream ends.
pub(super) async fn job_events(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
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
        let name = if event.finished() { event.status.as_str() } else { "progress" };
        let sse = Event::default().event(name).json_data(&event).unwrap_or_else(|_| Event::default().event(name));
        Some((Ok::<_, std::convert::Infallible>(sse), (receiver, stopping, event.finished(), false)))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()).into_response())
}

/// A stored job's state as an event.
pub(super) fn event_of(stored: &StoredJob) -> JobEvent {
    let status = stored.status;
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
pub(super) async fn follow_stored(store: Store, id: String, events: tokio::sync::watch::Sender<JobEvent>) {
    let mut wait = std::time::Duration::from_millis(50);
    loop {
        tokio::time::sleep(wait).await;
        if events.receiver_count() == 0 {
            return;
        }
        let job = id.clone();
        let stored = match store.call(move |s| s.get(&job)).await {
            Ok(Some(stored)) => stored,
            Ok(None) => return,
            // The store blinked: keep following, less often, until it answers.
            Err(_) => {
                wait = std::time::Duration::from_secs(1);
                continue;
            }
        };
        wait = std::time::Duration::from_millis(50);
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
pub(super) async fn cancel_job(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
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
            let error = crate::supervise::cancelled_error();
            // A running job is counted where it runs, when it stops; a waiting one only here.
            if stored.status == JobStatus::Queued {
                state.job_finished(&id, stored.job["method"]["name"].as_str().unwrap_or(""), error.code.as_str(), 0.0, None);
            }
            store_failure(&state, &id, failure_detail(&error)).await;
        }
    }
    tracing::info!(%id, "job cancellation requested");
    let record = job_record(State(state), Path(id)).await?;
    Ok((StatusCode::ACCEPTED, record).into_response())
}

pub(super) async fn job_image(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    if let Some(rendered) = state.jobs.find(&id) {
        return Ok(image_response(&id, &rendered));
    }
    unless_unfinished_here(&state, &id)?;
    // A result from the durable store: the bytes and the format its record names.
    let stored = stored_job(&state, &id).await?.ok_or_else(|| unknown_job(&id))?;
    if stored.status != JobStatus::Succeeded {
        return Err(no_image(&id, stored.status));
    }
    if stored.image_bytes == 0 {
        return Err(unknown_job(&id)); // Dropped under --results-bytes.
    }
    let Some(store) = state.store.clone() else { return Err(unknown_job(&id)) };
    let image_id = id.clone();
    let bytes = store.call(move |s| s.image(&image_id)).await.map_err(store_error)?.ok_or_else(|| unknown_job(&id))?;
    let mime = if stored.result.as_ref().is_some_and(|r| r["format"] == "exr") { "image/x-exr" } else { "image/png" };
    Ok(([(header::CONTENT_TYPE, mime)], bytes).into_response())
}

/// `GET /v1/jobs/{id}/thumbnail`: a small PNG of a kept result (the dashboard's previews).
/// Results never change under their id, so browsers may cache it for good.
pub(super) async fn job_thumbnail(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    unless_unfinished_here(&state, &id)?;
    let rendered = state.jobs.find(&id).ok_or_else(|| unknown_job(&id))?;
    let png = tokio::task::spawn_blocking(move || crate::output::thumbnail(&rendered.bytes, THUMBNAIL_SIZE))
        .await
        .map_err(|e| JobError::internal(format!("thumbnail task failed: {e}")))??;
    Ok(([(header::CONTENT_TYPE, "image/png"), (header::CACHE_CONTROL, "private, max-age=86400, immutable")], png).into_response())
}

/// Longest side of a thumbnail, pixels.
const THUMBNAIL_SIZE: u32 = 160;

/// A job held here that has not succeeded has no image yet (or ever): 409 saying its state,
/// not 404, which would tell a client the job does not exist.
fn unless_unfinished_here(state: &AppState, id: &str) -> Result<(), ApiError> {
    match state.jobs.submitted(id).map(|events| events.borrow().status) {
        Some(status) if status != JobStatus::Succeeded => Err(no_image(id, status)),
        _ => Ok(()),
    }
}

fn no_image(id: &str, status: JobStatus) -> ApiError {
    let message = match status {
        JobStatus::Queued | JobStatus::Running => format!("job `{id}` is {status}; its image exists once it has succeeded"),
        _ => format!("job `{id}` {status}; it has no image"),
    };
    ApiError(JobError::new(ErrorCode::Conflict, message))
}

pub(super) fn unknown_job(id: &str) -> ApiError {
    ApiError(JobError::new(ErrorCode::NotFound, format!("no finished job `{id}` is kept on this server")))
}
