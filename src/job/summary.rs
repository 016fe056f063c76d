//! What the service remembers of a finished job for the dashboard, and what it computes over
//! the recent ones: throughput and latency per method (one replica's jobs or, through a shared
//! store, every replica's).

use std::time::Duration;

/// What the dashboard shows of one finished job (kept in a shared store for every replica's
/// `/v1/stats`, hence both ways through serde).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JobSummary {
    pub id: String,
    pub method: String,
    /// `ok`, or the error code.
    pub outcome: String,
    /// The replica that rendered it (`--replica-name`).
    #[serde(default)]
    pub replica: String,
    /// Milliseconds since the Unix epoch when it finished.
    pub finished_unix_ms: u64,
    /// Wall time from the request (or submission) to the result, queueing included.
    pub wall_ms: f64,
    /// Render phases of a successful job, in order: (name, wall milliseconds).
    pub phases: Vec<(String, f64)>,
    pub width: u32,
    pub height: u32,
}

/// Per-method latency over the recent window.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct MethodLatency {
    pub jobs: usize,
    pub failed: usize,
    pub p50_ms: f64,
    pub p95_ms: f64,
    pub max_ms: f64,
}

/// Of `jobs` (newest first), those finished in the `window` before `now_unix_ms`, per minute.
pub fn per_minute(jobs: &[JobSummary], now_unix_ms: u64, window: Duration) -> f64 {
    let since = now_unix_ms.saturating_sub(window.as_millis() as u64);
    let count = jobs.iter().filter(|job| job.finished_unix_ms >= since).count();
    count as f64 * 60.0 / window.as_secs_f64()
}

/// Latency percentiles per method (successful jobs; failures counted) over `jobs`.
pub fn latency_by_method(jobs: &[JobSummary]) -> std::collections::BTreeMap<String, MethodLatency> {
    let mut walls: std::collections::BTreeMap<String, (Vec<f64>, usize)> = Default::default();
    for job in jobs {
        let entry = walls.entry(job.method.clone()).or_default();
        if job.outcome == "ok" {
            entry.0.push(job.wall_ms);
        } else {
            entry.1 += 1;
        }
    }
    walls
        .into_iter()
        .map(|(method, (mut ms, failed))| {
            ms.sort_by(f64::total_cmp);
            let at = |q: f64| if ms.is_empty() { 0.0 } else { ms[((ms.len() - 1) as f64 * q).round() as usize] };
            let latency = MethodLatency { jobs: ms.len() + failed, failed, p50_ms: at(0.5), p95_ms: at(0.95), max_ms: at(1.0) };
            (method, latency)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(method: &str, outcome: &str, finished_unix_ms: u64, wall_ms: f64) -> JobSummary {
        JobSummary {
            id: format!("{method}-{finished_unix_ms}"),
            method: method.into(),
            outcome: outcome.into(),
            replica: "a".into(),
            finished_unix_ms,
            wall_ms,
            phases: vec![("method".into(), wall_ms / 2.0)],
            width: 4,
            height: 3,
        }
    }

    #[test]
    fn throughput_counts_the_window_and_latency_only_successes() {
        let now = 1_000_000;
        let jobs: Vec<JobSummary> =
            (0..10).map(|k| job("hard", if k == 3 { "cancelled" } else { "ok" }, now - k * 10_000, 100.0 * (k + 1) as f64)).collect();
        // Finished at now, now−10 s, …, now−90 s: seven within the last minute, its edge included.
        assert_eq!(per_minute(&jobs, now, Duration::from_secs(60)), 7.0);
        let latency = &latency_by_method(&jobs)["hard"];
        assert_eq!((latency.jobs, latency.failed), (10, 1));
        assert_eq!((latency.p50_ms, latency.max_ms), (600.0, 1000.0));
    }

    #[test]
    fn a_summary_survives_the_shared_store_round_trip() {
        let summary = job("pcss", "ok", 5, 12.5);
        let back: JobSummary = serde_json::from_str(&serde_json::to_string(&summary).unwrap()).unwrap();
        assert_eq!(back, summary);
    }
}
