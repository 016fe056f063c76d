//! The cost and quality model of this device (contract §5): what each candidate method costs
//! here as a function of a job's size, and how far its penumbra lies from the truth by kind of
//! scene and light — measured by `measure.rs` on a small built-in suite, kept in the data
//! directory per adapter and build, and read to predict a job before it renders
//! (`POST /v1/estimate`) and to choose for `auto` under a time or an error budget.

pub mod measure;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::job::auto::{AutoBudget, AutoChoice, Prediction};
use crate::job::{AssetRef, Job, MethodSpec};

/// The shipped model: measured on lavapipe (2 cores) by `penumbra eval --model --out DIR`,
/// what an `auto` job is chosen by until this device's own is measured. Its costs are fitted
/// to its times by this build's fit (`measure::refit`; a test keeps them so).
const SHIPPED: &str = include_str!("default.json");

/// The model's label of the reference candidate a progressive job's first round is predicted
/// by.
const FIRST_ROUND_CANDIDATE: &str = "reference:samples=16";

/// What a choice's predictions must fit inside: a prediction × this ≤ the budget. The time
/// and error of a job vary about the model's fit (noisy machines, scenes unlike the suite's),
/// and a budget asked for is a promise: choosing on the bare prediction would miss about
/// half of the budgets that sit near it.
pub const MARGIN: f64 = 1.25;

/// The model of one device: every candidate's cost fit and measured errors.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Model {
    pub key: ModelKey,
    /// `measured` on this device, or `default` (shipped, measured elsewhere).
    pub source: String,
    pub measured_unix_ms: u64,
    /// Wall time the measurement took.
    pub measure_seconds: f64,
    pub candidates: Vec<Candidate>,
}

/// Which device and build a model was measured on: another adapter or another build of
/// penumbra measures again.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Eq)]
pub struct ModelKey {
    pub adapter: String,
    pub driver: String,
    /// The crate version and a digest of the running executable.
    pub build: String,
}

/// One method with its parameters, as `auto` may choose it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Candidate {
    /// `name[:key=value…]`, as `eval` writes methods.
    pub label: String,
    pub method: MethodSpec,
    /// Milliseconds of a whole render (frame and PNG encoding): `cost · features`, per kind
    /// of light.
    pub cost: Costs,
    /// Mean |V − Vref| over the penumbra, per suite case.
    pub errors: Vec<ErrorPoint>,
    /// Whether the errors were measured (false: extrapolated from the reference's other
    /// sample counts, as 1/√samples).
    #[serde(default = "yes")]
    pub errors_measured: bool,
    /// The times the cost was fitted to (none where extrapolated).
    #[serde(default)]
    pub times: Vec<TimePoint>,
}

/// One measured render time and the job's features.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TimePoint {
    pub scene: String,
    pub light: String,
    pub pixels: u64,
    pub texels: u64,
    pub triangles: u64,
    /// `Features::map_share` of the case (1 in models measured before it was).
    #[serde(default = "one")]
    pub map_share: f64,
    pub ms: f64,
}

impl TimePoint {
    pub fn features(&self) -> Features {
        Features {
            pixels: self.pixels,
            texels: self.texels,
            map_share: self.map_share,
            triangles: self.triangles,
            triangles_known: true,
            light: self.light.clone(),
            scene: Some(self.scene.clone()),
            pace: 1.0,
        }
    }
}

fn yes() -> bool {
    true
}

fn one() -> f64 {
    1.0
}

/// A linear cost: milliseconds per unit of each feature of a job, all ≥ 0 (fitted by
/// non-negative least squares on relative errors, `measure::fit`).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Default)]
pub struct Cost {
    pub base_ms: f64,
    /// Per million output pixels.
    pub per_mpixel: f64,
    /// Per million scene triangles.
    pub per_mtriangle: f64,
    /// Per million shadow-map texels (those drawn, for a method that crops its maps).
    pub per_mtexel: f64,
    /// Per million texels of the whole maps, for a method that crops its maps: what a map
    /// costs that its crop does not cut. On `columns`, whose maps are cropped to a fifth, the
    /// drawn texels alone under-predicted the references' time by up to 1.5× (measured:
    /// docs/performance-log.md). 0 for the methods that draw whole maps, and in models
    /// measured before it was.
    #[serde(default)]
    pub per_mtexel_whole: f64,
}

impl Cost {
    pub fn as_array(&self) -> [f64; FEATURES] {
        [self.base_ms, self.per_mpixel, self.per_mtriangle, self.per_mtexel, self.per_mtexel_whole]
    }

    pub fn from_array(c: [f64; FEATURES]) -> Self {
        Self { base_ms: c[0], per_mpixel: c[1], per_mtriangle: c[2], per_mtexel: c[3], per_mtexel_whole: c[4] }
    }

    /// Milliseconds for a job of these terms (`Candidate::terms`).
    pub fn ms(&self, terms: [f64; FEATURES]) -> f64 {
        self.as_array().iter().zip(terms).map(|(c, x)| c * x).sum()
    }
}

/// A cost per light the suite measured, fitted apart: a coloured light costs E0 and the
/// colour-aware methods more per pixel, and the sampling methods less where it has dark gaps
/// (a sample on a black texel is skipped) — effects a shared term could not tell apart.
pub type Costs = std::collections::BTreeMap<String, Cost>;

/// How many terms a cost has.
pub const FEATURES: usize = 5;

/// One measured error: a scene kind (a built-in scene's name), a light (a built-in image's
/// name) and a size.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ErrorPoint {
    pub scene: String,
    pub light: String,
    pub pixels: u64,
    pub error: f64,
}

/// The light of a job as the model knows lights: `white`, a built-in image's name, or
/// `image` for a user's (predicted as the worst coloured light measured).
pub const USER_IMAGE: &str = "image";

/// What a job's cost and error follow, read from the job (and the scene's triangles where the
/// engine knows them).
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    pub pixels: u64,
    /// A shadow map's texels (the job's resolution²).
    pub texels: u64,
    /// The share of each sample map a reference or `filtered` frame draws: the crop of what
    /// the camera sees (`reference::predicted_map_share`; 1 where the scene's shape is not
    /// known before rendering). A view of a small part of a large scene crops its maps to a
    /// fifth, and the maps' cost with them.
    pub map_share: f64,
    pub triangles: u64,
    /// Whether `triangles` was counted (false: a guess, the suite's largest scene).
    pub triangles_known: bool,
    /// `white`, a built-in image's name, or `image` (`USER_IMAGE`).
    pub light: String,
    /// How fast this device has lately run against its model (`Pace::factor`): every time
    /// predicted is multiplied by it. 1 for the model's own fit.
    pub pace: f64,
    /// The built-in scene's name; `None` for a user's scene (its error is predicted as the
    /// worst built-in kind's).
    pub scene: Option<String>,
}

/// Whether `method` draws its sample maps cropped to the view: the reference and `filtered`
/// (`reference`'s maps), unless its `crop` is false.
pub fn crops(method: &MethodSpec) -> bool {
    matches!(method.name.as_str(), "reference" | "filtered") && method.params.get("crop").and_then(Value::as_bool) != Some(false)
}

/// Triangles assumed for a scene the engine has not counted.
pub const UNKNOWN_TRIANGLES: u64 = 100_000;

impl Features {
    /// A job's features; `shape`: its scene's, where known (`Engine::scene_shape`).
    pub fn of(job: &Job, shape: Option<&crate::scene::Shape>) -> Self {
        let light = match &job.light.image {
            None => "white".to_owned(),
            Some(AssetRef::Builtin { name, .. }) => name.clone(),
            Some(_) => USER_IMAGE.to_owned(),
        };
        let scene = match &job.scene.asset {
            AssetRef::Builtin { name, .. } => Some(name.clone()),
            _ => None,
        };
        let resolution = job.shadow_map.resolution;
        // A camera or light the job cannot resolve fails at render time with its field named;
        // predicted, it draws whole maps.
        let map_share = shape
            .and_then(|shape| {
                let (camera, light, _) = crate::render::resolve_view(job, &shape.defaults, &shape.extent.corners()).ok()?;
                let aspect = job.output.width as f32 / job.output.height.max(1) as f32;
                Some(crate::methods::reference::predicted_map_share(camera.view_proj(aspect), &light, &shape.extent, resolution))
            })
            .unwrap_or(1.0);
        Self {
            pixels: u64::from(job.output.width) * u64::from(job.output.height),
            texels: u64::from(resolution).pow(2),
            map_share,
            triangles: shape.map_or(UNKNOWN_TRIANGLES, |s| s.triangles),
            triangles_known: shape.is_some(),
            light,
            scene,
            pace: 1.0,
        }
    }

    /// The cost's terms, in its units (millions); `cropped`: whether the method draws only
    /// `map_share` of each map (its whole maps' texels are a term of their own; 0 for a method
    /// that draws them whole, whose texels are all drawn).
    pub fn vector(&self, cropped: bool) -> [f64; FEATURES] {
        let texels = self.texels as f64 / 1e6;
        let (drawn, whole) = if cropped { (texels * self.map_share, texels) } else { (texels, 0.0) };
        [1.0, self.pixels as f64 / 1e6, self.triangles as f64 / 1e6, drawn, whole]
    }
}

impl Candidate {
    /// The method this candidate renders in place of `job`'s: its own sample maps (if it draws
    /// any) at the job's shadow-map resolution, as the model measured it.
    pub fn method_for(&self, job: &Job) -> MethodSpec {
        crate::methods::with_map_resolution(&self.method, job.shadow_map.resolution)
    }

    /// Whether this candidate draws its sample maps cropped to the view (`Features::map_share`):
    /// the reference and `filtered`, unless told not to.
    pub fn cropped(&self) -> bool {
        crops(&self.method)
    }

    /// A job's cost terms for this candidate.
    pub fn terms(&self, features: &Features) -> [f64; FEATURES] {
        features.vector(self.cropped())
    }

    /// The predicted error: the measured errors of the job's scene kind and light kind (every
    /// kind's worst for a user's scene), interpolated over the output's pixels in log scale,
    /// held at the ends.
    pub fn error(&self, features: &Features) -> f64 {
        // A light the suite did not measure: every coloured light's points; a scene it did not
        // measure: every scene's. The worst of them is kept.
        let light_measured = self.errors.iter().any(|p| p.light == features.light);
        let scene = features.scene.as_ref().filter(|s| self.errors.iter().any(|p| &p.scene == *s));
        let chosen = self.errors.iter().filter(|p| {
            let light = if light_measured { p.light == features.light } else { p.light != "white" };
            light && scene.is_none_or(|s| &p.scene == s)
        });
        let mut by_size: Vec<(u64, f64)> = Vec::new();
        for point in chosen {
            match by_size.iter_mut().find(|(pixels, _)| *pixels == point.pixels) {
                Some((_, error)) => *error = error.max(point.error),
                None => by_size.push((point.pixels, point.error)),
            }
        }
        by_size.sort_by_key(|(pixels, _)| *pixels);
        interpolate_log(&by_size, features.pixels)
    }

    /// The fitted cost's relative error over the times it was fitted to: the median and the
    /// largest |predicted − measured| / measured (`None` where nothing was measured).
    pub fn fit_error(&self) -> Option<(f64, f64)> {
        let mut relative: Vec<f64> = self.times.iter().map(|t| (self.ms(&t.features()) - t.ms).abs() / t.ms).collect();
        relative.sort_by(f64::total_cmp);
        Some((*relative.get(relative.len() / 2)?, *relative.last()?))
    }

    /// The predicted time: the cost fitted under the job's light, or for a light the suite did
    /// not measure the costliest of the coloured lights' at these features.
    pub fn ms(&self, features: &Features) -> f64 {
        let terms = self.terms(features);
        let fitted = match self.cost.get(&features.light) {
            Some(cost) => cost.ms(terms),
            None => self.cost.iter().filter(|(light, _)| *light != "white").map(|(_, c)| c.ms(terms)).fold(0.0, f64::max),
        };
        fitted * features.pace
    }

    pub fn predict(&self, features: &Features) -> Prediction {
        Prediction { ms: self.ms(features), error: self.error(features) }
    }
}

/// `points` (pixels ascending) at `pixels`, linear in log(pixels), held beyond the ends.
fn interpolate_log(points: &[(u64, f64)], pixels: u64) -> f64 {
    let Some(&(first_px, first)) = points.first() else { return 1.0 };
    let &(last_px, last) = points.last().expect("not empty");
    if pixels <= first_px {
        return first;
    }
    if pixels >= last_px {
        return last;
    }
    let x = (pixels as f64).ln();
    for pair in points.windows(2) {
        let ((p0, e0), (p1, e1)) = (pair[0], pair[1]);
        if pixels <= p1 {
            let t = (x - (p0 as f64).ln()) / ((p1 as f64).ln() - (p0 as f64).ln());
            return e0 + t * (e1 - e0);
        }
    }
    last
}

/// Renders whose times a `Pace` follows: the last this many.
pub const PACE_WINDOW: usize = 8;

/// Renders a `Pace` waits for before it moves off 1.
const PACE_FIRST: usize = 4;

/// What the pace may scale predictions by, at most, either way. Machines of one kind differ by
/// more than 2×: a fresh two-core machine ran 2.5× faster than the one the shipped model was
/// measured on (docs/performance-log.md), and a limit of 2 left its predictions 1.25× too slow.
/// Four times off, the model is not this device's: one to measure again, not to follow.
const PACE_LIMIT: f64 = 4.0;

/// How fast this device runs against its model lately (contract §5): the median of the last
/// `PACE_WINDOW` renders' measured ÷ predicted times, by which every time prediction is
/// multiplied (`Features::pace`). The model is measured once, and the device's speed drifts:
/// on a shared two-core machine by ±40 % from minute to minute and up to 2.5× from one machine
/// of the kind to another (docs/performance-log.md); on any machine with its clocks, its
/// neighbours and its load. A short window follows minutes; the median lets a few renders
/// unlike the rest (a scene the fit misses) not move it. Kept per model: a new model starts at 1.
#[derive(Debug, Default)]
pub struct Pace {
    ratios: std::sync::Mutex<std::collections::VecDeque<f64>>,
}

impl Pace {
    /// A render predicted at `predicted_ms` (by the model alone: pace 1) took `measured_ms`.
    pub fn observe(&self, predicted_ms: f64, measured_ms: f64) {
        let ratio = measured_ms / predicted_ms;
        if !(ratio.is_finite() && ratio > 0.0) {
            return;
        }
        let mut ratios = self.ratios.lock().unwrap_or_else(|p| p.into_inner());
        if ratios.len() == PACE_WINDOW {
            ratios.pop_front();
        }
        ratios.push_back(ratio);
    }

    /// The median ratio of the window, within [1/`PACE_LIMIT`, `PACE_LIMIT`]; 1 until
    /// `PACE_FIRST` renders were seen.
    pub fn factor(&self) -> f64 {
        let ratios = self.ratios.lock().unwrap_or_else(|p| p.into_inner());
        if ratios.len() < PACE_FIRST {
            return 1.0;
        }
        let mut sorted: Vec<f64> = ratios.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let median = if n % 2 == 1 { sorted[n / 2] } else { 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]) };
        median.clamp(1.0 / PACE_LIMIT, PACE_LIMIT)
    }

    /// Forgets every render seen: back to 1.
    pub fn reset(&self) {
        self.ratios.lock().unwrap_or_else(|p| p.into_inner()).clear();
    }

    /// Renders seen, up to the window.
    pub fn observed(&self) -> usize {
        self.ratios.lock().unwrap_or_else(|p| p.into_inner()).len()
    }
}

/// Why no candidate fits an `auto` budget: the field that cannot be met and the closest
/// candidate with its prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct Unmet {
    pub field: &'static str,
    pub closest: String,
    pub prediction: Prediction,
    pub message: String,
}

impl Model {
    /// The model shipped with penumbra.
    pub fn shipped() -> Self {
        let mut model: Model = serde_json::from_str(SHIPPED).expect("the shipped model parses (tested)");
        model.source = "default".into();
        model
    }

    /// The first reference round's predicted time (`reference:samples=16`), where the model
    /// has it.
    pub fn first_round_ms(&self, features: &Features) -> Option<f64> {
        self.candidates.iter().find(|c| c.label == FIRST_ROUND_CANDIDATE).map(|c| c.ms(features))
    }

    /// A progressive job's first image (contract §5): among the candidates other than the
    /// reference that `allowed` keeps, the most faithful predicted to take a tenth of `max_ms`
    /// (without `max_ms`: the first reference round's predicted time), else the cheapest.
    /// `None` where the model has no such candidate.
    pub fn first_image(
        &self,
        max_ms: Option<f64>,
        features: &Features,
        allowed: impl Fn(&Candidate) -> bool,
    ) -> Option<(Candidate, Prediction)> {
        let budget = AutoBudget { max_ms: max_ms.map(|ms| ms / 10.0).or(self.first_round_ms(features)), max_error: None };
        let fast = |c: &Candidate| c.method.name != "reference" && allowed(c);
        if let Ok(chosen) = self.choose_among(&budget, features, fast) {
            return Some(chosen);
        }
        let cheapest = self.predictions(features).into_iter().filter(|(c, _)| fast(c)).min_by(|a, b| a.1.ms.total_cmp(&b.1.ms));
        cheapest.map(|(c, p)| (c.clone(), p))
    }

    /// Every candidate's prediction for a job with these features, in the model's order.
    pub fn predictions(&self, features: &Features) -> Vec<(&Candidate, Prediction)> {
        self.candidates.iter().map(|c| (c, c.predict(features))).collect()
    }

    /// The choice for an `auto` budget: under `max_ms` alone, the candidate of least predicted
    /// error whose time fits; under `max_error` (alone or with `max_ms`), the cheapest whose
    /// error (and time) fit — each prediction with the `MARGIN`.
    pub fn choose(&self, budget: &AutoBudget, features: &Features) -> Result<(Candidate, Prediction), Unmet> {
        self.choose_among(budget, features, |_| true)
    }

    /// `choose` among the candidates `allowed` keeps (those this server's limits let a job
    /// ask for: a candidate above an operator's cap is never chosen).
    pub fn choose_among(
        &self,
        budget: &AutoBudget,
        features: &Features,
        allowed: impl Fn(&Candidate) -> bool,
    ) -> Result<(Candidate, Prediction), Unmet> {
        let predictions: Vec<(&Candidate, Prediction)> = self.predictions(features).into_iter().filter(|(c, _)| allowed(c)).collect();
        let time_fits = |p: &Prediction| budget.max_ms.is_none_or(|max| p.ms * MARGIN <= max);
        let error_fits = |p: &Prediction| budget.max_error.is_none_or(|max| p.error * MARGIN <= max);
        let fitting = predictions.iter().filter(|(_, p)| time_fits(p) && error_fits(p));
        let best = if budget.max_error.is_some() {
            fitting.min_by(|a, b| a.1.ms.total_cmp(&b.1.ms))
        } else {
            fitting.min_by(|a, b| a.1.error.total_cmp(&b.1.error).then(a.1.ms.total_cmp(&b.1.ms)))
        };
        if let Some((candidate, prediction)) = best {
            return Ok(((*candidate).clone(), *prediction));
        }
        // Nothing fits: the field that cannot be met, and the candidate nearest to it.
        let Some(cheapest) = predictions.iter().min_by(|a, b| a.1.ms.total_cmp(&b.1.ms)) else {
            let prediction = Prediction { ms: 0.0, error: 1.0 };
            let message = "this daemon's model has no method this server's limits allow".into();
            return Err(Unmet { field: "method.name", closest: String::new(), prediction, message });
        };
        let (field, (candidate, prediction)) = match (budget.max_ms, budget.max_error) {
            (Some(max), _) if cheapest.1.ms * MARGIN > max => ("method.max_ms", cheapest),
            (_, Some(_)) => {
                // The most faithful within the time asked for (or at all).
                let within = predictions.iter().filter(|(_, p)| time_fits(p));
                ("method.max_error", within.min_by(|a, b| a.1.error.total_cmp(&b.1.error)).unwrap_or(cheapest))
            }
            _ => ("method.max_ms", cheapest),
        };
        let message = format!(
            "no method is predicted to meet it on this device (with a {:.0} % margin); the closest is {} at {:.0} ms and a penumbra error of {:.4}",
            (MARGIN - 1.0) * 100.0,
            candidate.label,
            prediction.ms,
            prediction.error
        );
        Err(Unmet { field, closest: candidate.label.clone(), prediction: *prediction, message })
    }

    /// The `AutoChoice` a job records for `candidate`.
    pub fn choice(&self, candidate: &Candidate, prediction: Prediction, job: &Job) -> AutoChoice {
        AutoChoice {
            method: candidate.method_for(job),
            label: candidate.label.clone(),
            predicted: prediction,
            model: self.source.clone(),
            measured_ms: None,
        }
    }

    /// The model as `GET /v1/methods` and `eval --model` show it: each candidate's cost terms
    /// and its errors by scene and light.
    pub fn summary(&self) -> Value {
        let candidates: Vec<Value> = self
            .candidates
            .iter()
            .map(|c| {
                let mut errors = Map::new();
                for p in &c.errors {
                    errors.insert(format!("{}/{}/{}", p.scene, p.light, p.pixels), p.error.into());
                }
                serde_json::json!({"label": c.label, "method": c.method, "cost": c.cost, "errors": errors, "errors_measured": c.errors_measured})
            })
            .collect();
        serde_json::json!({
            "source": self.source,
            "adapter": self.key.adapter,
            "driver": self.key.driver,
            "build": self.key.build,
            "measured_unix_ms": self.measured_unix_ms,
            "measure_seconds": self.measure_seconds,
            "margin": MARGIN,
            "candidates": candidates,
        })
    }

    /// A Markdown table of the model: each candidate's predicted time at three sizes under
    /// white light and at 1080p under each coloured light, how well its cost fits what was
    /// measured, and its error per scene kind and light at the suite's largest size.
    pub fn table(&self) -> String {
        let points = || self.candidates.iter().flat_map(|c| c.errors.iter());
        let mut scenes: Vec<&str> = points().map(|p| p.scene.as_str()).collect();
        let mut lights: Vec<&str> = points().map(|p| p.light.as_str()).collect();
        for list in [&mut scenes, &mut lights] {
            list.sort_unstable();
            list.dedup();
        }
        let coloured: Vec<&str> = lights.iter().copied().filter(|l| *l != "white").collect();
        let sizes = [(256u32, 192u32), (640, 480), (1920, 1080)];
        let mut out =
            format!("Model of {} ({}), build {}, {}.\n\n| candidate |", self.key.adapter, self.key.driver, self.key.build, self.source);
        for (w, h) in sizes {
            out.push_str(&format!(" ms {w}×{h} |"));
        }
        for light in &coloured {
            out.push_str(&format!(" ms 1920×1080 {light} |"));
        }
        out.push_str(" fit, median | fit, worst |");
        for scene in &scenes {
            for light in &lights {
                out.push_str(&format!(" {scene} {light} |"));
            }
        }
        out.push_str("\n|---|");
        out.push_str(&"---:|".repeat(sizes.len() + coloured.len() + 2 + scenes.len() * lights.len()));
        out.push('\n');
        let largest = points().map(|p| p.pixels).max().unwrap_or(0);
        let at = |pixels: u64, light: &str, scene: Option<&str>| Features {
            pixels,
            texels: 2048 * 2048,
            map_share: 1.0,
            triangles: 10_000,
            triangles_known: true,
            light: light.to_owned(),
            scene: scene.map(str::to_owned),
            pace: 1.0,
        };
        for c in &self.candidates {
            out.push_str(&format!("| {} |", c.label));
            for (w, h) in sizes {
                out.push_str(&format!(" {:.0} |", c.ms(&at(u64::from(w) * u64::from(h), "white", None))));
            }
            for light in &coloured {
                out.push_str(&format!(" {:.0} |", c.ms(&at(1920 * 1080, light, None))));
            }
            match c.fit_error() {
                Some((median, worst)) => out.push_str(&format!(" {:.0} % | {:.0} % |", median * 100.0, worst * 100.0)),
                None => out.push_str(" - | - |"),
            }
            for scene in &scenes {
                for light in &lights {
                    out.push_str(&format!(
                        " {:.4}{} |",
                        c.error(&at(largest, light, Some(scene))),
                        if c.errors_measured { "" } else { "*" }
                    ));
                }
            }
            out.push('\n');
        }
        out.push_str(
            "\nTimes with 10,000 triangles and a 2,048² map; the fit's relative error over the suite's times; errors (mean |V − Vref| over the penumbra) at the suite's largest size; * extrapolated, not measured.\n",
        );
        out
    }
}

/// Where a device's model is kept under the data directory: one file per adapter and build.
pub fn stored_path(data_dir: &std::path::Path, key: &ModelKey) -> std::path::PathBuf {
    let digest = crate::upload_store::content_id(format!("{}|{}|{}", key.adapter, key.driver, key.build).as_bytes());
    data_dir.join("models").join(format!("{}.json", &digest[..16]))
}

/// The model stored for `key`, if one is and it parses and names that key.
pub fn load(data_dir: &std::path::Path, key: &ModelKey) -> Option<Model> {
    let bytes = std::fs::read(stored_path(data_dir, key)).ok()?;
    let model: Model = serde_json::from_slice(&bytes).ok()?;
    (model.key == *key && !model.candidates.is_empty()).then_some(model)
}

/// Keeps `model` for the next start (written whole, then renamed into place).
pub fn save(data_dir: &std::path::Path, model: &Model) -> std::io::Result<()> {
    let path = stored_path(data_dir, &model.key);
    std::fs::create_dir_all(path.parent().expect("under models/"))?;
    let partial = path.with_extension("json.partial");
    std::fs::write(&partial, serde_json::to_vec_pretty(model).map_err(std::io::Error::other)?)?;
    std::fs::rename(partial, path)
}

/// The key of this build on `adapter`: the crate's version and the first 12 hex digits of the
/// running executable's SHA-256, so that a rebuilt penumbra measures again.
pub fn key_for(adapter: &crate::gpu::AdapterSummary) -> ModelKey {
    // Streamed: the executable is ~140 MB with its line tables, not to be held at once.
    let digest = std::env::current_exe()
        .and_then(std::fs::File::open)
        .and_then(|mut file| {
            use sha2::Digest;
            use std::io::Read;
            let (mut hasher, mut buffer) = (sha2::Sha256::new(), vec![0u8; 1 << 20]);
            loop {
                match file.read(&mut buffer)? {
                    0 => break,
                    n => hasher.update(&buffer[..n]),
                }
            }
            Ok(hasher.finalize().iter().take(6).map(|b| format!("{b:02x}")).collect::<String>())
        })
        .unwrap_or_else(|_| "unknown".into());
    ModelKey { adapter: adapter.name.clone(), driver: adapter.driver.clone(), build: format!("{}+{digest}", env!("CARGO_PKG_VERSION")) }
}

#[cfg(test)]
mod tests;
