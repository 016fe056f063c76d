//! `penumbra eval --budgets` (contract §5): whether `auto` keeps its promises on this device.
//! The model is measured first (or read with `--model-file`); then every case of the suite
//! (its scenes, lights and sizes — built-in scenes the model's suite did not measure, and sizes
//! it did not render, included) is asked a range of time and error budgets, each choice is
//! rendered and timed as the daemon would, and measured against the model's own truth; and
//! the reference's rounds as a progressive job runs them, each round's error estimate against
//! its measured error (`budgets.md`, `budgets.json`, and `budgets.svg`: measured against
//! predicted and estimated).

use anyhow::Context;
use serde::Serialize;

use super::options::{parse_size, EvalOptions};
use super::{case_job, suite};
use crate::engine::Engine;
use crate::job::auto::AutoBudget;
use crate::job::OutputFormat;
use crate::model::measure::{self, Suite};
use crate::model::{Features, Model, MARGIN};

/// Time budgets, as multiples of the case's cheapest predicted time (with the margin): from
/// one only the cheapest fits to one most candidates fit.
const TIME_FACTORS: &[f64] = &[1.2, 2.0, 4.0, 8.0];
/// Error budgets, mean |V − Vref| over the penumbra.
const ERRORS: &[f64] = &[0.01, 0.02, 0.04, 0.08];
/// How close a prediction must come to count as right (the goal: ±25 %).
const WITHIN: f64 = 0.25;
/// How close a progressive round's error estimate must come (the goal: ±30 %).
const ESTIMATE_WITHIN: f64 = 0.30;
/// The samples a case's progressive rounds reach: a quarter of the truth's, so that the
/// truth's own noise adds little to the errors measured against it.
const ROUND_SAMPLES: u32 = 256;

/// One budget asked of one case, and what came of it.
#[derive(Debug, Clone, Serialize)]
pub struct BudgetRow {
    pub scene: String,
    pub light: String,
    pub size: String,
    /// `max_ms=…` or `max_error=…`.
    pub budget: String,
    /// The candidate chosen, or `refused (closest …)`.
    pub choice: String,
    /// At the device's pace: the model's time × `pace`.
    pub predicted_ms: f64,
    /// `model::Pace::factor` when the choice was made.
    pub pace: f64,
    /// The median of `--repeat` renders.
    pub measured_ms: Option<f64>,
    pub predicted_error: f64,
    pub measured_error: Option<f64>,
    /// Whether every render kept the budget (None: refused).
    pub kept: Option<bool>,
}

/// One round of a case's progressive job: its error estimate and its error measured against
/// the truth.
#[derive(Debug, Clone, Serialize)]
pub struct RoundRow {
    pub scene: String,
    pub light: String,
    pub size: String,
    pub samples: u32,
    pub estimated: f64,
    pub measured: f64,
}

/// The suite's answers, summed up against the goals.
#[derive(Debug, Clone, Serialize)]
pub struct BudgetReport {
    pub model: String,
    pub rows: Vec<BudgetRow>,
    /// Time budgets kept, of those rendered.
    pub time_kept: (usize, usize),
    pub error_kept: (usize, usize),
    /// Predictions within ±25 %, over every distinct (case, choice) rendered.
    pub time_predicted: (usize, usize),
    /// The same for the model alone (pace 1).
    pub time_predicted_unpaced: (usize, usize),
    pub error_predicted: (usize, usize),
    pub rounds: Vec<RoundRow>,
    /// Progressive rounds whose estimate is within ±30 % of their measured error.
    pub rounds_estimated: (usize, usize),
    pub first_images: Vec<FirstImageRow>,
    /// Progressive jobs' first images that came within a tenth of `max_ms`.
    pub first_images_kept: (usize, usize),
}

/// A progressive job's first image for one case and `max_ms`: the daemon's choice
/// (`Model::first_image`) and its time against a tenth of the budget.
#[derive(Debug, Clone, Serialize)]
pub struct FirstImageRow {
    pub scene: String,
    pub light: String,
    pub size: String,
    pub max_ms: f64,
    pub choice: String,
    pub predicted_ms: f64,
    /// The median of `--repeat` renders.
    pub measured_ms: f64,
    /// Whether every render came within `max_ms / 10`.
    pub kept: bool,
}

/// What measuring a case's choices shares: each candidate rendered once untimed per light
/// (`warm`), then timed `repeat` times, its error against the truth, kept per case so that a
/// candidate chosen twice is rendered once.
struct Measuring<'a> {
    engine: &'a Engine,
    job: &'a crate::job::Job,
    /// The job's features at pace 1, and the pace each new measurement is told.
    features: &'a Features,
    pace: &'a crate::model::Pace,
    reference: &'a crate::render::FrameOutput,
    case: &'a str,
    light: &'a str,
    repeat: u32,
    warm: &'a mut Vec<(String, String)>,
    measured: Vec<(String, f64, f64, f64)>,
}

/// A candidate's time on the case — the median of `repeat` renders, and the slowest (every
/// render must keep a budget) — and its penumbra error.
fn measure_choice(m: &mut Measuring<'_>, candidate: &crate::model::Candidate) -> anyhow::Result<(f64, f64, f64)> {
    if let Some(&(_, ms, slowest, error)) = m.measured.iter().find(|(l, ..)| *l == candidate.label) {
        return Ok((ms, slowest, error));
    }
    let case = m.case;
    eprintln!("{case}: {}", candidate.label);
    let chosen = crate::job::Job { method: candidate.method_for(m.job), compare: true, ..m.job.clone() };
    let warm_key = (candidate.label.clone(), m.light.to_owned());
    if !m.warm.contains(&warm_key) {
        m.engine.render_frame(&chosen, &()).map_err(|e| anyhow::anyhow!("{case}: {e}"))?;
        m.warm.push(warm_key);
    }
    let (mut times, mut error) = (Vec::new(), 0.0);
    for _ in 0..m.repeat {
        let (frame, ms) = measure::timed_render(m.engine, &chosen).map_err(|e| anyhow::anyhow!("{case}: {e}"))?;
        error = crate::quality::compare(&frame, m.reference, 0.0).visibility.penumbra.mae;
        times.push(ms);
    }
    times.sort_by(f64::total_cmp);
    let (median, slowest) = (times[times.len() / 2], times[times.len() - 1]);
    // As a daemon follows the jobs it renders.
    m.pace.observe(candidate.ms(m.features), median);
    m.measured.push((candidate.label.clone(), median, slowest, error));
    Ok((median, slowest, error))
}

/// Runs the budgets over `options`' scenes, lights and sizes (at its first map resolution) and
/// writes `budgets.md` and `budgets.json` under `options.out`.
pub fn run(engine: &Engine, options: &EvalOptions, model_file: Option<&std::path::Path>) -> anyhow::Result<BudgetReport> {
    std::fs::create_dir_all(&options.out).with_context(|| format!("cannot create {}", options.out.display()))?;
    let model = match model_file {
        Some(path) => serde_json::from_slice::<Model>(&std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?)
            .with_context(|| format!("{} is not a model", path.display()))?,
        None => {
            eprintln!("measuring the model first (penumbra eval --model)");
            let key = crate::model::key_for(&engine.adapter());
            let model = measure::measure(engine, &Suite::standard(), key, &measure::Plain)?.context("cancelled")?;
            std::fs::write(options.out.join("model.json"), serde_json::to_vec_pretty(&model)?)?;
            model
        }
    };
    let truth = Suite::standard();
    let sizes: Vec<(u32, u32)> = options.sizes.iter().map(|s| parse_size(s)).collect::<anyhow::Result<_>>()?;
    let shadow_map = options.shadow_map.first().copied().unwrap_or(1024);
    let (mut rows, mut rendered, mut rounds, mut firsts) = (Vec::new(), Vec::<BudgetRow>::new(), Vec::new(), Vec::new());
    // A daemon answers warm: each method's pipelines under each light are compiled by a first
    // render that is not timed.
    engine.warm_up().context("warm-up")?;
    let mut warm: Vec<(String, String)> = Vec::new();
    let pace = crate::model::Pace::default();
    for scene in suite::scenes(&options.scenes)? {
        for light in &options.lights {
            for &size in &sizes {
                let job = case_job(&scene, light, shadow_map, size, OutputFormat::Png)?;
                let case = format!("{} / {light} / {}×{}", scene.label, size.0, size.1);
                eprintln!("{case}: the truth");
                let (reference, _) = engine.render_frame(&truth.truth_of(&job), &()).map_err(|e| anyhow::anyhow!("{case}: {e}"))?;
                let unpaced = Features::of(&job, engine.scene_shape(&job.scene).as_ref());
                let paced = || Features { pace: pace.factor(), ..unpaced.clone() };
                let cheapest = model.predictions(&paced()).iter().map(|(_, p)| p.ms).fold(f64::INFINITY, f64::min);
                let budgets = TIME_FACTORS
                    .iter()
                    .map(|f| AutoBudget { max_ms: Some(cheapest * MARGIN * f), max_error: None })
                    .chain(ERRORS.iter().map(|&e| AutoBudget { max_ms: None, max_error: Some(e) }));
                let mut measuring = Measuring {
                    engine,
                    job: &job,
                    features: &unpaced,
                    pace: &pace,
                    reference: &reference,
                    case: &case,
                    light,
                    repeat: options.repeat,
                    warm: &mut warm,
                    measured: Vec::new(),
                };
                for budget in budgets {
                    let label = match (budget.max_ms, budget.max_error) {
                        (Some(ms), _) => format!("max_ms={ms:.0}"),
                        (_, Some(error)) => format!("max_error={error}"),
                        _ => unreachable!("a budget has one"),
                    };
                    let mut row = BudgetRow {
                        scene: scene.label.clone(),
                        light: light.clone(),
                        size: format!("{}×{}", size.0, size.1),
                        budget: label,
                        choice: String::new(),
                        predicted_ms: 0.0,
                        pace: 1.0,
                        measured_ms: None,
                        predicted_error: 0.0,
                        measured_error: None,
                        kept: None,
                    };
                    let features = paced();
                    row.pace = features.pace;
                    match model.choose(&budget, &features) {
                        Err(unmet) => {
                            row.choice = format!("refused (closest {})", unmet.closest);
                            (row.predicted_ms, row.predicted_error) = (unmet.prediction.ms, unmet.prediction.error);
                        }
                        Ok((candidate, prediction)) => {
                            let (ms, slowest, error) = measure_choice(&mut measuring, &candidate)?;
                            row.choice = candidate.label.clone();
                            (row.predicted_ms, row.predicted_error) = (prediction.ms, prediction.error);
                            (row.measured_ms, row.measured_error) = (Some(ms), Some(error));
                            row.kept =
                                Some(budget.max_ms.is_none_or(|max| slowest <= max) && budget.max_error.is_none_or(|max| error <= max));
                            if !rendered
                                .iter()
                                .any(|r| r.scene == row.scene && r.light == row.light && r.size == row.size && r.choice == row.choice)
                            {
                                rendered.push(row.clone());
                            }
                        }
                    }
                    rows.push(row);
                }
                // A progressive job's first image, for time budgets ten times auto's: the
                // daemon's choice, held to a tenth of the budget.
                for factor in TIME_FACTORS {
                    let max_ms = 10.0 * cheapest * MARGIN * factor;
                    let Some((candidate, prediction)) = model.first_image(Some(max_ms), &paced(), |_| true) else { continue };
                    let (ms, slowest, _) = measure_choice(&mut measuring, &candidate)?;
                    firsts.push(FirstImageRow {
                        scene: scene.label.clone(),
                        light: light.clone(),
                        size: format!("{}×{}", size.0, size.1),
                        max_ms,
                        choice: candidate.label.clone(),
                        predicted_ms: prediction.ms,
                        measured_ms: ms,
                        kept: slowest <= max_ms / 10.0,
                    });
                }
                drop(measuring);
                eprintln!("{case}: progressive rounds");
                for (samples, estimated, measured) in
                    progressive_rounds(engine, &job, &reference).map_err(|e| anyhow::anyhow!("{case}: {e}"))?
                {
                    let (scene, light, size) = (scene.label.clone(), light.clone(), format!("{}×{}", size.0, size.1));
                    rounds.push(RoundRow { scene, light, size, samples, estimated, measured });
                }
            }
        }
    }
    let share = |rows: &mut dyn Iterator<Item = bool>| rows.fold((0, 0), |(yes, all), kept| (yes + usize::from(kept), all + 1));
    let kept_of = |time: bool| {
        share(&mut rows.iter().filter(|r| r.budget.starts_with(if time { "max_ms" } else { "max_error" })).filter_map(|r| r.kept))
    };
    let close = |predicted: f64, measured: f64| (predicted - measured).abs() <= WITHIN * measured;
    let report = BudgetReport {
        model: format!("{} on {} ({})", model.source, model.key.adapter, model.key.build),
        time_kept: kept_of(true),
        error_kept: kept_of(false),
        time_predicted: share(&mut rendered.iter().map(|r| close(r.predicted_ms, r.measured_ms.unwrap_or(0.0)))),
        time_predicted_unpaced: share(&mut rendered.iter().map(|r| close(r.predicted_ms / r.pace, r.measured_ms.unwrap_or(0.0)))),
        error_predicted: share(&mut rendered.iter().map(|r| close(r.predicted_error, r.measured_error.unwrap_or(0.0)))),
        rows,
        rounds_estimated: share(&mut rounds.iter().map(|r| (r.estimated - r.measured).abs() <= ESTIMATE_WITHIN * r.measured)),
        rounds,
        first_images_kept: share(&mut firsts.iter().map(|r| r.kept)),
        first_images: firsts,
    };
    std::fs::write(options.out.join("budgets.json"), serde_json::to_vec_pretty(&report)?)?;
    super::plots::plot_budgets(&options.out, &rendered, &report.rounds)?;
    let table = table(&report);
    std::fs::write(options.out.join("budgets.md"), &table)?;
    println!("{table}");
    Ok(report)
}

/// A row of a Markdown table.
fn row(cells: &[String]) -> String {
    format!("| {} |\n", cells.join(" | "))
}

/// A progressive job's reference rounds on `job` (16, 32 … `ROUND_SAMPLES` samples, each
/// round's sums carried to the next as the daemon carries them): per round, its samples, its
/// error estimate and its error measured against `truth`.
fn progressive_rounds(
    engine: &Engine,
    job: &crate::job::Job,
    truth: &crate::render::FrameOutput,
) -> crate::error::JobResult<Vec<(u32, f64, f64)>> {
    let carried = crate::supervise::Rounds::default();
    let supervisor = crate::supervise::WithRounds { inner: &(), rounds: &carried };
    let mut rounds = Vec::new();
    for samples in crate::job::progressive::round_samples(ROUND_SAMPLES) {
        let reference = crate::job::MethodSpec { name: "reference".into(), params: Default::default() };
        let method = crate::job::progressive::round_method(&reference, samples);
        // EXR: its visibility comes back, to be measured.
        let output = crate::job::OutputSpec { format: OutputFormat::Exr, ..job.output.clone() };
        let method = crate::methods::with_map_resolution(&method, job.shadow_map.resolution);
        let round = crate::job::Job { method, output, ..job.clone() };
        let (frame, _) = engine.render_frame(&round, &supervisor)?;
        let estimated = crate::render::method::ERROR_ESTIMATE.get(&frame.counters).unwrap_or(f64::NAN);
        rounds.push((samples, estimated, crate::quality::compare(&frame, truth, 0.0).visibility.penumbra.mae));
    }
    Ok(rounds)
}

/// The report as Markdown: the summary against the goals, then every row.
pub fn table(report: &BudgetReport) -> String {
    let percent = |(yes, all): (usize, usize)| {
        if all == 0 {
            "-".to_owned()
        } else {
            format!("{yes} of {all} ({:.0} %)", 100.0 * yes as f64 / all as f64)
        }
    };
    let mut out = format!(
        "# auto's budgets, measured\n\nModel: {}.\n\n| what | measured | goal |\n|---|---:|---:|\n\
         | time budgets kept | {} | ≥ 90 % |\n| error budgets kept | {} | ≥ 90 % |\n\
         | time predicted within ±25 % | {} | ≥ 80 % |\n| … by the model alone (pace 1) | {} | |\n\
         | error predicted within ±25 % | {} | ≥ 80 % |\n\
         | progressive rounds' error estimated within ±30 % | {} | ≥ 80 % |\n\
         | progressive first images within a tenth of max_ms | {} | ≥ 90 % |\n\n\
         | scene | light | size | budget | choice | pace | predicted ms | measured ms | predicted error | measured error | kept |\n\
         |---|---|---|---|---|---:|---:|---:|---:|---:|---|\n",
        report.model,
        percent(report.time_kept),
        percent(report.error_kept),
        percent(report.time_predicted),
        percent(report.time_predicted_unpaced),
        percent(report.error_predicted),
        percent(report.rounds_estimated),
        percent(report.first_images_kept)
    );
    let or_dash = |v: Option<f64>, digits: usize| v.map_or("-".to_owned(), |v| format!("{v:.digits$}"));
    for r in &report.rows {
        let kept = match r.kept {
            Some(true) => "yes",
            Some(false) => "**no**",
            None => "refused",
        };
        out.push_str(&row(&[
            r.scene.clone(),
            r.light.clone(),
            r.size.clone(),
            r.budget.clone(),
            r.choice.clone(),
            format!("{:.2}", r.pace),
            format!("{:.0}", r.predicted_ms),
            or_dash(r.measured_ms, 0),
            format!("{:.4}", r.predicted_error),
            or_dash(r.measured_error, 4),
            kept.to_owned(),
        ]));
    }
    out.push_str(
        "\n## Progressive rounds\n\nThe reference's rounds as a progressive job runs them (sums carried), each round's \
         error estimate (half its two halves' difference) against its error measured against the truth.\n\n\
         | scene | light | size | samples | estimated | measured | estimated ÷ measured |\n|---|---|---|---:|---:|---:|---:|\n",
    );
    for r in &report.rounds {
        out.push_str(&row(&[
            r.scene.clone(),
            r.light.clone(),
            r.size.clone(),
            r.samples.to_string(),
            format!("{:.4}", r.estimated),
            format!("{:.4}", r.measured),
            format!("{:.2}", r.estimated / r.measured),
        ]));
    }
    out.push_str(
        "\n## Progressive first images\n\nA progressive job's first image for `max_ms` ten times each of auto's time \
         budgets: the method the daemon picks for a tenth of it, and its time (the median of `--repeat` renders; kept when \
         every render came within the tenth).\n\n\
         | scene | light | size | max_ms | first image | predicted ms | measured ms | within a tenth |\n|---|---|---|---:|---|---:|---:|---|\n",
    );
    for r in &report.first_images {
        out.push_str(&row(&[
            r.scene.clone(),
            r.light.clone(),
            r.size.clone(),
            format!("{:.0}", r.max_ms),
            r.choice.clone(),
            format!("{:.0}", r.predicted_ms),
            format!("{:.0}", r.measured_ms),
            if r.kept { "yes" } else { "**no**" }.to_owned(),
        ]));
    }
    out
}
