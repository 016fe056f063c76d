//! `auto` jobs and estimates (contract §5): the device's cost and quality model (the shipped
//! one until this device's is measured in the background, or read from the data directory),
//! a budget resolved to a method at submission and again on the replica that renders it, and
//! `POST /v1/estimate`, which predicts a job without rendering it.

use std::sync::RwLock;

use super::*;
use crate::config::ModelMode;
use crate::job::auto::{AutoBudget, AutoChoice, Prediction};
use crate::model::{self, Features, Model};

/// The model in use and where it stands.
pub struct ModelState {
    current: RwLock<Arc<Model>>,
    /// How fast the device runs against `current` lately.
    pace: model::Pace,
    /// `default` (the shipped model), `measuring`, `measured`, `stored` (read from the data
    /// directory) or `failed` (the shipped model stays).
    status: RwLock<&'static str>,
}

impl ModelState {
    pub fn shipped() -> Self {
        Self { current: RwLock::new(Arc::new(Model::shipped())), pace: model::Pace::default(), status: RwLock::new("default") }
    }

    pub fn get(&self) -> Arc<Model> {
        self.current.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// `Pace::factor` of the model in use.
    pub fn pace(&self) -> f64 {
        self.pace.factor()
    }

    /// Renders the pace follows now (`Pace::observed`).
    pub fn pace_renders(&self) -> usize {
        self.pace.observed()
    }

    /// A rendered job's time against the model's prediction for it (`Pace::observe`), where
    /// the model has its method (an `auto` job's choice, or a job whose method is a
    /// candidate's) and its scene was counted (a path's triangles are a guess: its time says
    /// nothing of the device's pace). `features`: the job's, at pace 1 — made only for a job
    /// the model has.
    pub fn observe(&self, job: &Job, features: impl FnOnce() -> Features, measured_ms: f64) {
        let model = self.get();
        let Some(candidate) = model.candidates.iter().find(|c| same_defaults(c, job)) else { return };
        let features = features();
        if features.triangles_known {
            self.pace.observe(candidate.ms(&features), measured_ms);
        }
    }

    pub fn status(&self) -> &'static str {
        *self.status.read().unwrap_or_else(|p| p.into_inner())
    }

    fn set_status(&self, status: &'static str) {
        *self.status.write().unwrap_or_else(|p| p.into_inner()) = status;
    }

    /// A new model, its pace started afresh (it was measured on the device as it runs now).
    fn set(&self, model: Model, status: &'static str) {
        *self.current.write().unwrap_or_else(|p| p.into_inner()) = Arc::new(model);
        self.pace.reset();
        self.set_status(status);
    }
}

/// Reads this device's stored model, or measures it in the background with the device's job
/// slots (a job waits at most for one small frame of it); `/readyz` is not held for it.
pub(super) fn spawn_model(state: Arc<AppState>, mode: ModelMode, data_dir: std::path::PathBuf) {
    if mode == ModelMode::Default {
        return;
    }
    tokio::spawn(async move {
        let (measuring, runtime) = (state.clone(), tokio::runtime::Handle::current());
        // Blocking throughout (the executable hashed, a file read, renders): off the workers.
        let outcome = tokio::task::spawn_blocking(move || read_or_measure(&measuring, mode, &data_dir, runtime)).await;
        if let Err(error) = outcome {
            tracing::warn!(%error, "measuring the model failed: auto keeps the shipped model");
            state.model.set_status("failed");
        }
    });
}

/// `spawn_model`'s work: the model stored for this adapter and build, else one measured on
/// the suite `mode` names and kept for the next start.
fn read_or_measure(state: &AppState, mode: ModelMode, data_dir: &std::path::Path, runtime: tokio::runtime::Handle) {
    let mut key = model::key_for(&state.engine.adapter());
    if mode == ModelMode::Quick {
        // Kept apart: a quick model is not what a `measure` start should find.
        key.build.push_str("+quick");
    }
    if let Some(stored) = model::load(data_dir, &key) {
        tracing::info!(build = %key.build, "cost and quality model read from the data directory");
        state.model.set(stored, "stored");
        return;
    }
    state.model.set_status("measuring");
    tracing::info!("measuring the cost and quality model in the background");
    let suite = match mode {
        ModelMode::Quick => model::measure::Suite::quick(),
        ModelMode::Measure | ModelMode::Default => model::measure::Suite::standard(),
    };
    match model::measure::measure(&state.engine, &suite, key, &SlotHooks { state, runtime }) {
        Ok(Some(measured)) => {
            if let Err(error) = model::save(data_dir, &measured) {
                tracing::warn!(%error, "the measured model could not be kept for the next start");
            }
            tracing::info!(seconds = measured.measure_seconds, "cost and quality model measured");
            state.model.set(measured, "measured");
        }
        Ok(None) => state.model.set_status("default"),
        Err(error) => {
            tracing::warn!(%error, "measuring the model failed: auto keeps the shipped model");
            state.model.set_status("failed");
        }
    }
}

/// The measurement's renders take a device slot each, as jobs do, and stop at shutdown.
struct SlotHooks<'a> {
    state: &'a AppState,
    runtime: tokio::runtime::Handle,
}

impl model::measure::Hooks for SlotHooks<'_> {
    fn device(&self) -> Box<dyn std::any::Any> {
        Box::new(self.runtime.block_on(self.state.queue.device_slot()))
    }

    fn progress(&self, done: usize, total: usize, what: &str) {
        tracing::debug!(done, total, what, "measuring the model");
    }

    fn cancelled(&self) -> bool {
        *self.state.stopping.borrow()
    }
}

impl AppState {
    /// An `auto` job's method chosen: `None` for any other job. Checks the budget's fields
    /// (`max_ms` at most the job deadline) and the rest of the job first. `strict` (at
    /// submission) refuses a budget no candidate is predicted to meet, with a 422 naming the
    /// field and the closest candidate; at render time (a replica whose model has changed
    /// since) the closest is rendered instead and says so.
    pub(super) fn resolve_auto(&self, job: &Job, strict: bool) -> Result<Option<(Job, AutoChoice)>, JobError> {
        let Some(budget) = AutoBudget::of(&job.method)? else { return Ok(None) };
        let features = self.checked_features(job, Some(&budget), false)?;
        let model = self.model.get();
        let (candidate, prediction) = match self.choose(&model, &budget, &features, job) {
            Ok(chosen) => chosen,
            Err(unmet) if strict || unmet.closest.is_empty() => {
                return Err(JobError::field(ErrorCode::BudgetUnmet, unmet.field, unmet.message))
            }
            Err(unmet) => {
                tracing::warn!(closest = %unmet.closest, "no method meets the budget at render time: the closest is rendered");
                let closest = model.candidates.iter().find(|c| c.label == unmet.closest).expect("named from the model");
                (closest.clone(), unmet.prediction)
            }
        };
        let choice = model.choice(&candidate, prediction, job);
        Ok(Some((Job { method: choice.method.clone(), ..job.clone() }, choice)))
    }

    /// The model's choice for `job` under `budget`, among the candidates this server's limits
    /// allow (`--max-samples` may rule out the 1,024-sample reference).
    pub(super) fn choose(
        &self,
        model: &model::Model,
        budget: &AutoBudget,
        features: &Features,
        job: &Job,
    ) -> Result<(model::Candidate, Prediction), model::Unmet> {
        model.choose_among(budget, features, |c| self.allows(c, job))
    }

    /// Whether this server's limits let `job` ask for `candidate`'s method.
    pub(super) fn allows(&self, candidate: &model::Candidate, job: &Job) -> bool {
        self.engine.check(&Job { method: candidate.method_for(job), ..job.clone() }, false).is_ok()
    }

    /// A job checked as a submission is — an `auto` one with its `budget` checked in place of
    /// its method, everything else before the scene is built to count its triangles — and what
    /// its predictions follow.
    fn checked_features(&self, job: &Job, budget: Option<&AutoBudget>, uploads_here: bool) -> Result<Features, JobError> {
        match budget {
            Some(budget) => {
                self.check_budget(budget)?;
                self.engine.check(&Job { method: Default::default(), ..job.clone() }, uploads_here)?;
            }
            None => self.engine.check(job, uploads_here)?,
        }
        Ok(self.features(job))
    }

    /// What `job`'s predictions follow, at the device's pace.
    pub(super) fn features(&self, job: &Job) -> Features {
        Features { pace: self.model.pace(), ..self.unpaced_features(job) }
    }

    /// `features` at pace 1: what the pace itself is measured against.
    pub(super) fn unpaced_features(&self, job: &Job) -> Features {
        Features::of(job, self.engine.scene_shape(&job.scene).as_ref())
    }

    /// `max_ms` no longer than a job may wait for the device (the deadline).
    fn check_budget(&self, budget: &AutoBudget) -> Result<(), JobError> {
        let deadline_ms = self.queue_config.deadline.as_secs_f64() * 1e3;
        match budget.max_ms {
            Some(max) if max > deadline_ms => {
                Err(JobError::invalid("method.max_ms", format!("must be at most the job deadline, {deadline_ms:.0} ms")))
            }
            _ => Ok(()),
        }
    }

    /// A job checked for admission: an `auto` job's budget resolved (strictly) and the
    /// method chosen checked as any job's.
    pub(super) fn check_submission(&self, job: &Job, uploads_here: bool) -> Result<(), JobError> {
        if let Some(max_ms) = job.progressive.and_then(|p| p.max_ms) {
            let deadline_ms = self.queue_config.deadline.as_secs_f64() * 1e3;
            if max_ms > deadline_ms {
                return Err(JobError::invalid("progressive.max_ms", format!("must be at most the job deadline, {deadline_ms:.0} ms")));
            }
        }
        match self.resolve_auto(job, true)? {
            Some((chosen, _)) => self.engine.check(&chosen, uploads_here),
            None => self.engine.check(job, uploads_here),
        }
    }
}

/// `POST /v1/estimate`: a job checked as a submission would be, and answered with what every
/// candidate is predicted to cost and how far from the truth on this device — the job's own
/// method's prediction where the model has it, and for `auto`, its choice or why none fits.
pub(super) async fn estimate(State(state): State<Arc<AppState>>, body: Result<Bytes, BytesRejection>) -> Result<Json<Value>, ApiError> {
    let body = body.map_err(|rejection| body_error(&state, rejection, ErrorCode::InvalidJson))?;
    let job = Job::from_json_limited(&body, state.engine.limits())?;
    let budget = AutoBudget::of(&job.method)?;
    let features = state.checked_features(&job, budget.as_ref(), state.shared_store().is_none())?;
    let model = state.model.get();
    let predictions: Vec<Value> = model
        .predictions(&features)
        .into_iter()
        .map(|(c, p)| json!({"label": c.label, "method": c.method_for(&job), "ms": p.ms, "error": p.error}))
        .collect();
    let mut answer = json!({
        "model": {"source": model.source, "status": state.model.status(), "adapter": model.key.adapter, "build": model.key.build},
        "features": {
            "pixels": features.pixels,
            "texels": features.texels,
            "triangles": features.triangles,
            "triangles_known": features.triangles_known,
            "map_share": features.map_share,
            "pace": features.pace,
            "light": features.light,
            "scene": features.scene,
        },
        "margin": model::MARGIN,
        "predictions": predictions,
    });
    match budget {
        Some(budget) => match state.choose(&model, &budget, &features, &job) {
            Ok((candidate, prediction)) => answer["auto"] = json!(model.choice(&candidate, prediction, &job)),
            Err(unmet) => {
                answer["unmet"] = json!({
                    "field": unmet.field,
                    "closest": unmet.closest,
                    "predicted": unmet.prediction,
                    "message": unmet.message,
                })
            }
        },
        None => {
            let own = model.candidates.iter().find(|c| same_defaults(c, &job));
            answer["job"] = match own {
                Some(c) => json!({"label": c.label, "predicted": c.predict(&features)}),
                None => Value::Null,
            };
        }
    }
    Ok(Json(answer))
}

/// Whether `candidate` is the job's method as the job gives it: the same name, and the same
/// parameters once the map resolution a candidate takes from the job is set on both.
fn same_defaults(candidate: &model::Candidate, job: &Job) -> bool {
    crate::methods::with_map_resolution(&job.method, job.shadow_map.resolution) == candidate.method_for(job)
}
