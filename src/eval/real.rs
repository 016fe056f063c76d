//! The real-model suite summed up per light and method: the mean and the worst penumbra
//! error over the models, how many models a method does worse on than the gray baseline
//! `pcss` (by 1.25× and 1.5×), and its mean on the built-in scenes of the same run beside it.
//! A method is only as good as its worst real model.

use serde::Serialize;

use super::Row;

/// The baseline every soft method is held against, model by model.
pub const BASELINE: &str = "pcss";

/// A model whose reference has less penumbra than this share of the frame is left out of the
/// summaries (its errors are a handful of pixels' noise), though its row is listed.
pub const MIN_PENUMBRA_SHARE: f64 = 0.005;

/// Whether a row's case has penumbra enough to be measured (`MIN_PENUMBRA_SHARE`).
pub fn measurable(row: &Row) -> bool {
    row.quality.penumbra_pixels as f64 >= MIN_PENUMBRA_SHARE * f64::from(row.width) * f64::from(row.height)
}

/// One method's penumbra error (mean |V − Vref| over the reference's penumbra) over the real
/// models under one light.
#[derive(Debug, Clone, Serialize)]
pub struct RealSummary {
    pub light: String,
    pub method: String,
    pub models: usize,
    pub mean: f64,
    pub worst: f64,
    pub worst_model: String,
    /// Models where the error exceeds 1.25 × and 1.5 × `pcss`'s on the same model.
    pub over_baseline_125: usize,
    pub over_baseline_150: usize,
    /// The method's mean over the built-in scenes of the same run under the same light.
    pub builtin_mean: Option<f64>,
    /// Every model, worst first: (scene, case picture name, error).
    pub ranked: Vec<(String, String, f64)>,
}

impl RealSummary {
    /// The mean over real models against the mean over built-ins (the target: ≤ 1.25).
    pub fn over_builtin(&self) -> Option<f64> {
        self.builtin_mean.filter(|b| *b > 0.0).map(|b| self.mean / b)
    }
}

fn error(row: &Row) -> f64 {
    row.quality.visibility.penumbra.mae
}

/// The summaries of every light and method that ran on real models (methods in run order).
pub fn summarize(rows: &[Row]) -> Vec<RealSummary> {
    let mut keys: Vec<(&str, &str)> = Vec::new();
    let rows: Vec<&Row> = rows.iter().filter(|r| measurable(r)).collect();
    for row in rows.iter().filter(|r| r.real_model && r.method != "reference") {
        if !keys.contains(&(row.light.as_str(), row.method.as_str())) {
            keys.push((&row.light, &row.method));
        }
    }
    keys.into_iter()
        .map(|(light, method)| {
            let chosen: Vec<&Row> = rows.iter().copied().filter(|r| r.real_model && r.light == light && r.method == method).collect();
            let baseline = |row: &Row| {
                rows.iter()
                    .find(|b| b.method == BASELINE && b.scene == row.scene && b.light == row.light && b.case == row.case)
                    .map(|b| error(b))
            };
            let over = |factor: f64| chosen.iter().filter(|r| baseline(r).is_some_and(|b| error(r) > factor * b)).count();
            let mut ranked: Vec<(String, String, f64)> = chosen.iter().map(|r| (r.scene.clone(), r.case.clone(), error(r))).collect();
            ranked.sort_by(|a, b| b.2.total_cmp(&a.2));
            let builtin: Vec<f64> =
                rows.iter().filter(|r| !r.real_model && r.light == light && r.method == method).map(|r| error(r)).collect();
            RealSummary {
                light: light.to_owned(),
                method: method.to_owned(),
                models: chosen.len(),
                mean: chosen.iter().map(|r| error(r)).sum::<f64>() / chosen.len() as f64,
                worst: ranked[0].2,
                worst_model: ranked[0].0.clone(),
                over_baseline_125: if method == BASELINE { 0 } else { over(1.25) },
                over_baseline_150: if method == BASELINE { 0 } else { over(1.5) },
                builtin_mean: (!builtin.is_empty()).then(|| builtin.iter().sum::<f64>() / builtin.len() as f64),
                ranked,
            }
        })
        .collect()
}
