//! Measuring the model (contract §5): every candidate rendered on a small built-in suite — three
//! scene kinds, a white and a coloured light, two sizes, two map resolutions — its wall time
//! fitted as a linear cost of the job's features, and its penumbra error taken against a
//! 1,024-sample reference of another seed.

use std::time::Instant;

use serde_json::Map;

use super::{Candidate, Cost, Costs, ErrorPoint, Features, Model, ModelKey, TimePoint, FEATURES};
use crate::engine::Engine;
use crate::error::JobResult;
use crate::job::{AssetRef, Job, LightSpec, MethodSpec, OutputFormat, OutputSpec, ShadowMapSpec};
use crate::render::FrameOutput;

/// The candidates `auto` chooses among, cheapest first: every method at its defaults, and the
/// reference at four sample counts (1,024 predicted from 64 and 256, not rendered: it is the
/// suite's truth's own cost).
pub const CANDIDATES: &[&str] = &[
    "hard",
    "pcss",
    "chun-oh",
    "brabec",
    "jfa-l",
    "jfa-e",
    "wedges",
    "filtered",
    "reference:samples=16",
    "reference:samples=64",
    "reference:samples=256",
];

/// What the model is measured on. The daemon and `eval --model` measure `Suite::standard`.
#[derive(Debug, Clone)]
pub struct Suite {
    /// Built-in scenes with their parameters (JSON objects).
    pub scenes: Vec<(&'static str, &'static str)>,
    /// Built-in light images: `white` and coloured ones (a job under another light is
    /// predicted as the worst of the coloured).
    pub lights: Vec<&'static str>,
    /// Output sizes: the cost's pixel terms need two or more, far apart.
    pub sizes: Vec<(u32, u32)>,
    /// Map resolutions: the cost's texel term needs two; errors are measured at the last.
    pub maps: Vec<u32>,
    /// Samples of the truth the errors are measured against, with a seed other than the
    /// candidates' (whose strata it would otherwise share).
    pub truth_samples: u32,
    pub truth_seed: u32,
}

impl Suite {
    /// One occluder over a floor, many, a view of a few of many on a wide floor (whose sample
    /// maps are cropped to a fifth: the maps' cost apart from the triangles'), and a
    /// self-shadowing landscape; white, stripes of three colours, and a flame of 26 cells with
    /// dark gaps; 160×120 and 640×480; maps of 512² and 1,024²; a 1,024-sample truth. About
    /// three minutes on two cores with lavapipe.
    pub fn standard() -> Self {
        Self {
            scenes: vec![("torus", "{}"), ("crowd", "{}"), ("columns", "{}"), ("terrain", r#"{"triangles": 30000}"#)],
            lights: vec!["white", "stripes", "flame"],
            sizes: vec![(160, 120), (640, 480)],
            maps: vec![512, 1024],
            truth_samples: 1024,
            truth_seed: 7,
        }
    }

    /// A suite of a tenth of the time (about 15 s on two cores): two scenes, white and
    /// `flame`, 96×64 and 320×240, maps of 256² and 512², a 256-sample truth. Its errors are
    /// those of small frames and its truth is noisier: for a fleet that must be choosing
    /// quickly, and for tests of the daemon's measurement.
    pub fn quick() -> Self {
        Self {
            scenes: vec![("torus", "{}"), ("crowd", "{}")],
            lights: vec!["white", "flame"],
            sizes: vec![(96, 64), (320, 240)],
            maps: vec![256, 512],
            truth_samples: 256,
            truth_seed: 7,
        }
    }

    /// The truth a job's error is measured against: the reference with the suite's samples and
    /// seed, and maps of the job's resolution (also what an `auto` job that asks to `compare`
    /// is measured against).
    pub fn truth_of(&self, job: &Job) -> Job {
        let mut truth = job.reference_with(self.truth_samples, job.shadow_map.resolution);
        truth.method.params.insert("seed".into(), self.truth_seed.into());
        truth
    }
}

/// What the measurement needs from its caller: a way to wait for the device between renders
/// (the daemon's job slots, so that jobs are never slowed by it), progress, and whether to stop.
pub trait Hooks {
    /// Called before each render; returns a guard held while it runs.
    fn device(&self) -> Box<dyn std::any::Any>;
    fn progress(&self, done: usize, total: usize, what: &str);
    fn cancelled(&self) -> bool;
}

/// No waiting, no progress: `eval --model` and tests.
pub struct Plain;

impl Hooks for Plain {
    fn device(&self) -> Box<dyn std::any::Any> {
        Box::new(())
    }
    fn progress(&self, _: usize, _: usize, _: &str) {}
    fn cancelled(&self) -> bool {
        false
    }
}

/// Measures every candidate on the suite; `None` if stopped.
pub fn measure(engine: &Engine, suite: &Suite, key: ModelKey, hooks: &dyn Hooks) -> JobResult<Option<Model>> {
    let started = Instant::now();
    let candidates: Vec<(String, MethodSpec)> = CANDIDATES.iter().map(|label| ((*label).to_owned(), candidate(label))).collect();
    let cases = cases(suite);
    let total = cases.len() * candidates.len() + cases.iter().filter(|c| c.errors_here).count();
    let mut done = 0;
    let mut times: Vec<Vec<TimePoint>> = candidates.iter().map(|_| Vec::new()).collect();
    let mut errors: Vec<Vec<ErrorPoint>> = candidates.iter().map(|_| Vec::new()).collect();
    // Every pipeline compiled before any render is timed (a light of several colours compiles
    // its own).
    let first_of_each_light = suite.lights.iter().filter_map(|light| cases.iter().find(|c| c.features.light == *light));
    for case in first_of_each_light {
        for (_, method) in &candidates {
            let _device = hooks.device();
            engine.render_frame(&case.job_with(method), &())?;
        }
    }
    for case in &cases {
        let truth = if case.errors_here {
            let truth = suite.truth_of(&case.job);
            let _device = hooks.device();
            let (frame, _) = engine.render_frame(&truth, &())?;
            done += 1;
            Some(frame)
        } else {
            None
        };
        for (c, (label, method)) in candidates.iter().enumerate() {
            if hooks.cancelled() {
                return Ok(None);
            }
            hooks.progress(done, total, label);
            let job = case.job_with(method);
            let (frame, ms) = {
                let _device = hooks.device();
                timed_render(engine, &job)?
            };
            let f = &case.features;
            let (pixels, texels, triangles, map_share) = (f.pixels, f.texels, f.triangles, f.map_share);
            let light = f.light.clone();
            times[c].push(TimePoint { scene: case.scene.to_owned(), light, pixels, texels, triangles, map_share, ms });
            if let Some(truth) = &truth {
                let quality = crate::quality::compare(&frame, truth, 0.0);
                errors[c].push(ErrorPoint {
                    scene: case.scene.to_owned(),
                    light: case.features.light.clone(),
                    pixels: case.features.pixels,
                    error: quality.visibility.penumbra.mae,
                });
            }
            done += 1;
        }
    }
    let mut fitted: Vec<Candidate> = candidates
        .into_iter()
        .zip(times.into_iter().zip(errors))
        .map(|((label, method), (times, errors))| Candidate {
            label,
            cost: fit_costs(&times, suite.lights.iter().copied(), &method),
            method,
            errors,
            errors_measured: true,
            times,
        })
        .collect();
    if let Some(extrapolated) = reference_1024(&fitted) {
        fitted.push(extrapolated);
    }
    Ok(Some(Model {
        key,
        source: "measured".into(),
        measured_unix_ms: crate::job::submission::unix_ms(),
        measure_seconds: started.elapsed().as_secs_f64(),
        candidates: fitted,
    }))
}

/// A render as a client's costs: the frame and its PNG, wall time in milliseconds.
pub fn timed_render(engine: &Engine, job: &Job) -> JobResult<(FrameOutput, f64)> {
    let started = Instant::now();
    let (frame, _) = engine.render_frame(job, &())?;
    crate::output::encode(&frame, OutputFormat::Png, 0.0)?;
    Ok((frame, started.elapsed().as_secs_f64() * 1e3))
}

/// A candidate's method from its label.
fn candidate(label: &str) -> MethodSpec {
    MethodSpec::parse(label).expect("the candidates' labels parse")
}

/// One case of the suite.
struct Case {
    scene: &'static str,
    job: Job,
    features: Features,
    /// Errors are measured at the suite's last map only (the truth costs most of the suite).
    errors_here: bool,
}

impl Case {
    fn job_with(&self, method: &MethodSpec) -> Job {
        let method = crate::methods::with_map_resolution(method, self.job.shadow_map.resolution);
        // `compare` reads the visibility back for the error (a little more than a PNG job reads).
        Job { method, compare: true, ..self.job.clone() }
    }
}

fn cases(suite: &Suite) -> Vec<Case> {
    let mut cases = Vec::new();
    for &(scene, params) in &suite.scenes {
        let params: Map<String, serde_json::Value> = serde_json::from_str(params).expect("the suite's scene parameters parse");
        let built =
            crate::scene::builtin::build(scene, &params, "scene", &crate::job::Limits::default()).expect("the suite's scenes build");
        for &light in &suite.lights {
            for &(width, height) in &suite.sizes {
                for &resolution in &suite.maps {
                    let job = Job {
                        scene: AssetRef::Builtin { name: scene.into(), params: params.clone() }.into(),
                        light: LightSpec { image: Some(AssetRef::builtin(light)), ..Default::default() },
                        shadow_map: ShadowMapSpec { resolution },
                        output: OutputSpec { width, height, format: OutputFormat::Png, exposure: 0.0 },
                        ..Job::embedded_default()
                    };
                    // As the daemon predicts a job: from the scene's shape (`Engine::scene_shape`).
                    let features = Features::of(&job, Some(&built.shape(job.scene.floor.as_ref())));
                    cases.push(Case { scene, job, features, errors_here: Some(&resolution) == suite.maps.last() });
                }
            }
        }
    }
    cases
}

/// A candidate's cost under each of `lights`, fitted to its `times` under that light.
fn fit_costs<'a>(times: &[TimePoint], lights: impl Iterator<Item = &'a str>, method: &MethodSpec) -> Costs {
    lights.map(|light| (light.to_owned(), fit(times.iter().filter(|t| t.light == light), super::crops(method)))).collect()
}

/// `model` as this build fits it: each measured candidate's costs fitted again to its times
/// (under the lights it has costs for) and the 1,024-sample reference extrapolated again. The
/// shipped model, measured by an earlier build, is kept so (a test).
#[cfg(test)]
pub(super) fn refit(model: &mut Model) {
    for candidate in model.candidates.iter_mut().filter(|c| !c.times.is_empty()) {
        let lights: Vec<String> = candidate.cost.keys().cloned().collect();
        candidate.cost = fit_costs(&candidate.times, lights.iter().map(String::as_str), &candidate.method);
    }
    if let Some(extrapolated) = reference_1024(&model.candidates) {
        match model.candidates.iter_mut().find(|c| c.label == extrapolated.label) {
            Some(old) => *old = extrapolated,
            None => model.candidates.push(extrapolated),
        }
    }
}

/// The reference at 1,024 samples, from its fits at 64 and 256: each cost term grows linearly
/// with the samples (a map and a test each), the errors fall as 1/√samples.
fn reference_1024(candidates: &[Candidate]) -> Option<Candidate> {
    let find = |label: &str| candidates.iter().find(|c| c.label == label);
    let (at_64, at_256) = (find("reference:samples=64")?, find("reference:samples=256")?);
    let extrapolate = |c64: &Cost, c256: &Cost| {
        let (c64, c256) = (c64.as_array(), c256.as_array());
        Cost::from_array(std::array::from_fn(|i| (c256[i] + (c256[i] - c64[i]) * (1024.0 - 256.0) / (256.0 - 64.0)).max(c256[i])))
    };
    let cost: Costs =
        at_256.cost.iter().filter_map(|(light, c256)| Some((light.clone(), extrapolate(at_64.cost.get(light)?, c256)))).collect();
    let errors = at_256.errors.iter().map(|p| ErrorPoint { error: p.error * 0.5, ..p.clone() }).collect();
    Some(Candidate {
        label: "reference:samples=1024".into(),
        method: candidate("reference:samples=1024"),
        cost,
        errors,
        errors_measured: false,
        times: Vec::new(),
    })
}

/// The non-negative least-squares fit of the times on the features (`cropped`: the texels a
/// cropping method draws, `Features::vector`), each residual relative to its time (a 20 ms
/// case counts as much as a 2 s one): every subset of the terms is solved by its normal
/// equations and the best fit with no negative coefficient kept (2⁵ − 1 subsets; one with a
/// term no time has, as the whole maps' texels of a method that does not crop, is singular
/// and skipped).
pub(super) fn fit<'a>(times: impl Iterator<Item = &'a TimePoint>, cropped: bool) -> Cost {
    let rows: Vec<([f64; FEATURES], f64)> =
        times.filter(|t| t.ms > 0.0).map(|t| (t.features().vector(cropped).map(|v| v / t.ms), 1.0)).collect();
    let mut best: Option<(f64, [f64; FEATURES])> = None;
    for subset in 1u32..(1 << FEATURES) {
        let terms: Vec<usize> = (0..FEATURES).filter(|i| subset & (1 << i) != 0).collect();
        let Some(solved) = least_squares(&rows, &terms) else { continue };
        if solved.iter().any(|c| *c < 0.0) {
            continue;
        }
        let mut coefficients = [0.0; FEATURES];
        for (&term, &c) in terms.iter().zip(&solved) {
            coefficients[term] = c;
        }
        let residual: f64 = rows.iter().map(|(x, b)| (x.iter().zip(&coefficients).map(|(x, c)| x * c).sum::<f64>() - b).powi(2)).sum();
        if best.is_none_or(|(r, _)| residual < r) {
            best = Some((residual, coefficients));
        }
    }
    Cost::from_array(best.map_or([0.0; FEATURES], |(_, c)| c))
}

/// Least squares over `terms` of `rows` by the normal equations; `None` when they are singular.
fn least_squares(rows: &[([f64; FEATURES], f64)], terms: &[usize]) -> Option<Vec<f64>> {
    let n = terms.len();
    let mut a = vec![vec![0.0; n + 1]; n];
    for (x, b) in rows {
        for (i, &ti) in terms.iter().enumerate() {
            for (j, &tj) in terms.iter().enumerate() {
                a[i][j] += x[ti] * x[tj];
            }
            a[i][n] += x[ti] * b;
        }
    }
    // Gaussian elimination with partial pivoting.
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        let pivot_row = a[col].clone();
        for (r, row) in a.iter_mut().enumerate() {
            if r != col {
                let factor = row[col] / pivot_row[col];
                for (x, p) in row[col..].iter_mut().zip(&pivot_row[col..]) {
                    *x -= factor * p;
                }
            }
        }
    }
    Some((0..n).map(|i| a[i][n] / a[i][i]).collect())
}
