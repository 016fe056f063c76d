//! `penumbra bench`: what a frame costs, phase by phase, as users request it — warm, PNG,
//! whole requests through `Engine::render` — at 1920×1080 on the built-in scenes, with every
//! method's penumbra error against a high-sample `reference` beside it, and how close the
//! interpolated E0 stays to the exact sum. Writes `bench.md` and `bench.json`.
//!
//! Runs are repeated round-robin over the methods and each phase's median is reported, so a
//! slow spell of a noisy machine hits every method alike; ratios to the G-buffer pass (whose
//! cost no method changes) are the figures to compare between machines.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use serde::Serialize;
use serde_json::Map;

use super::{case_job, every_method_but_reference, median_timings, method_job, parse_methods, parse_named, parse_size};
use crate::engine::Engine;
use crate::job::{Job, MethodSpec, OutputFormat};
use crate::render::{E0Mode, FrameOutput};
use crate::timing::{PhaseName, Timings};

/// What to run.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchOptions {
    /// Scenes, comma-separated: built-in ones, each optionally with parameters, scene files
    /// and folders of them (real models, staged on a floor as `eval` stages them).
    #[arg(long, value_delimiter = ',', default_value = "crowd,columns,terrain:triangles=100000")]
    pub scenes: Vec<String>,
    /// Built-in light images, comma-separated: by default 1, 6, 26 and 64 uniform cells (the
    /// most E0 sums: issue 20 bounds the floor for lights of up to 64).
    #[arg(long, value_delimiter = ',', default_value = "white,stripes,flame,mosaic")]
    pub lights: Vec<String>,
    /// Methods, comma-separated, each optionally with parameters (`name:key=value`). Default:
    /// every registered method but `reference`, which is timed on its own (`--reference-samples`).
    #[arg(long, value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Output size, WIDTHxHEIGHT.
    #[arg(long, default_value = "1920x1080")]
    pub size: String,
    /// Shadow-map resolution (texels per side).
    #[arg(long, default_value_t = 2048)]
    pub shadow_map: u32,
    /// Timed runs of every method per case, round-robin; phases are their medians.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeat: u32,
    /// Light samples of the reference every error is measured against.
    #[arg(long, default_value_t = 256)]
    pub samples: u32,
    /// Light samples of the timed `reference` row (its error against the one above is
    /// reported too: it falls as 1/√samples).
    #[arg(long, default_value_t = 64)]
    pub reference_samples: u32,
    /// Folder for `bench.md` and `bench.json`.
    #[arg(long, default_value = "bench")]
    pub out: PathBuf,
}

/// The phases of a request, in order; `floor` is what every method shares after its own
/// pass (E0, composite, readback, encode).
const PHASES: [PhaseName; 7] = [
    PhaseName::ShadowMap,
    PhaseName::Gbuffer,
    PhaseName::E0,
    PhaseName::Method,
    PhaseName::Composite,
    PhaseName::Readback,
    PhaseName::Encode,
];
const FLOOR: [PhaseName; 4] = [PhaseName::E0, PhaseName::Composite, PhaseName::Readback, PhaseName::Encode];

/// One method in one case: median phase times of whole requests and its error.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRow {
    pub scene: String,
    pub light: String,
    pub method: String,
    /// Median ms per phase (GPU time where timestamps exist, else wall time), `PHASES` order.
    pub phases: Vec<(String, f64)>,
    /// E0 + composite + readback + encode, ms.
    pub floor_ms: f64,
    /// Median wall time of the whole request, ms.
    pub whole_ms: f64,
    /// `whole_ms` over the G-buffer phase's median.
    pub whole_over_gbuffer: f64,
    /// Median CPU time of the whole request, ms: user and system time of every thread of the
    /// process. On a software adapter the device's work runs on this process's threads, so
    /// this is what the request cost in cores; over `whole_ms`, how many it kept busy.
    pub cpu_ms: f64,
    /// Mean |V − Vref| over the reference's penumbra, and over the frame.
    pub penumbra_error: f64,
    pub frame_error: f64,
    pub triangles: u64,
    /// Median GPU ms of each pass (of each dispatch, where timestamps can be written inside
    /// passes) as (phase, pass, ms), in recording order.
    pub passes: Vec<(String, String, f64)>,
}

/// How the interpolated E0 compares with the exact sum in one case.
#[derive(Debug, Clone, Serialize)]
pub struct E0Accuracy {
    pub scene: String,
    pub light: String,
    pub cells: usize,
    /// Largest |E0 − exact| / exact over pixels and channels with exact > 1e-3 × the frame's
    /// largest value, and the mean over the same.
    pub worst_relative: f64,
    pub mean_relative: f64,
    /// Lit pixels whose E0 the interpolation kept (not listed for an exact sum).
    pub interpolated_fraction: f64,
    /// The E0 phase of one frame summed exactly everywhere, and of one interpolated, ms.
    pub exact_ms: f64,
    pub interpolated_ms: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub adapter: crate::gpu::AdapterSummary,
    pub width: u32,
    pub height: u32,
    pub shadow_map: u32,
    pub repeat: u32,
    pub samples: u32,
    pub reference_samples: u32,
    pub rows: Vec<BenchRow>,
    pub e0: Vec<E0Accuracy>,
}

/// Runs the benchmark and writes `bench.md` and `bench.json` under `options.out`.
pub fn run(engine: &Engine, options: &BenchOptions) -> anyhow::Result<BenchReport> {
    let (width, height) = parse_size(&options.size)?;
    let mut methods = if options.methods.is_empty() { every_method_but_reference() } else { parse_methods(&options.methods)? };
    let mut timed_reference = MethodSpec { name: "reference".into(), params: Map::new() };
    timed_reference.params.insert("samples".into(), options.reference_samples.into());
    timed_reference.params.insert("resolution".into(), options.shadow_map.into());
    methods.push((format!("reference ({} samples)", options.reference_samples), timed_reference));
    std::fs::create_dir_all(&options.out).with_context(|| format!("cannot create {}", options.out.display()))?;
    engine.warm_up().context("warm-up")?;

    let scenes = super::suite::scenes(&options.scenes)?;
    let cases = scenes.len() * options.lights.len();
    let progress = indicatif::ProgressBar::new((cases * (methods.len() * (options.repeat as usize + 1) + 3)) as u64);
    progress.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed_precise} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let (mut rows, mut e0) = (Vec::new(), Vec::new());
    for suite_scene in &scenes {
        let scene = &suite_scene.label;
        for light in &options.lights {
            let case = format!("{scene}, {light}");
            let base = case_job(suite_scene, light, options.shadow_map, (width, height), OutputFormat::Png)?;
            let exr = |job: &Job| Job { output: crate::job::OutputSpec { format: OutputFormat::Exr, ..job.output.clone() }, ..job.clone() };
            let frame = |job: &Job, what: &str| engine.render_frame(&exr(job), &()).map_err(|e| anyhow::anyhow!("{case}: {what}: {e}"));

            progress.set_message(format!("{case}: reference, {} samples", options.samples));
            let (truth, _) = frame(&base.reference_with(options.samples, options.shadow_map), "reference")?;
            progress.inc(1);

            progress.set_message(format!("{case}: E0, exact and interpolated"));
            e0.push(e0_accuracy(
                engine,
                scene,
                light,
                &exr(&Job { method: MethodSpec { name: "hard".into(), params: Map::new() }, ..base.clone() }),
            )?);
            progress.inc(2);

            // Errors, from one EXR frame each (not timed).
            let mut errors = Vec::new();
            for (label, method) in &methods {
                progress.set_message(format!("{case}: {label}, error"));
                let (test, _) = frame(&method_job(&base, method), label)?;
                errors.push(visibility_errors(&test, &truth));
                progress.inc(1);
            }
            // Whole PNG requests, round-robin.
            let mut runs: Vec<Vec<(Timings, f64)>> = vec![Vec::new(); methods.len()];
            for repetition in 0..options.repeat {
                for ((label, method), runs) in methods.iter().zip(&mut runs) {
                    progress.set_message(format!("{case}: {label} ({}/{})", repetition + 1, options.repeat));
                    let cpu_before = crate::timing::process_cpu_ms();
                    let rendered = engine.render(&method_job(&base, method), &()).map_err(|e| anyhow::anyhow!("{case}: {label}: {e}"))?;
                    runs.push((rendered.timings, crate::timing::process_cpu_ms() - cpu_before));
                    progress.inc(1);
                }
            }
            for (((label, _), runs), (penumbra_error, frame_error)) in methods.iter().zip(runs).zip(errors) {
                rows.push(bench_row(scene, light, label, runs, penumbra_error, frame_error));
            }
        }
    }
    progress.finish_and_clear();
    let report = BenchReport {
        adapter: engine.gpu().adapter.clone(),
        width,
        height,
        shadow_map: options.shadow_map,
        repeat: options.repeat,
        samples: options.samples,
        reference_samples: options.reference_samples,
        rows,
        e0,
    };
    std::fs::write(options.out.join("bench.json"), serde_json::to_vec_pretty(&report)?)?;
    std::fs::write(options.out.join("bench.md"), markdown(&report)?)?;
    Ok(report)
}

/// A phase's time: GPU time where measured, else wall time.
fn phase_ms(t: &Timings, name: PhaseName) -> f64 {
    t.get(name).map(|p| p.gpu_ms.unwrap_or(p.cpu_ms)).unwrap_or(0.0)
}

/// The middle value (the upper of the two middle ones for an even count).
fn middle(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn bench_row(scene: &str, light: &str, method: &str, runs: Vec<(Timings, f64)>, penumbra_error: f64, frame_error: f64) -> BenchRow {
    let whole_ms = middle(runs.iter().map(|(t, _)| t.total_ms).collect());
    let cpu_ms = middle(runs.iter().map(|(_, cpu)| *cpu).collect());
    let median = median_timings(runs.into_iter().map(|(t, _)| t).collect());
    let phases: Vec<(String, f64)> = PHASES.iter().map(|&p| (p.to_string(), phase_ms(&median, p))).collect();
    let gbuffer = phase_ms(&median, PhaseName::Gbuffer);
    BenchRow {
        scene: scene.into(),
        light: light.into(),
        method: method.into(),
        floor_ms: FLOOR.iter().map(|&p| phase_ms(&median, p)).sum(),
        whole_over_gbuffer: if gbuffer > 0.0 { whole_ms / gbuffer } else { f64::NAN },
        phases,
        whole_ms,
        cpu_ms,
        penumbra_error,
        frame_error,
        triangles: median.scene_triangles,
        passes: median.phases.iter().flat_map(|p| p.passes.iter().map(|q| (p.name.to_string(), q.name.to_owned(), q.gpu_ms))).collect(),
    }
}

/// Mean |V − Vref| (all channels) over the reference's penumbra and over the whole frame.
fn visibility_errors(test: &FrameOutput, truth: &FrameOutput) -> (f64, f64) {
    let mask = crate::quality::penumbra_mask(truth);
    let (v, r) = (test.visibility.as_ref().expect("EXR frames carry V"), truth.visibility.as_ref().expect("EXR frames carry V"));
    let (mut penumbra, mut count, mut whole) = (0.0f64, 0usize, 0.0f64);
    for ((a, b), inside) in v.iter().zip(r).zip(&mask) {
        let d: f64 = (0..3).map(|k| f64::from((a[k] - b[k]).abs())).sum::<f64>() / 3.0;
        whole += d;
        if *inside {
            penumbra += d;
            count += 1;
        }
    }
    (if count > 0 { penumbra / count as f64 } else { 0.0 }, whole / v.len().max(1) as f64)
}

/// Renders `job` with E0 summed exactly and interpolated, and compares the two E0 images.
fn e0_accuracy(engine: &Engine, scene: &str, light: &str, job: &Job) -> anyhow::Result<E0Accuracy> {
    let mut frames = Vec::new();
    for mode in [E0Mode::Exact, E0Mode::Interpolated] {
        engine.set_e0_mode(mode);
        let rendered = engine.render_frame(job, &());
        engine.set_e0_mode(E0Mode::default());
        let (frame, timings) = rendered.map_err(|e| anyhow::anyhow!("{scene}, {light}: E0: {e}"))?;
        let summed_exactly = crate::render::E0_SUMMED_EXACTLY.get(&frame.counters);
        frames.push((frame.e0.context("EXR frames carry E0")?, summed_exactly, phase_ms(&timings, PhaseName::E0)));
    }
    let ((exact, _, exact_ms), (interpolated, summed_exactly, interpolated_ms)) = (&frames[0], &frames[1]);
    let largest = exact.iter().flatten().fold(0.0f32, |m, &e| m.max(e));
    let (mut worst, mut sum, mut counted, mut lit) = (0.0f64, 0.0f64, 0usize, 0usize);
    for (e, i) in exact.iter().zip(interpolated) {
        for k in 0..3 {
            if e[k] > 1e-3 * largest {
                let relative = f64::from((i[k] - e[k]).abs() / e[k]);
                worst = worst.max(relative);
                sum += relative;
                counted += 1;
            }
        }
        lit += usize::from(e.iter().any(|&c| c > 0.0));
    }
    // The lit pixels the interpolation kept: all of them but those it listed for the exact
    // sums (none where it did not run: a light of a cell or two).
    let kept = summed_exactly.map_or(0, |listed| lit.saturating_sub(listed as usize));
    let (name, params) = parse_named(light)?;
    let image = crate::light::LightImage::builtin(&name, &params, "light").map_err(|e| anyhow::anyhow!("{light}: {}", e.message))?;
    let unit = crate::light::AreaLight::new(glam::Vec3::ZERO, -glam::Vec3::Y, -glam::Vec3::Z, glam::Vec2::ONE, 1.0)
        .map_err(|e| anyhow::anyhow!(e.message))?;
    Ok(E0Accuracy {
        scene: scene.into(),
        light: light.into(),
        cells: crate::light::light_cells(&unit, &image).len(),
        worst_relative: worst,
        mean_relative: if counted > 0 { sum / counted as f64 } else { 0.0 },
        interpolated_fraction: if lit > 0 { kept as f64 / lit as f64 } else { 0.0 },
        exact_ms: *exact_ms,
        interpolated_ms: *interpolated_ms,
    })
}

fn markdown(report: &BenchReport) -> Result<String, std::fmt::Error> {
    let mut md = String::new();
    let a = &report.adapter;
    writeln!(md, "# penumbra bench\n")?;
    writeln!(
        md,
        "Adapter: {} ({}, {}). {}×{}, shadow map {}², whole PNG requests of a warm engine, medians of {} runs of every \
         method, interleaved. Phases in ms (GPU time where timestamps exist; readback and encode are wall time); \
         *floor* = E0 + composite + readback + encode, what every method shares after its own pass; *÷ G-buffer* = \
         the whole request over the G-buffer pass, the ratio to compare between machines; *CPU* = the process's CPU \
         time over the request (every thread: on a software adapter, the device's work too) and *cores* = CPU over \
         whole, how many cores it kept busy. Error: mean |V − Vref| over the penumbra of a {}-sample reference.\n",
        a.name, a.backend, a.device_type, report.width, report.height, report.shadow_map, report.repeat, report.samples
    )?;
    let mut cases: Vec<(&str, &str)> = Vec::new();
    for row in &report.rows {
        if !cases.contains(&(row.scene.as_str(), row.light.as_str())) {
            cases.push((&row.scene, &row.light));
        }
    }
    for (scene, light) in cases {
        let rows: Vec<&BenchRow> = report.rows.iter().filter(|r| r.scene == scene && r.light == light).collect();
        let triangles = rows.first().map(|r| r.triangles).unwrap_or(0);
        writeln!(md, "## {scene}, {light} ({triangles} triangles)\n")?;
        writeln!(md, "| method | shadow map | G-buffer | E0 | method | composite | readback | encode | floor | whole | ÷ G-buffer | CPU | cores | penumbra error |")?;
        writeln!(md, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
        for row in &rows {
            let phases: Vec<String> = row.phases.iter().map(|(_, ms)| format!("{ms:.0}")).collect();
            writeln!(
                md,
                "| {} | {} | {:.0} | {:.0} | {:.1} | {:.0} | {:.2} | {:.4} |",
                row.method,
                phases.join(" | "),
                row.floor_ms,
                row.whole_ms,
                row.whole_over_gbuffer,
                row.cpu_ms,
                row.cpu_ms / row.whole_ms,
                row.penumbra_error
            )?;
        }
        writeln!(md)?;
        passes_markdown(&mut md, &rows)?;
    }
    writeln!(md, "## E0: interpolated against the exact sum\n")?;
    writeln!(md, "Relative error over pixels and channels with E0 > 1e-3 × the frame's largest (contract §1: at most 1e-3).\n")?;
    writeln!(
        md,
        "| scene | light | cells | interpolated pixels | worst relative error | mean relative error | E0 exact ms | E0 interpolated ms |"
    )?;
    writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|")?;
    for e in &report.e0 {
        writeln!(
            md,
            "| {} | {} | {} | {:.0} % | {:.1e} | {:.1e} | {:.0} | {:.0} |",
            e.scene,
            e.light,
            e.cells,
            100.0 * e.interpolated_fraction,
            e.worst_relative,
            e.mean_relative,
            e.exact_ms,
            e.interpolated_ms
        )?;
    }
    Ok(md)
}

/// Where each row's E0 and method phases go, pass by pass (dispatch by dispatch where the
/// adapter times inside passes): the list to read before choosing what to speed up.
fn passes_markdown(md: &mut String, rows: &[&BenchRow]) -> std::fmt::Result {
    if rows.iter().all(|r| r.passes.is_empty()) {
        return Ok(());
    }
    writeln!(md, "ms per pass (medians; GPU time, or wall time on the CPU for a pass named `*_cpu_*`), E0 then the method:\n")?;
    for row in rows {
        let list: Vec<String> = row
            .passes
            .iter()
            .filter(|(phase, _, _)| phase == "e0" || phase == "method")
            .map(|(_, pass, ms)| format!("{pass} {ms:.1}"))
            .collect();
        if !list.is_empty() {
            writeln!(md, "- {}: {}", row.method, list.join(" · "))?;
        }
    }
    writeln!(md)
}
