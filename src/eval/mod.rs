//! `penumbra eval`: runs a suite — built-in scenes × light images × methods × output sizes —
//! against `reference`, and writes to a folder a Markdown table, the same rows as CSV and
//! JSON, a contact sheet per case (reference and every method side by side, their
//! visibility errors below) and an error heat-map per method.
//!
//! Timings in one run are comparable with each other: the engine is warmed up first (no
//! pipeline compilation in any row) and every row reports its ratio to `hard` in the same
//! case. Quote those ratios, not absolute times: these machines are noisy.
//!
//! Scenes are built-ins or real models (`suite.rs`): files made by others, staged on a floor
//! with the fitted camera and light; their rows are also summed up per method (`real.rs`).

pub mod budgets;
mod compare;
pub mod frame_bench;
mod options;
mod pictures;
mod plots;
mod real;
mod suite;
mod tables;

use std::path::PathBuf;

use anyhow::Context as _;
use serde::Serialize;

use crate::engine::Engine;
use crate::job::{AssetRef, Job, MethodSpec, OutputFormat};
use crate::methods::Counters;
use crate::quality::{self, QualityReport};
use crate::render::FrameOutput;
use crate::timing::Timings;
use compare::{colored_ratios, jump_twin, with_white_twins};
pub use compare::{compare_flooding, ColoredRatio, FloodingComparison, SuiteLight};
pub use options::EvalOptions;
use options::{every_method_but_reference, parse_method, parse_methods, parse_named, parse_size, parse_sweep, Sweep};
use pictures::{sanitize, write_pictures};
use plots::{plot_scaling, plot_sweep};
pub use real::RealSummary;
pub use suite::SuiteScene;
use tables::write_tables;

/// One method in one case.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub scene: String,
    /// Whether the scene is a real model (a file), not a built-in.
    pub real_model: bool,
    /// The case's name in its pictures (`sheet-{case}.png`).
    pub case: String,
    pub light: String,
    pub width: u32,
    pub height: u32,
    pub shadow_map: u32,
    pub method: String,
    pub timings: Timings,
    /// Total wall time of this row over that of `hard` in the same case.
    pub ratio_to_hard: Option<f64>,
    pub quality: QualityReport,
    pub counters: Counters,
}

#[derive(Debug, Clone, Serialize)]
pub struct EvalReport {
    pub adapter: crate::gpu::AdapterSummary,
    /// Runs of every method per case; times are medians over them.
    pub repeat: u32,
    pub rows: Vec<Row>,
    /// Jump against standard flooding, for every method run both ways (Rong & Tan 2006 §4.2).
    pub flooding: Vec<FloodingComparison>,
    /// With `--colored`: each method's penumbra error under each coloured light against its
    /// error under the light's white twin.
    pub colored: Vec<ColoredRatio>,
    /// With real models: each method's penumbra error over them, per light.
    pub real_models: Vec<RealSummary>,
    /// Real models left out of the suite, and why (penumbra refused them, or a method failed).
    pub skipped: Vec<(String, String)>,
    pub files: Vec<PathBuf>,
}

/// A case's job: a suite's scene under a built-in light image (as given on the command line),
/// at this output size and format and this shadow-map resolution, with the scene's default
/// camera and light (fitted, for a file) and the embedded default's method.
fn case_job(scene: &SuiteScene, light: &str, shadow_map: u32, (width, height): (u32, u32), format: OutputFormat) -> anyhow::Result<Job> {
    let (light_name, light_params) = parse_named(light)?;
    Ok(Job {
        scene: scene.scene.clone(),
        light: crate::job::LightSpec { image: Some(AssetRef::Builtin { name: light_name, params: light_params }), ..Default::default() },
        shadow_map: crate::job::ShadowMapSpec { resolution: shadow_map },
        output: crate::job::OutputSpec { width, height, format, exposure: 0.0 },
        ..Job::embedded_default()
    })
}

/// `base` rendered by `method`, its own sample maps (if it draws any) at the case's shadow-map
/// resolution, as the reference it is measured against draws them (`with_map_resolution`).
fn method_job(base: &Job, method: &MethodSpec) -> Job {
    Job { method: crate::methods::with_map_resolution(method, base.shadow_map.resolution), ..base.clone() }
}

/// Runs the suite and writes the results under `options.out`.
pub fn run(engine: &Engine, options: &EvalOptions) -> anyhow::Result<EvalReport> {
    let sweep = options.sweep.as_deref().map(parse_sweep).transpose()?;
    let mut methods =
        if options.methods.is_empty() && sweep.is_none() { every_method_but_reference() } else { parse_methods(&options.methods)? };
    if let Some(sweep) = &sweep {
        for (_, label) in &sweep.points {
            methods.push((label.clone(), parse_method(label)?));
        }
    }
    let sizes: Vec<(u32, u32)> = options.sizes.iter().map(|s| parse_size(s)).collect::<anyhow::Result<_>>()?;
    let lights = with_white_twins(&options.lights, options.colored)?;
    let scenes = suite::scenes(&options.scenes)?;
    let options = &EvalOptions {
        lights: lights.iter().map(|l| l.label.clone()).collect(),
        scenes: scenes.iter().map(|s| s.label.clone()).collect(),
        ..options.clone()
    };
    std::fs::create_dir_all(&options.out).with_context(|| format!("cannot create {}", options.out.display()))?;
    engine.warm_up().context("warm-up")?;

    let cases = options.scenes.len() * options.lights.len() * sizes.len() * options.shadow_map.len();
    let progress = indicatif::ProgressBar::new((cases * (methods.len() + 1)) as u64);
    progress.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed_precise} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let suite = Suite { engine, options, methods: &methods, sweep: sweep.as_ref(), progress: &progress };
    let (mut rows, mut flooding, mut files, mut skipped) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for scene in &scenes {
        for light in &options.lights {
            for (&size, &shadow_map) in sizes.iter().flat_map(|s| options.shadow_map.iter().map(move |m| (s, m))) {
                match suite.run_case(scene, light, size, shadow_map) {
                    Ok(case) => {
                        rows.extend(case.rows);
                        flooding.extend(case.flooding);
                        files.extend(case.files);
                    }
                    // A model others made may be one penumbra refuses, or one a method fails
                    // on: the suite goes on, and the report names it.
                    Err(error) if scene.real => {
                        progress.println(format!("skipped {}: {error:#}", scene.label));
                        skipped.push((scene.label.clone(), format!("{error:#}")));
                    }
                    Err(error) => return Err(error),
                }
            }
        }
    }
    progress.finish_and_clear();
    files.extend(plot_scalings(options, sizes.len(), &rows)?);
    let colored = if options.colored { colored_ratios(&rows, &lights) } else { Vec::new() };
    let real_models = real::summarize(&rows);
    files.extend(pictures::write_worst_sheets(&options.out, &real_models, &methods)?);
    let report =
        EvalReport { adapter: engine.gpu().adapter.clone(), repeat: options.repeat, rows, flooding, colored, real_models, skipped, files };
    write_tables(&options.out, &report, &methods.iter().map(|(l, _)| l.clone()).collect::<Vec<_>>(), sweep.as_ref())?;
    Ok(report)
}

/// What every case of a suite shares.
struct Suite<'a> {
    engine: &'a Engine,
    options: &'a EvalOptions,
    methods: &'a [(String, MethodSpec)],
    sweep: Option<&'a Sweep>,
    progress: &'a indicatif::ProgressBar,
}

/// One case's rows (the reference's first), flooding comparisons and files written.
struct CaseResults {
    rows: Vec<Row>,
    flooding: Vec<FloodingComparison>,
    files: Vec<PathBuf>,
}

impl Suite<'_> {
    /// Renders the reference and every method (`repeat` times, round-robin) for one scene,
    /// light, output size and shadow map, and writes the case's pictures (and sweep plot).
    fn run_case(&self, scene: &SuiteScene, light: &str, (width, height): (u32, u32), shadow_map: u32) -> anyhow::Result<CaseResults> {
        let (engine, options, progress) = (self.engine, self.options, self.progress);
        let scene_label = sanitize(&scene.label);
        let name = case_name(&scene_label, light, (width, height), (options.shadow_map.len() > 1).then_some(shadow_map));
        let key = Case { scene, name, light, shadow_map };
        let case = &key.name;
        let base = case_job(scene, light, shadow_map, (width, height), OutputFormat::Exr)?;
        progress.set_message(format!("{case}: reference"));
        let (reference, reference_timings) = engine
            .render_frame(&base.reference_with(options.samples, shadow_map), &|done, total| {
                progress.set_message(format!("{case}: reference {done}/{total} samples"))
            })
            .with_context(|| format!("{case}: reference"))?;
        progress.inc(1);
        let mut rows = vec![key.row("reference", reference_timings, &reference, &reference)];
        let mut frames = Vec::new();
        let mut runs: Vec<Vec<Timings>> = vec![Vec::new(); self.methods.len()];
        for repetition in 0..options.repeat {
            for ((label, method), runs) in self.methods.iter().zip(&mut runs) {
                progress.set_message(format!("{case}: {label} ({}/{})", repetition + 1, options.repeat));
                let job = method_job(&base, method);
                let (frame, timings) = engine.render_frame(&job, &()).map_err(|e| anyhow::anyhow!("{case}: {label}: {e}"))?;
                runs.push(timings);
                if repetition == 0 {
                    frames.push((label.clone(), frame));
                }
            }
        }
        for (((label, _), runs), (_, frame)) in self.methods.iter().zip(runs).zip(&frames) {
            rows.push(key.row(label, median_timings(runs), frame, &reference));
            progress.inc(1);
        }
        let hard_ms = rows.iter().find(|r| r.method == "hard").map(|r| r.timings.total_ms);
        for r in &mut rows {
            r.ratio_to_hard = hard_ms.map(|h| r.timings.total_ms / h);
        }
        let mut flooding = Vec::new();
        for (label, frame) in &frames {
            let twin = jump_twin(label).and_then(|jump| frames.iter().find(|(l, _)| *l == jump));
            if let Some((jump_label, jump)) = twin {
                flooding.push(compare_flooding(case, jump_label, jump, frame));
            }
        }
        let mut files = write_pictures(&options.out, case, &reference, &frames)?;
        if let Some(sweep) = self.sweep {
            files.push(plot_sweep(&options.out, case, sweep, &rows)?);
        }
        Ok(CaseResults { rows, flooding, files })
    }
}

/// Cost against the size of the problem: per scene and light against the shadow map's
/// resolution or the output's pixels where the suite has several (of `sizes` output sizes);
/// per built-in scene run at several sizes (`terrain:triangles=…`) against its triangles,
/// where the object-space method grows and the image-space ones stay flat.
fn plot_scalings(options: &EvalOptions, sizes: usize, rows: &[Row]) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    if options.shadow_map.len() > 1 || sizes > 1 {
        for scene in &options.scenes {
            for light in &options.lights {
                let by_map = options.shadow_map.len() > 1;
                let x: fn(&Row) -> f64 =
                    if by_map { |r| f64::from(r.shadow_map) } else { |r| f64::from(r.width) * f64::from(r.height) / 1e6 };
                let x_desc = if by_map { "shadow-map resolution (texels per side)" } else { "output (megapixels)" };
                let chosen: Vec<&Row> = rows.iter().filter(|r| &r.scene == scene && &r.light == light).collect();
                let name = format!("scaling-{}-{}.svg", sanitize(scene), sanitize(light));
                files.push(plot_scaling(&options.out, &name, &format!("{scene}, {light}"), x_desc, &chosen, x, false)?);
            }
        }
    }
    let bases: Vec<&str> = options.scenes.iter().map(|s| s.split(':').next().unwrap_or_default()).collect();
    for base in bases.iter().copied().collect::<std::collections::BTreeSet<_>>() {
        if bases.iter().filter(|b| **b == base).count() < 2 {
            continue;
        }
        for light in &options.lights {
            let chosen: Vec<&Row> = rows.iter().filter(|r| r.scene.split(':').next() == Some(base) && &r.light == light).collect();
            let name = format!("scaling-{base}-triangles-{}.svg", sanitize(light));
            files.push(plot_scaling(
                &options.out,
                &name,
                &format!("{base}, {light}"),
                "scene triangles",
                &chosen,
                |r| r.timings.scene_triangles as f64,
                true,
            )?);
        }
    }
    Ok(files)
}

/// Per phase, the median over repeated runs of one job (wall and GPU time separately).
fn median_timings(mut runs: Vec<Timings>) -> Timings {
    fn median(mut values: Vec<f64>) -> f64 {
        values.sort_by(f64::total_cmp);
        let mid = values.len() / 2;
        if values.len() % 2 == 1 {
            values[mid]
        } else {
            0.5 * (values[mid - 1] + values[mid])
        }
    }
    let mut result = runs.swap_remove(0);
    if runs.is_empty() {
        return result;
    }
    for phase in &mut result.phases {
        let same: Vec<_> = runs.iter().filter_map(|t| t.phases.iter().find(|p| p.name == phase.name)).collect();
        let mut wall: Vec<f64> = same.iter().map(|p| p.cpu_ms).collect();
        wall.push(phase.cpu_ms);
        phase.cpu_ms = median(wall);
        if let Some(gpu) = phase.gpu_ms {
            let mut all: Vec<f64> = same.iter().filter_map(|p| p.gpu_ms).collect();
            all.push(gpu);
            phase.gpu_ms = Some(median(all));
        }
        for pass in &mut phase.passes {
            let mut all: Vec<f64> = same.iter().filter_map(|p| p.passes.iter().find(|q| q.name == pass.name)).map(|q| q.gpu_ms).collect();
            all.push(pass.gpu_ms);
            pass.gpu_ms = median(all);
        }
    }
    result
}

/// The name of a case's pictures: scene, light, size, and the shadow map's resolution where
/// the suite runs several.
fn case_name(scene: &str, light: &str, (width, height): (u32, u32), shadow_map: Option<u32>) -> String {
    match shadow_map {
        Some(map) => format!("{scene}-{}-{width}x{height}-map{map}", sanitize(light)),
        None => format!("{scene}-{}-{width}x{height}", sanitize(light)),
    }
}

/// What one case's rows share: its scene, its name in pictures, its light and shadow map.
struct Case<'a> {
    scene: &'a SuiteScene,
    name: String,
    light: &'a str,
    shadow_map: u32,
}

impl Case<'_> {
    /// A method's row: its frame against the reference.
    fn row(&self, method: &str, mut timings: Timings, frame: &FrameOutput, reference: &FrameOutput) -> Row {
        timings.total_ms = timings.phases.iter().map(|p| p.cpu_ms).sum();
        Row {
            scene: self.scene.label.clone(),
            real_model: self.scene.real,
            case: self.name.clone(),
            light: self.light.into(),
            width: frame.width,
            height: frame.height,
            shadow_map: self.shadow_map,
            method: method.into(),
            timings,
            ratio_to_hard: None,
            quality: quality::compare(frame, reference, 0.0),
            counters: frame.counters.clone(),
        }
    }
}

#[cfg(test)]
mod tests;
