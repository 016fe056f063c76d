//! The background life of a submitted job: waiting for the device (or, with a shared store,
//! taken by one of this replica's workers), rendering, and storing its outcome — retried while
//! the store cannot take it, so an accepted job never fails because the store blinked.

use super::*;

/// A submitted job's life: wait for the device (up to the deadline; at shutdown with a
/// durable store, stop waiting and stay queued there; cancelled, leave the queue), then
/// render and store it.
pub(super) async fn run_submitted(
    state: Arc<AppState>,
    id: String,
    job: Job,
    admitted: Admitted,
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
        Ok(_) = cancelled.wait_for(|c| *c) => Err(crate::supervise::cancelled_error()),
    };
    drop(waiting);
    match device {
        Ok(device) => render_and_store(&state, id, job, (admitted, device), events, cancel, started).await,
        Err(error) => finish_failed(&state, &id, &job.method.name, error, started, &events).await,
    }
}

/// One worker of a replica on a shared store: with a free device slot, takes the next job
/// (a dead replica's first), keeps it claimed while it renders, stores the outcome.
pub(super) async fn work_shared_queue(state: Arc<AppState>, consumer: String) {
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
        let name = consumer.clone();
        let stored = match store.call(move |s| s.next(&name, std::time::Duration::ZERO)).await {
            // Claimed back while this replica still holds it, storing its finished result
            // through an outage: not rendered again; storing it acknowledges the entry.
            Ok(Some(stored)) if state.jobs.submitted(&stored.id).is_some_and(|e| !e.borrow().finished()) => continue,
            Ok(Some(stored)) => stored,
            Ok(None) => {
                drop(device);
                tokio::time::sleep(SHARED_QUEUE_POLL).await;
                continue;
            }
            Err(error) => {
                // An outage is logged once by the store's health.
                tracing::debug!(%error, "cannot take a job from the shared queue; retrying in 1 s");
                drop(device);
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
                continue;
            }
        };
        let Ok(admitted) = state.queue.admit_waiting().await else { return };
        let started = std::time::Instant::now();
        let (events, _) = tokio::sync::watch::channel(JobEvent::status(JobStatus::Queued));
        let cancel = state.jobs.submit(stored.listed(), events.clone());
        let span = state::submitted_span(stored.request_id.as_deref());
        let method = stored.job["method"]["name"].as_str().unwrap_or("hard").to_owned();
        let job = match Job::from_json_limited(stored.job.to_string().as_bytes(), state.engine.limits()) {
            Ok(_) if stored.attempts >= MAX_ATTEMPTS => {
                let detail = abandoned(stored.attempts);
                store_failure(&state, &stored.id, detail.clone()).await;
                events.send_modify(|event| event.finish(JobStatus::Failed, Some(detail)));
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
            let mut tick = tokio::time::interval(beat_store.blocking().heartbeat_every());
            loop {
                tick.tick().await;
                let (c, j) = (beat_consumer.clone(), beat_job.clone());
                match beat_store.call(move |s| s.heartbeat(&c, &j).and_then(|()| s.cancelled(&j.id))).await {
                    Ok(true) => drop(beat_state.jobs.cancel(&beat_job.id)),
                    Err(error) => tracing::debug!(%error, "cannot renew the claim on a job"),
                    _ => {}
                }
            }
        });
        use tracing::Instrument as _;
        render_and_store(&state, stored.id.clone(), job, ((admitted, None), device), events, cancel, started).instrument(span).await;
        heartbeat.abort();
    }
}

/// The error of a job that daemons kept dying on: said in full, since the reason is the
/// point and reveals nothing internal.
pub(super) fn abandoned(attempts: u32) -> Value {
    json!({
        "code": "internal",
        "status": 500,
        "message": format!("the job was started {attempts} times by daemons that stopped before it finished; it is not retried again"),
    })
}

/// Renders a job that holds its device slot, reporting progress (to the shared store too, at
/// most every 250 ms), and stores the outcome. The device slot goes as soon as the render is
/// done; the queue place and the promised room stay until the outcome is stored, which is
/// retried while the store cannot take it (`persist`).
pub(super) async fn render_and_store(
    state: &Arc<AppState>,
    id: String,
    job: Job,
    (admitted, device): (Admitted, tokio::sync::OwnedSemaphorePermit),
    events: tokio::sync::watch::Sender<JobEvent>,
    cancel: tokio::sync::watch::Receiver<bool>,
    started: std::time::Instant,
) {
    let method = job.method.name.clone();
    events.send_replace(JobEvent::status(JobStatus::Running));
    let running = state.metrics.job_running();
    if let Some(store) = &state.store {
        let running_id = id.clone();
        if let Err(error) = store.call(move |s| s.start(&running_id)).await {
            tracing::debug!(%error, "cannot mark the job running in the store");
        }
    }
    let (progress, store, job_id) = (events.clone(), state.store.clone(), id.clone());
    let last_shared = std::sync::Mutex::new(std::time::Instant::now());
    let report = move |done, total| {
        progress.send_modify(|event| {
            event.done = done;
            event.total = total;
        });
        if let Some(store) = store.as_ref().filter(|s| s.shared()) {
            let mut last = last_shared.lock().unwrap_or_else(|p| p.into_inner());
            if last.elapsed() >= std::time::Duration::from_millis(250) {
                *last = std::time::Instant::now();
                let _ = store.call_blocking(|s| s.progress(&job_id, done, total));
            }
        }
    };
    // A progressive job's rounds are kept until it ends, whichever way it ends.
    let _rounds = RoundsKept { state, id: id.clone() };
    let outcome = match job.progressive {
        Some(spec) => super::progressive::render_rounds(state, &id, job, spec, device, &events, cancel).await,
        None => {
            let supervise = Supervise { progress: report, cancelled: move || *cancel.borrow() };
            let outcome = render_blocking(state, &id, job, supervise, (), |_| {}).await;
            drop(device);
            outcome
        }
    };
    drop(running);
    let rendered = match outcome {
        Ok(rendered) => Arc::new(rendered),
        Err(error) => {
            finish_failed(state, &id, &method, error, started, &events).await;
            drop(admitted);
            return;
        }
    };
    if state.store.is_some() {
        let (stored_id, stored) = (id.clone(), rendered.clone());
        let record = Arc::new(job_json(&id, &rendered));
        match persist(state, &id, "result", move |s| s.succeed(&stored_id, &record, &stored.bytes)).await {
            Ok(true) => {}
            // Cancelled through the store while it rendered: the client was told so.
            Ok(false) => {
                finish_failed(state, &id, &method, crate::supervise::cancelled_error(), started, &events).await;
                drop(admitted);
                return;
            }
            Err(error) if state.shared_store().is_some() => {
                // Left pending on the shared queue: another replica (or this one) claims it
                // once the store is back, and renders it again.
                tracing::error!(%id, %error, "gave up storing a finished result; the job stays claimable on the shared queue");
                state.jobs.forget(&id);
                drop(admitted);
                return;
            }
            Err(error) => {
                tracing::error!(%id, %error, "gave up storing a finished result; it is served from memory until a restart renders it again");
            }
        }
    }
    state.job_finished(&id, &method, "ok", started.elapsed().as_secs_f64(), Some(&rendered));
    tracing::info!(%id, total_ms = rendered.timings.total_ms, "job done");
    state.jobs.keep(id, rendered);
    events.send_modify(|event| event.finish(JobStatus::Succeeded, None));
    // The queue place goes only now: a drain that sees it back finds the job recorded.
    drop(admitted);
}

/// Drops a progressive job's round images when its life here ends.
struct RoundsKept<'a> {
    state: &'a AppState,
    id: String,
}

impl Drop for RoundsKept<'_> {
    fn drop(&mut self) {
        self.state.jobs.drop_rounds(&self.id);
        if let Some(store) = self.state.store.clone() {
            let id = self.id.clone();
            let remove = move || {
                if let Err(error) = store.call_blocking(|s| s.drop_rounds(&id)) {
                    tracing::warn!(%id, %error, "could not remove a finished job's round images");
                }
            };
            // Off the runtime's threads where there is one (a task dropped as the runtime
            // shuts down has none: the next start clears the rounds anyway).
            match tokio::runtime::Handle::try_current() {
                Ok(runtime) => drop(runtime.spawn_blocking(remove)),
                Err(_) => remove(),
            }
        }
    }
}

/// Writes a finished job's outcome to the store, retrying with backoff (0.25 s, doubling to
/// 5 s) while the store is unavailable or full, for up to `--store-retry-secs` or until the
/// daemon stops — so no accepted job fails because the store blinked. Err: the last error,
/// once it gave up or met an error that retrying cannot cure.
pub(super) async fn persist<T: Send + 'static>(
    state: &AppState,
    id: &str,
    what: &'static str,
    write: impl Fn(&dyn DurableStore) -> crate::store::StoreResult<T> + Clone + Send + 'static,
) -> crate::store::StoreResult<T> {
    let Some(store) = &state.store else { return Err(StoreError::Other(anyhow::anyhow!("no store"))) };
    let give_up = std::time::Instant::now() + state.store_retry;
    let mut stopping = state.stopping.subscribe();
    let mut wait = std::time::Duration::from_millis(250);
    let mut waiting = None;
    loop {
        let attempt = write.clone();
        match store.call(move |s| attempt(s)).await {
            Err(error) if error.is_transient() && std::time::Instant::now() + wait < give_up && !*stopping.borrow() => {
                if waiting.is_none() {
                    tracing::warn!(%id, %error, "cannot store the job's {what} yet; retrying until the store takes it");
                    waiting = Some(store.health().waiting_write());
                }
                tokio::select! {
                    _ = tokio::time::sleep(wait) => {}
                    _ = stopping.wait_for(|stop| *stop) => {}
                }
                wait = (wait * 2).min(std::time::Duration::from_secs(5));
            }
            outcome => {
                if waiting.is_some() && outcome.is_ok() {
                    tracing::info!(%id, "stored the job's {what} after the store came back");
                }
                return outcome;
            }
        }
    }
}

/// Records, stores and announces a job's failure (or cancellation).
pub(super) async fn finish_failed(
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
    if status == JobStatus::Cancelled {
        tracing::info!(%id, "job cancelled");
    }
    store_failure(state, id, detail.clone()).await;
    events.send_modify(|event| event.finish(status, Some(detail)));
}

/// Stores a job's failure, retried as results are (`persist`).
pub(super) async fn store_failure(state: &AppState, id: &str, detail: Value) {
    if state.store.is_none() {
        return;
    }
    let stored_id = id.to_owned();
    if let Err(error) = persist(state, id, "failure", move |s| s.fail(&stored_id, &detail)).await {
        tracing::warn!(%id, %error, "cannot store the job's failure");
    }
}

/// A failed job's error as its record and events carry it: the error body with its status.
pub(super) fn failure_detail(error: &JobError) -> Value {
    let mut detail = error::error_body(error);
    detail["status"] = json!(error::status_of(error.code).as_u16());
    detail
}
