//! Submitted jobs (contract §3): `POST /v1/jobs` answers 202 and renders in the background;
//! records, server-sent events, images and thumbnails; `DELETE` cancels. With a shared store,
//! each replica's workers take jobs from the store's queue and follow jobs run elsewhere.

use super::*;
use crate::job::OutputFormat;
use crate::queue::KeptRound;

/// `GET /v1/jobs/{id}`: a finished render's record, or a submitted job's state; a submitted
/// job's record names the request that submitted it (`request_id`).
pub(super) async fn job_record(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<Value>, ApiError> {
    let held_request = || state.jobs.listed(&id).and_then(|listed| listed.request_id);
    let (mut record, request_id) = if let Some(rendered) = state.jobs.find(&id) {
        (job_json(&id, &rendered), held_request())
    } else if let Some(events) = state.jobs.submitted(&id) {
        let event = events.borrow().clone();
        let mut record = state_record(&id, event.status, (event.done, event.total), event.error);
        // A running progressive job's latest round (contract §5).
        if let Some(round) = event.round.filter(|_| !event.status.finished()) {
            record["round"] = json!(round);
        }
        (record, held_request())
    } else {
        let stored = stored_job(&state, &id).await?.ok_or_else(|| unknown_job(&id))?;
        let record = match stored.result {
            Some(result) if stored.status == JobStatus::Succeeded => result,
            _ => {
                let mut record = state_record(&id, stored.status, (stored.done, stored.total), stored.error);
                // A progressive job running on another replica: its latest round.
                if let Some(round) = stored.rounds.last().filter(|_| !stored.status.finished()) {
                    record["round"] = json!(round);
                }
                record
            }
        };
        (record, stored.request_id)
    };
    if let Some(request_id) = request_id {
        record["request_id"] = json!(request_id);
    }
    Ok(Json(record))
}

/// The record of a submitted job without a result: its state, progress and error.
fn state_record(id: &str, status: JobStatus, (done, total): (u64, u64), error: Option<Value>) -> Value {
    json!({"id": id, "status": status, "progress": {"done": done, "total": total}, "error": error})
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
/// `/events` for server-sent progress, `/image` once it succeeded. With an `Idempotency-Key`,
/// a key that names a job already answers that job (202, `Idempotent-Replayed: true`) and
/// creates nothing, or 422 `idempotency_key_reused` when its body differed.
pub(super) async fn submit_job(
    State(state): State<Arc<AppState>>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let key = headers.get(IDEMPOTENCY_KEY).map(|v| idempotency_key(v.as_bytes())).transpose();
    let body = body.map_err(|rejection| body_error(&state, rejection, ErrorCode::InvalidJson));
    let parsed = key.and_then(|key| {
        let body = body?;
        let job = Job::from_json_limited(&body, state.engine.limits())?;
        let uploads_here = state.shared_store().is_none();
        state.check_submission(&job, uploads_here)?;
        // The job as sent (it parsed, so it is JSON): what the store keeps and resumes.
        let sent: Value = serde_json::from_slice(&body).map_err(|e| JobError::new(ErrorCode::InvalidJson, e.to_string()))?;
        Ok((key, job, sent))
    });
    let (key, job, sent) = parsed.inspect_err(|error| state.job_finished("", "", error.code.as_str(), 0.0, None))?;
    let keyed = key.map(|key| {
        let claim = KeyedJob { id: new_job_id(), fingerprint: fingerprint(&sent), expires_unix_ms: unix_ms() + state.idempotency.ttl_ms() };
        (key, claim)
    });
    if let Some((key, claim)) = &keyed {
        if let Some(held) = find_keyed(&state, key).await? {
            return replay(&state, key, &claim.fingerprint, held).await;
        }
    }
    let method = job.method.name.clone();
    let request_id = headers.get(REQUEST_ID).and_then(|v| v.to_str().ok()).map(str::to_owned);
    let accepted = accept_job(&state, job, sent, request_id, keyed.as_ref()).await;
    let id = match accepted.inspect_err(|error| state.job_finished("", &method, error.code.as_str(), 0.0, None))? {
        Accepted::New(id) => id,
        Accepted::Twin(held) => {
            let (key, claim) = keyed.as_ref().expect("a twin has a key");
            return replay(&state, key, &claim.fingerprint, held).await;
        }
    };
    Ok(accepted_response(&id, JobStatus::Queued, false))
}

/// The 202 of a submission: the job's id, state and links, its record in `Location`.
fn accepted_response(id: &str, status: JobStatus, replayed: bool) -> Response {
    let links = json!({"id": id, "status": status, "record": format!("/v1/jobs/{id}"), "events": format!("/v1/jobs/{id}/events")});
    let mut response = (StatusCode::ACCEPTED, [(header::LOCATION, format!("/v1/jobs/{id}"))], Json(links)).into_response();
    if replayed {
        response.headers_mut().insert("idempotent-replayed", HeaderValue::from_static("true"));
    }
    response
}

/// The job an idempotency key names: in the store (every replica's), or here without one.
async fn find_keyed(state: &AppState, key: &str) -> Result<Option<KeyedJob>, ApiError> {
    match state.store.clone() {
        Some(store) => {
            let key = key.to_owned();
            Ok(store.call(move |s| s.keyed(&key)).await.map_err(store_error)?)
        }
        None => Ok(state.idempotency.keys.find(key, |id| state.jobs.submitted(id).is_some())),
    }
}

/// The answer to a submission whose key names a job already: that job's 202 when the body is
/// the same, 422 naming the key when it is not.
async fn replay(state: &AppState, key: &str, fingerprint: &str, held: KeyedJob) -> Result<Response, ApiError> {
    if held.fingerprint != fingerprint {
        let message = format!("the Idempotency-Key `{key}` names job `{}`, submitted with another body", held.id);
        return Err(ApiError(JobError::field(ErrorCode::IdempotencyKeyReused, "Idempotency-Key", message)));
    }
    // A held key's job exists (`keyed`): its status now; queued if it went in between.
    let status = match state.jobs.submitted(&held.id) {
        Some(events) => events.borrow().status,
        None => stored_job(state, &held.id).await?.map_or(JobStatus::Queued, |stored| stored.status),
    };
    tracing::info!(id = %held.id, "idempotent submission: the job its key names is answered");
    Ok(accepted_response(&held.id, status, true))
}

/// What admission made of a submission: a new job, or (under an idempotency key) the job a
/// twin sent at the same time created.
enum Accepted {
    New(String),
    Twin(KeyedJob),
}

/// Admits a valid job and records it in the store before its 202: the store must answer
/// (503) and, on a local disk, have room for the result (507); the queue must have a place
/// (429). Under an idempotency key the key is claimed in the same step as the record.
async fn accept_job(
    state: &Arc<AppState>,
    job: Job,
    sent: Value,
    request_id: Option<String>,
    keyed: Option<&(String, KeyedJob)>,
) -> Result<Accepted, JobError> {
    let store = state.store.clone();
    if store.as_ref().is_some_and(|s| !s.health().available()) {
        // Known down: answered at once; the probe notices when it is back.
        return Err(store_error(StoreError::Unavailable("the last call and probe failed".into())));
    }
    let shared = state.shared_store().cloned();
    if let Some(store) = &shared {
        // The shared queue is bounded as a whole, by the same --queue.
        let queued = store.call(|s| s.queued()).await.map_err(store_error)?;
        if queued >= u64::from(state.queue_config.capacity) {
            return Err(JobError::new(ErrorCode::QueueFull, "the shared job queue is full; retry after the Retry-After seconds"));
        }
    }
    // Without a store the key is claimed here before admission, and freed if it fails.
    let mut id = keyed.map_or_else(new_job_id, |(_, claim)| claim.id.clone());
    if let (None, Some((key, claim))) = (&store, keyed) {
        if let Some(held) = state.idempotency.keys.claim(key, claim.clone(), |id| state.jobs.submitted(id).is_some()) {
            return Ok(Accepted::Twin(held));
        }
    }
    let release = |error: JobError| {
        if let (None, Some((key, claim))) = (&store, keyed) {
            state.idempotency.keys.release(key, &claim.id);
        }
        error
    };
    // Room for the result on a local store's disk, promised until it is stored.
    let reservation = match store.as_ref().filter(|s| !s.shared()) {
        Some(store) => Some(store.reserve(promised_bytes(&job, state.engine.limits())).await.map_err(store_error)?),
        None => None,
    };
    // A local place in the queue, unless the shared queue holds the job (its workers take one
    // when they take the job).
    let admitted = if shared.is_some() { None } else { Some(state.admit().map_err(release)?) };
    let submitted_unix_ms = unix_ms();
    // Durable before the 202: an accepted job survives a crash from here on. Ids are random, so
    // one the store already holds is a once-in-2^122 event; a fresh one is drawn, never an
    // existing record overwritten.
    if let Some(store) = &store {
        let sent = Arc::new(sent);
        for attempt in 1.. {
            let mut record = StoredJob::queued(&id, &sent);
            (record.submitted_unix_ms, record.request_id) = (submitted_unix_ms, request_id.clone());
            let keyed = keyed.map(|(key, claim)| (key.clone(), KeyedJob { id: id.clone(), ..claim.clone() }));
            let outcome = store
                .call(move |s| match &keyed {
                    Some((key, claim)) => s.accept_keyed(&record, key, claim),
                    None => s.accept_record(&record).map(|()| None),
                })
                .await;
            match outcome {
                Ok(None) => break,
                Ok(Some(held)) => return Ok(Accepted::Twin(held)),
                Err(StoreError::Exists(_)) if attempt < 3 => id = new_job_id(),
                Err(error) => {
                    tracing::warn!(%error, "cannot record a submitted job");
                    return Err(store_error(error));
                }
            }
        }
    }
    if let Some(admitted) = admitted {
        let mut listed = ListedJob::new(&id, JobStatus::Queued, &job.method.name, submitted_unix_ms);
        listed.request_id = request_id;
        state.spawn_submitted(listed, job, (admitted, reservation));
    }
    Ok(Accepted::New(id))
}

/// `GET /v1/jobs`: submitted jobs newest first, filtered by `status` and `method`, `limit` a
/// page (default 50, at most 500), `cursor` the `next_cursor` of the page before. With a
/// store, every replica lists the same jobs; without one, the jobs this process holds.
pub(super) async fn list_jobs(
    State(state): State<Arc<AppState>>,
    query: Result<axum::extract::Query<Vec<(String, String)>>, axum::extract::rejection::QueryRejection>,
) -> Result<Json<Value>, ApiError> {
    let invalid = |field: &str, message: String| ApiError(JobError::field(ErrorCode::InvalidParameter, field, message));
    let axum::extract::Query(pairs) = query.map_err(|e| invalid("query", format!("cannot read the query string: {e}")))?;
    let (mut filter, mut after, mut limit) = (JobFilter::default(), None, DEFAULT_PAGE);
    let mut seen = std::collections::HashSet::new();
    for (name, value) in pairs {
        if !seen.insert(name.clone()) {
            return Err(invalid(&name, format!("`{name}` is given more than once")));
        }
        match name.as_str() {
            "status" => {
                let status = serde_json::from_value(json!(value))
                    .map_err(|_| invalid("status", "status is one of queued, running, succeeded, failed, cancelled".to_owned()))?;
                filter.status = Some(status);
            }
            "method" => {
                crate::methods::find(&value).map_err(|error| invalid("method", error.message))?;
                filter.method = Some(value);
            }
            "limit" => {
                limit = value
                    .parse()
                    .ok()
                    .filter(|n| (1..=MAX_PAGE).contains(n))
                    .ok_or_else(|| invalid("limit", format!("limit is a whole number from 1 to {MAX_PAGE}")))?;
            }
            "cursor" => after = Some(Cursor::decode(&value)?),
            _ => {
                let shown: String = name.chars().take(32).collect();
                return Err(invalid(&shown, format!("unknown parameter `{shown}`: status, method, limit and cursor are")));
            }
        }
    }
    let (jobs, next) = match state.store.clone() {
        Some(store) => store.call(move |s| s.list(&filter, after.as_ref(), limit)).await.map_err(store_error)?,
        None => state.jobs.list(&filter, after.as_ref(), limit),
    };
    Ok(Json(json!({"jobs": jobs, "next_cursor": next.map(|c| c.encode())})))
}

/// `GET /v1/jobs/{id}/events`: server-sent events — `progress` with the job's state at once and
/// on every change, a progressive job's `round` for each of its rounds, then one `succeeded`
/// or `failed`, and the stream ends.
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
    // (receiver, stopping, ended, first, rounds sent, events to send before the next change):
    // a progressive job's every round is an event of its own, even to a stream that fell
    // behind its rounds.
    let start = (receiver, stopping, false, true, 0usize, std::collections::VecDeque::new());
    let stream = futures_util::stream::unfold(start, |(mut receiver, mut stopping, ended, first, mut sent, mut pending)| async move {
        if let Some(sse) = pending.pop_front() {
            return Some((Ok::<_, std::convert::Infallible>(sse), (receiver, stopping, ended, first, sent, pending)));
        }
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
        let sse =
            |name: &str, event: &JobEvent| Event::default().event(name).json_data(event).unwrap_or_else(|_| Event::default().event(name));
        for round in event.rounds.iter().skip(sent) {
            pending.push_back(sse("round", &JobEvent { round: Some(round.clone()), ..event.clone() }));
        }
        let had_rounds = sent < event.rounds.len();
        sent = event.rounds.len();
        if event.finished() {
            pending.push_back(sse(event.status.as_str(), &event));
        } else if !had_rounds {
            pending.push_back(sse("progress", &event));
        }
        let next = pending.pop_front()?;
        Some((Ok(next), (receiver, stopping, event.finished(), false, sent, pending)))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()).into_response())
}

/// A stored job's state as an event.
pub(super) fn event_of(stored: &StoredJob) -> JobEvent {
    let status = stored.status;
    let mut event = JobEvent::status(status);
    (event.done, event.total) = (stored.done, stored.total);
    (event.round, event.rounds) = (stored.rounds.last().cloned(), stored.rounds.clone());
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
            let changed = (current.status, current.done, current.total, current.rounds.len())
                != (event.status, event.done, event.total, event.rounds.len());
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

/// `GET /v1/jobs/{id}/image`: the result, with its digest as a strong `ETag` (304 for an
/// `If-None-Match` that names it) and cacheable for good: a result never changes under its id.
pub(super) async fn job_image(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    match image_at(&state, &id).await? {
        ImageAt::Here(rendered) => {
            let etag = format!("\"{}\"", rendered.image_sha256());
            if not_modified(&headers, &etag) {
                return Ok(unchanged(&etag));
            }
            Ok(immutable(image_response(&id, &rendered), &etag))
        }
        ImageAt::Stored { digest, exr } => {
            // The record names the digest (results stored before it did get one from the bytes).
            let recorded = digest.map(|d| format!("\"{d}\""));
            if recorded.as_ref().is_some_and(|etag| not_modified(&headers, etag)) {
                return Ok(unchanged(recorded.as_deref().unwrap_or_default()));
            }
            let bytes = stored_image(&state, &id).await?;
            let etag = recorded.unwrap_or_else(|| format!("\"{}\"", content_id(&bytes)));
            if not_modified(&headers, &etag) {
                return Ok(unchanged(&etag));
            }
            let mime = if exr { "image/x-exr" } else { "image/png" };
            Ok(immutable(([(header::CONTENT_TYPE, mime)], bytes).into_response(), &etag))
        }
    }
}

/// The bytes a job's images may take on a local store's disk: its result's, and a progressive
/// job's round images' besides (contract §5: kept until it ends) — its first image and as
/// many rounds as its samples allow.
pub(super) fn promised_bytes(job: &Job, limits: &crate::job::Limits) -> u64 {
    let images = match job.progressive {
        Some(_) => 2 + crate::job::progressive::round_samples(super::progressive::samples_cap(job, limits)).len() as u64,
        None => 1,
    };
    images * crate::output::max_result_bytes(job.output.width, job.output.height, job.output.format)
}

/// `GET /v1/jobs/{id}/rounds/{round}`: a running progressive job's round image (contract
/// §5), held by the replica that renders it — and, through a shared store, served by every
/// replica — until the job ends; 404 after (the last round is the job's image) or for a round
/// not drawn.
pub(super) async fn round_image(
    State(state): State<Arc<AppState>>,
    Path((id, round)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let gone = || {
        ApiError(JobError::new(
            ErrorCode::NotFound,
            format!("job `{id}` holds no round `{round}` here: rounds are kept while the job runs, and its last is its image"),
        ))
    };
    let number: usize = round.parse().map_err(|_| gone())?;
    let from_store = |store: Option<Store>| {
        let job = id.clone();
        async move {
            let Some(store) = store else { return Ok(None) };
            store.call(move |s| s.round(&job, number)).await.map_err(store_error)
        }
    };
    let (format, bytes) = match state.jobs.round(&id, number) {
        Some(KeptRound { format, bytes: Some(bytes) }) => (format, bytes.as_ref().clone()),
        Some(KeptRound { format, bytes: None }) => (format, from_store(state.store.clone()).await?.ok_or_else(gone)?),
        // Drawn by another replica of a shared store: a PNG or an EXR, as its job asked.
        None => {
            let bytes = from_store(state.store.clone().filter(|s| s.shared())).await?.ok_or_else(gone)?;
            (if bytes.starts_with(b"\x89PNG") { OutputFormat::Png } else { OutputFormat::Exr }, bytes)
        }
    };
    let mut response = bytes.into_response();
    response.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static(format.mime()));
    Ok(response)
}

/// Where a succeeded job's image is: in this replica's memory, or in the durable store (the
/// record naming its digest and format) — where any replica of a shared store finds it.
enum ImageAt {
    Here(Arc<Rendered>),
    Stored { digest: Option<String>, exr: bool },
}

/// Finds a succeeded job's image: 409 for a job that has not succeeded, 404 for one unknown
/// here and in the store, or whose image was dropped under `--results-bytes`.
async fn image_at(state: &AppState, id: &str) -> Result<ImageAt, ApiError> {
    if let Some(rendered) = state.jobs.find(id) {
        return Ok(ImageAt::Here(rendered));
    }
    unless_unfinished_here(state, id)?;
    let stored = stored_job(state, id).await?.ok_or_else(|| unknown_job(id))?;
    if stored.status != JobStatus::Succeeded {
        return Err(no_image(id, stored.status));
    }
    if stored.image_bytes == 0 {
        return Err(unknown_job(id));
    }
    let result = stored.result.as_ref();
    let digest = result.and_then(|r| r["image_sha256"].as_str()).map(str::to_owned);
    Ok(ImageAt::Stored { digest, exr: result.is_some_and(|r| r["format"] == "exr") })
}

/// A stored image's bytes.
async fn stored_image(state: &AppState, id: &str) -> Result<Vec<u8>, ApiError> {
    let Some(store) = state.store.clone() else { return Err(unknown_job(id)) };
    let image_id = id.to_owned();
    store.call(move |s| s.image(&image_id)).await.map_err(store_error)?.ok_or_else(|| unknown_job(id))
}

/// Whether `If-None-Match` names `etag` (or is `*`): weak comparison, as RFC 9110 §13.1.2
/// asks for this header.
pub(super) fn not_modified(headers: &HeaderMap, etag: &str) -> bool {
    let opaque = |tag: &str| tag.trim().trim_start_matches("W/").to_owned();
    headers
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|tag| tag.trim() == "*" || opaque(tag) == opaque(etag))
}

/// 304 Not Modified for `etag`.
pub(super) fn unchanged(etag: &str) -> Response {
    immutable(StatusCode::NOT_MODIFIED.into_response(), etag)
}

/// Bytes that never change under their URL: private (the API may need a token), kept a year.
const IMMUTABLE: &str = "private, max-age=31536000, immutable";

/// `response` as bytes that never change under their URL: `etag`, and `Cache-Control:
/// immutable`.
pub(super) fn immutable(mut response: Response, etag: &str) -> Response {
    if let Ok(value) = HeaderValue::from_str(etag) {
        response.headers_mut().insert(header::ETAG, value);
    }
    response.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static(IMMUTABLE));
    response
}

/// `GET /v1/jobs/{id}/thumbnail`: a small PNG of a result kept here or in the store, so any
/// replica of a shared store has every replica's (the dashboard's previews).
/// Results never change under their id, so browsers may cache it for good; its `ETag` is the
/// result's digest and the thumbnail's size.
pub(super) async fn job_thumbnail(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let tag = |digest: &str| format!("\"{digest}-thumbnail-{THUMBNAIL_SIZE}\"");
    let (etag, encoded) = match image_at(&state, &id).await? {
        ImageAt::Here(rendered) => (tag(rendered.image_sha256()), Encoded::Here(rendered)),
        ImageAt::Stored { digest, .. } => {
            // Answered from the recorded digest before the image is read, when it can be.
            if let Some(etag) = digest.as_deref().map(tag).filter(|etag| not_modified(&headers, etag)) {
                return Ok(unchanged(&etag));
            }
            let bytes = stored_image(&state, &id).await?;
            (tag(&digest.unwrap_or_else(|| content_id(&bytes))), Encoded::Stored(bytes))
        }
    };
    if not_modified(&headers, &etag) {
        return Ok(unchanged(&etag));
    }
    let png = tokio::task::spawn_blocking(move || crate::output::thumbnail(encoded.bytes(), THUMBNAIL_SIZE))
        .await
        .map_err(|e| JobError::internal(format!("thumbnail task failed: {e}")))??;
    Ok(immutable(([(header::CONTENT_TYPE, "image/png")], png).into_response(), &etag))
}

/// An encoded image, held in memory or read from the store.
enum Encoded {
    Here(Arc<Rendered>),
    Stored(Vec<u8>),
}

impl Encoded {
    fn bytes(&self) -> &[u8] {
        match self {
            Encoded::Here(rendered) => &rendered.bytes,
            Encoded::Stored(bytes) => bytes,
        }
    }
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
