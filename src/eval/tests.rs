//! Unit tests of `eval`.

use super::*;
use crate::timing::{Phase, PhaseName};

fn timings(method_ms: f64, gpu_ms: Option<f64>) -> Timings {
    Timings {
        phases: vec![
            Phase { name: PhaseName::Gbuffer, cpu_ms: 1.0, gpu_ms: None, passes: Vec::new() },
            Phase { name: PhaseName::Method, cpu_ms: method_ms, gpu_ms, passes: Vec::new() },
        ],
        ..Default::default()
    }
}

#[test]
fn repeated_runs_report_each_phases_median() {
    let runs = vec![timings(10.0, Some(9.0)), timings(300.0, Some(290.0)), timings(12.0, Some(11.0))];
    let median = median_timings(runs);
    assert_eq!(median.phases[1].cpu_ms, 12.0, "one slow spell does not move the median");
    assert_eq!(median.phases[1].gpu_ms, Some(11.0));
    assert_eq!(median.phases[0].cpu_ms, 1.0);
    assert_eq!(median_timings(vec![timings(4.0, None), timings(6.0, None)]).phases[1].cpu_ms, 5.0);
}
