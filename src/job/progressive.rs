//! `"progressive": {"max_error": …, "max_ms": …}` (contract §5): a submitted `reference` job
//! that answers at once with a fast method's image, then refines in rounds of light samples
//! until its own error estimate meets `max_error`, its time is spent, or its samples run out.
//! The spec and its checks, the rounds' sample counts, and what each round reports.

use serde::{Deserialize, Serialize};

use super::Job;
use crate::error::{JobError, JobResult};

/// What a progressive job asks for: at least one of an error and a time.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Progressive {
    /// Stop once the estimated mean |V − Vref| over the penumbra is at most this, in (0, 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_error: Option<f64>,
    /// Start no round that would end past this many milliseconds from the job's start.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_ms: Option<f64>,
}

/// The samples of the first refinement round: enough for each half of the samples to hold two
/// of the sequence's 2 × 2-stratified blocks, so that the first error estimate means something.
pub const FIRST_ROUND_SAMPLES: u32 = 16;

impl Progressive {
    /// Refuses budgets that are not finite and positive, an error outside (0, 1), a spec with
    /// neither, and a method other than `reference` (each naming its field). The time's
    /// ceiling (the job deadline) is the server's to check.
    pub fn check(&self, job: &Job) -> JobResult<()> {
        if let Some(error) = self.max_error {
            if !(error.is_finite() && error > 0.0 && error < 1.0) {
                return Err(JobError::invalid("progressive.max_error", "must be in (0, 1): a mean |V − Vref| over the penumbra"));
            }
        }
        if let Some(ms) = self.max_ms {
            if !(ms.is_finite() && ms > 0.0) {
                return Err(JobError::invalid("progressive.max_ms", "must be a finite number of milliseconds > 0"));
            }
        }
        if self.max_error.is_none() && self.max_ms.is_none() {
            return Err(JobError::invalid("progressive.max_error", "a progressive job needs max_error, max_ms or both"));
        }
        if job.compare {
            return Err(JobError::invalid(
                "compare",
                "a progressive job estimates its own error every round; `compare` is for jobs rendered once",
            ));
        }
        if job.method.name != "reference" {
            return Err(JobError::invalid(
                "method.name",
                format!("a progressive job refines a `reference` (its samples the most it takes), not `{}`", job.method.name),
            ));
        }
        Ok(())
    }
}

/// The samples taken by the end of each round, for at most `cap` samples: 16, 32, 64, … —
/// doubling, so that each round halves the error's variance and the rounds' time before the
/// last is at most the last's — and `cap` itself last.
pub fn round_samples(cap: u32) -> Vec<u32> {
    let mut totals = Vec::new();
    let mut n = FIRST_ROUND_SAMPLES.min(cap.max(1));
    loop {
        totals.push(n);
        if n >= cap {
            return totals;
        }
        n = (n * 2).min(cap);
    }
}

/// A round's method: the job's reference with `samples` so far, on the CPU engine — the only
/// one that carries its sums between rounds (the round's image is that of this method).
pub fn round_method(method: &super::MethodSpec, samples: u32) -> super::MethodSpec {
    let mut method = method.clone();
    method.params.insert("samples".into(), samples.into());
    method.params.insert("engine".into(), "cpu".into());
    method
}

/// One round of a progressive job, as its events and record report it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Round {
    /// 0: the fast method's first image; 1, 2, …: the reference's rounds.
    pub round: u32,
    /// The method that drew it, with its parameters (`reference` with `samples` so far).
    pub method: String,
    /// Light samples taken so far (0 for the first image).
    pub samples: u32,
    /// The estimated mean |V − Vref| over the penumbra: from the samples' halves for a
    /// reference round, the model's prediction for the first image.
    pub error_estimate: f64,
    /// Whether `error_estimate` is the model's prediction rather than measured from samples.
    pub predicted: bool,
    /// Milliseconds from the job's start to this round's image.
    pub elapsed_ms: f64,
    /// Where the round's image is, while the job runs (the last round's is the job's image).
    pub image: String,
}

/// Why a progressive job stopped refining.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stopped {
    /// The error estimate met `max_error`.
    MaxError,
    /// The next round would have ended past `max_ms`.
    MaxMs,
    /// Every sample the job allows was taken.
    Samples,
}

/// What a finished progressive job's record says of its rounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProgressiveOutcome {
    pub rounds: Vec<Round>,
    pub stopped: Stopped,
    /// The non-progressive job whose image this one's final image is, byte for byte
    /// (a `reference` with the samples taken and the job's seed), or the first image's
    /// method where no reference round finished in time.
    pub equivalent: super::MethodSpec,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounds_double_from_sixteen_to_the_cap() {
        assert_eq!(round_samples(256), [16, 32, 64, 128, 256]);
        assert_eq!(round_samples(100), [16, 32, 64, 100]);
        assert_eq!(round_samples(16), [16]);
        assert_eq!(round_samples(4), [4]);
    }

    #[test]
    fn bad_budgets_name_their_field() {
        let mut job = Job::embedded_default();
        job.method.name = "reference".into();
        let field = |p: Progressive, job: &Job| p.check(job).err().and_then(|e| e.field);
        assert_eq!(field(Progressive::default(), &job).as_deref(), Some("progressive.max_error"));
        assert_eq!(field(Progressive { max_error: Some(1.0), max_ms: None }, &job).as_deref(), Some("progressive.max_error"));
        assert_eq!(field(Progressive { max_error: None, max_ms: Some(f64::NAN) }, &job).as_deref(), Some("progressive.max_ms"));
        assert_eq!(field(Progressive { max_error: None, max_ms: Some(-1.0) }, &job).as_deref(), Some("progressive.max_ms"));
        assert!(Progressive { max_error: Some(0.01), max_ms: Some(1000.0) }.check(&job).is_ok());
        job.method.name = "pcss".into();
        assert_eq!(field(Progressive { max_error: Some(0.01), max_ms: None }, &job).as_deref(), Some("method.name"));
    }
}
