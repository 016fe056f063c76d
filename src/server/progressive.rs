//! A progressive job's rounds (contract §5): a first image from a fast method the device's
//! model picks for a tenth of the budget, then the `reference` in rounds of light samples —
//! each round's sums carried to the next (`supervise::Rounds`), its image kept while the job
//! runs and announced as an SSE `round` event with the error estimate of its samples' halves
//! — until the estimate meets `max_error`, the next round would end past `max_ms`, the
//! samples run out, or the job is cancelled. The device slot is held one round at a time, so a
//! progressive job never keeps other jobs from the device longer than one round.

use std::sync::Arc;
use std::time::Instant;

use tokio::sync::{watch, OwnedSemaphorePermit};

use super::*;
use crate::job::progressive::{round_method, round_samples, Progressive, ProgressiveOutcome, Round, Stopped, FIRST_ROUND_SAMPLES};
use crate::render::method::ERROR_ESTIMATE;
use crate::supervise::{Rounds, WithRounds};

/// Renders a progressive job, `device` its first slot: every round published as it comes,
/// the last returned with the rounds' story (`ProgressiveOutcome`).
pub(super) async fn render_rounds(
    state: &Arc<AppState>,
    id: &str,
    job: Job,
    spec: Progressive,
    device: OwnedSemaphorePermit,
    events: &watch::Sender<JobEvent>,
    cancel: watch::Receiver<bool>,
) -> Result<Rendered, JobError> {
    let started = Instant::now();
    // Each round is a job rendered once.
    let job = Job { progressive: None, ..job };
    let model = state.model.get();
    let features = state.features(&job);
    let first_round_ms = model.first_round_ms(&features);
    let (candidate, prediction) = model
        .first_image(spec.max_ms, &features, |c| state.allows(c, &job))
        .ok_or_else(|| JobError::internal("the device's model has no method for a first image"))?;
    let first_job = Job { method: candidate.method_for(&job), ..job.clone() };
    let mut published = Published { state, id, events, started, rounds: Vec::new() };
    let mut last = render_round(state, id, first_job.clone(), None, events, cancel.clone()).await?;
    drop(device);
    published.publish(&last, &candidate.label, 0, prediction.error, true).await;
    let mut equivalent = first_job.method;

    // The reference's rounds, each in a device slot of its own.
    let carried = Arc::new(Rounds::default());
    let (mut stopped, mut before, mut last_round) = (Stopped::Samples, 0u32, None::<(u32, f64)>);
    for total in round_samples(samples_cap(&job, state.engine.limits())) {
        if *cancel.borrow() {
            return Err(crate::supervise::cancelled_error());
        }
        if let Some(max_ms) = spec.max_ms {
            // This round's time: the last one's per new sample (each round re-draws the frame
            // too, so this errs long), or the model's for the first.
            let predicted = match last_round {
                Some((samples, ms)) => ms * f64::from(total - before) / f64::from(samples),
                None => first_round_ms.unwrap_or(0.0) * f64::from(total) / f64::from(FIRST_ROUND_SAMPLES),
            };
            if started.elapsed().as_secs_f64() * 1e3 + predicted > max_ms {
                stopped = Stopped::MaxMs;
                break;
            }
        }
        let round_job = Job { method: round_method(&job.method, total), ..job.clone() };
        let slot = state.queue.device().await?;
        let round_started = Instant::now();
        let rendered = render_round(state, id, round_job.clone(), Some(carried.clone()), events, cancel.clone()).await?;
        drop(slot);
        last_round = Some((total - before, round_started.elapsed().as_secs_f64() * 1e3));
        before = total;
        let error = ERROR_ESTIMATE.get(&rendered.counters).unwrap_or(f64::NAN);
        published.publish(&rendered, &format!("reference:samples={total}"), total, error, false).await;
        (last, equivalent) = (rendered, round_job.method);
        if spec.max_error.is_some_and(|max| error <= max) {
            stopped = Stopped::MaxError;
            break;
        }
    }
    last.progressive = Some(ProgressiveOutcome { rounds: published.rounds, stopped, equivalent });
    Ok(last)
}

/// The most samples a progressive job takes: its `samples` where it gives them, else every
/// sample this server allows a reference.
pub(super) fn samples_cap(job: &Job, limits: &crate::job::Limits) -> u32 {
    let given = job.method.params.get("samples").and_then(|v| v.as_u64()).and_then(|n| u32::try_from(n).ok());
    given.unwrap_or_else(|| limits.max_samples.min(crate::methods::reference::MAX_SAMPLES))
}

/// The rounds published so far.
struct Published<'a> {
    state: &'a Arc<AppState>,
    id: &'a str,
    events: &'a watch::Sender<JobEvent>,
    started: Instant,
    rounds: Vec<Round>,
}

impl Published<'_> {
    /// Keeps a round's image while the job runs — on a local store's disk, where admission
    /// promised it room, else in memory, and in a shared store for the other replicas too —
    /// and announces it, to the other replicas through a shared store.
    async fn publish(&mut self, rendered: &Rendered, method: &str, samples: u32, error_estimate: f64, predicted: bool) {
        let number = self.rounds.len() as u32;
        let image = Arc::new(rendered.bytes.clone());
        let mut bytes = Some(image.clone());
        if let Some(store) = &self.state.store {
            let (id, shared) = (self.id.to_owned(), store.shared());
            match store.call(move |s| s.put_round(&id, number as usize, &image)).await {
                // This replica serves it from the local disk; from memory where it is shared.
                Ok(true) if !shared => bytes = None,
                Ok(_) => {}
                // Kept in memory (only): the round is still served here, and the job goes on.
                Err(error) => tracing::warn!(id = self.id, round = number, %error, "could not keep a round image in the store"),
            }
        }
        self.state.jobs.keep_round(self.id, crate::queue::KeptRound { format: rendered.format, bytes });
        let round = Round {
            round: number,
            method: method.to_owned(),
            samples,
            error_estimate,
            predicted,
            elapsed_ms: self.started.elapsed().as_secs_f64() * 1e3,
            image: format!("/v1/jobs/{}/rounds/{number}", self.id),
        };
        tracing::info!(id = self.id, round = number, samples, error_estimate, "progressive round");
        self.events.send_modify(|event| {
            event.round = Some(round.clone());
            event.rounds.push(round.clone());
        });
        if let Some(store) = self.state.store.as_ref().filter(|s| s.shared()) {
            let (id, drawn) = (self.id.to_owned(), round.clone());
            if let Err(error) = store.call(move |s| s.round_drawn(&id, &drawn)).await {
                tracing::warn!(id = self.id, round = number, %error, "could not announce a round to the other replicas");
            }
        }
        self.rounds.push(round);
    }
}

/// One round's render on the blocking pool, its progress in the job's events; `carried`
/// holds the reference's sums from round to round.
async fn render_round(
    state: &Arc<AppState>,
    id: &str,
    job: Job,
    carried: Option<Arc<Rounds>>,
    events: &watch::Sender<JobEvent>,
    cancel: watch::Receiver<bool>,
) -> Result<Rendered, JobError> {
    let (engine, store, events) = (state.engine.clone(), state.store.clone(), events.clone());
    let span = tracing::info_span!("job", %id, method = %job.method.name);
    tokio::task::spawn_blocking(move || {
        let _entered = span.enter();
        let supervise = Supervise {
            progress: |done, total| {
                events.send_modify(|event| (event.done, event.total) = (done, total));
            },
            cancelled: || *cancel.borrow(),
        };
        fetch_shared_uploads(&engine, store.as_ref(), &job)?;
        match &carried {
            Some(rounds) => engine.render(&job, &WithRounds { inner: &supervise, rounds }),
            None => engine.render(&job, &supervise),
        }
    })
    .await
    .unwrap_or_else(|e| Err(JobError::internal(format!("render task failed: {e}"))))
}
