//! `penumbra eval`'s tables: `results.md` (cost, quality against the reference, the flooding
//! experiment, the subdivision histogram, a sweep), `results.csv` and `results.json`.

use std::fmt::Write as _;
use std::path::Path;

use super::{EvalReport, Row, Sweep};
use crate::methods::chun_oh::{PIXELS_SUBDIVIDED, SPLITS_FORCED_BY_LIGHT};
use crate::methods::filter::BACKGROUND_PIXELS;
use crate::methods::{CounterKey, Counters};
use crate::render::method::ERROR_ESTIMATE;
use crate::timing::{PhaseName, Timings};

/// The render phases the cost tables list, in pass order.
const PHASE_COLUMNS: [PhaseName; 5] = [PhaseName::ShadowMap, PhaseName::Gbuffer, PhaseName::E0, PhaseName::Method, PhaseName::Composite];

/// A row's time per phase in `PHASE_COLUMNS` order.
fn phase_cells(t: &Timings) -> Vec<String> {
    PHASE_COLUMNS.iter().map(|&phase| gpu(t, phase)).collect()
}

fn gpu(t: &Timings, phase: PhaseName) -> String {
    t.get(phase).and_then(|p| p.gpu_ms.or(Some(p.cpu_ms))).map(|ms| format!("{ms:.1}")).unwrap_or_else(|| "-".into())
}

fn psnr(db: f64) -> String {
    if db.is_finite() {
        format!("{db:.1}")
    } else {
        "∞".into()
    }
}

fn counters_text(counters: &Counters) -> String {
    counters.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(" ")
}

/// The method phase's time of a row: GPU time where measured, else wall time.
pub(super) fn method_ms(row: &Row) -> f64 {
    row.timings.get(PhaseName::Method).map(|p| p.gpu_ms.unwrap_or(p.cpu_ms)).unwrap_or(0.0)
}

/// Writes `results.md`, `results.csv` and `results.json` into `out`.
pub(super) fn write_tables(out: &Path, report: &EvalReport, methods: &[String], sweep: Option<&Sweep>) -> anyhow::Result<()> {
    let mut md = String::new();
    write_preamble(&mut md, report, methods)?;
    write_cost(&mut md, report)?;
    write_quality(&mut md, report)?;
    write_real_models(&mut md, report)?;
    write_colored(&mut md, report)?;
    write_flooding(&mut md, report)?;
    write_subdivision(&mut md, report)?;
    write_error_estimates(&mut md, report)?;
    write_contact(&mut md, report)?;
    if let Some(sweep) = sweep {
        write_sweep(&mut md, report, sweep)?;
    }
    std::fs::write(out.join("results.md"), md)?;
    std::fs::write(out.join("results.csv"), csv(report)?)?;
    std::fs::write(out.join("results.json"), serde_json::to_vec_pretty(report)?)?;
    Ok(())
}

/// What the tables measure and how to read them.
fn write_preamble(md: &mut String, report: &EvalReport, methods: &[String]) -> std::fmt::Result {
    let a = &report.adapter;
    writeln!(md, "# penumbra eval\n")?;
    writeln!(md, "Adapter: {} ({}, {}), GPU timestamps: {}.\n", a.name, a.backend, a.device_type, a.timestamps)?;
    writeln!(md, "Times are per phase in ms — GPU time where timestamps exist, else wall time — and the wall total;")?;
    if report.repeat > 1 {
        writeln!(md, "each the median of {} runs of every method, interleaved;", report.repeat)?;
    }
    writeln!(md, "`× hard` is the row's total over `hard`'s in the same case, the figure to quote. Quality is against")?;
    writeln!(md, "`reference` (same scene, view, light, size): visibility (V) and displayed colour, whole frame and")?;
    writeln!(
        md,
        "penumbra only (pixels with 0 < Vref < 1). Contact sheets `sheet-*.png`: reference then {} left to",
        if methods.is_empty() { "no method".into() } else { methods.join(", ") }
    )?;
    writeln!(md, "right; below each, |V − Vref| (magma, black = 0, yellow = 1), below the reference Vref itself.\n")
}

/// Time per phase and the ratio to `hard`, per row.
fn write_cost(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    writeln!(md, "## Cost\n")?;
    writeln!(
        md,
        "| scene | light | size | map res | method | {} | total ms | × hard | counters |",
        PHASE_COLUMNS.map(PhaseName::as_str).join(" ms | ") + " ms"
    )?;
    writeln!(md, "|---|---|---|---:|---|{}---:|---:|---|", "---:|".repeat(PHASE_COLUMNS.len()))?;
    for r in &report.rows {
        writeln!(
            md,
            "| {} | {} | {}×{} | {} | {} | {} | {:.1} | {} | {} |",
            r.scene,
            r.light,
            r.width,
            r.height,
            r.shadow_map,
            r.method,
            phase_cells(&r.timings).join(" | "),
            r.timings.total_ms,
            r.ratio_to_hard.map(|x| format!("{x:.2}")).unwrap_or_else(|| "-".into()),
            counters_text(&r.counters)
        )?;
    }
    Ok(())
}

/// Visibility and colour against the reference, whole frame and penumbra only.
fn write_quality(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    writeln!(md, "\n## Quality against reference\n")?;
    writeln!(md, "| scene | light | size | method | penumbra px | V RMSE | V MAE | V PSNR | V SSIM | V FLIP | V RMSE (penumbra) | V MAE (penumbra) | V PSNR (penumbra) | V SSIM (penumbra) | V FLIP (penumbra) | colour RMSE | colour PSNR | colour SSIM | colour FLIP | colour RMSE (penumbra) | colour FLIP (penumbra) |")?;
    writeln!(md, "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    for r in &report.rows {
        let (v, c) = (&r.quality.visibility, &r.quality.color);
        writeln!(
            md,
            "| {} | {} | {}×{} | {} | {} | {:.4} | {:.4} | {} | {:.3} | {:.4} | {:.4} | {:.4} | {} | {:.3} | {:.4} | {:.4} | {} | {:.3} | {:.4} | {:.4} | {:.4} |",
            r.scene, r.light, r.width, r.height, r.method, r.quality.penumbra_pixels,
            v.whole.rmse, v.whole.mae, psnr(v.whole.psnr_db), v.whole.ssim, v.whole.flip,
            v.penumbra.rmse, v.penumbra.mae, psnr(v.penumbra.psnr_db), v.penumbra.ssim, v.penumbra.flip,
            c.whole.rmse, psnr(c.whole.psnr_db), c.whole.ssim, c.whole.flip, c.penumbra.rmse, c.penumbra.flip
        )?;
    }
    Ok(())
}

/// The real models: per light, each method's mean and worst penumbra error over them, how often
/// it does worse than `pcss` on the same model, its mean on the built-ins beside it; then every
/// model's error per method, and the models left out.
fn write_real_models(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    if report.real_models.is_empty() && report.skipped.is_empty() {
        return Ok(());
    }
    writeln!(md, "\n## Real models\n")?;
    writeln!(md, "Mean |V − Vref| over the reference's penumbra, per model (each staged on a floor with the fitted")?;
    writeln!(md, "camera and light). `> 1.25 × pcss`, `> 1.5 × pcss`: models where the method's error exceeds")?;
    writeln!(md, "`pcss`'s on the same model by that factor. `real / built-in`: the mean over real models over")?;
    writeln!(md, "the mean over the built-in scenes of this run. `worst-{{light}}-{{method}}.png`: the worst models,")?;
    writeln!(md, "reference and method, with Vref and |V − Vref| under them. A model whose reference has less")?;
    writeln!(
        md,
        "penumbra than {} % of the frame is listed below but left out of the summary.\n",
        super::real::MIN_PENUMBRA_SHARE * 100.0
    )?;
    writeln!(
        md,
        "| light | method | models | mean | worst | worst model | > 1.25 × pcss | > 1.5 × pcss | built-in mean | real / built-in |"
    )?;
    writeln!(md, "|---|---|---:|---:|---:|---|---:|---:|---:|---:|")?;
    for s in &report.real_models {
        writeln!(
            md,
            "| {} | {} | {} | {:.4} | {:.4} | {} | {} | {} | {} | {} |",
            s.light,
            s.method,
            s.models,
            s.mean,
            s.worst,
            s.worst_model,
            s.over_baseline_125,
            s.over_baseline_150,
            s.builtin_mean.map_or_else(|| "-".into(), |m| format!("{m:.4}")),
            s.over_builtin().map_or_else(|| "-".into(), |r| format!("{r:.2}")),
        )?;
    }
    let mut methods: Vec<&str> = Vec::new();
    for s in &report.real_models {
        if !methods.contains(&s.method.as_str()) {
            methods.push(&s.method);
        }
    }
    writeln!(md, "\nPer model:\n")?;
    writeln!(md, "| model | light | penumbra px | {} |", methods.join(" | "))?;
    writeln!(md, "|---|---|---:|{}", "---:|".repeat(methods.len()))?;
    for reference in report.rows.iter().filter(|r| r.real_model && r.method == "reference") {
        let cells: Vec<String> = methods
            .iter()
            .map(|m| {
                report
                    .rows
                    .iter()
                    .find(|r| r.case == reference.case && r.method == *m)
                    .map_or_else(|| "-".into(), |r| format!("{:.4}", r.quality.visibility.penumbra.mae))
            })
            .collect();
        writeln!(md, "| {} | {} | {} | {} |", reference.scene, reference.light, reference.quality.penumbra_pixels, cells.join(" | "))?;
    }
    if !report.skipped.is_empty() {
        writeln!(md, "\nLeft out:\n")?;
        for (model, why) in &report.skipped {
            writeln!(md, "- {model}: {why}")?;
        }
    }
    Ok(())
}

/// What the light's colours cost each method (`--colored`): penumbra error per channel under
/// the coloured light, under its white twin, and the ratio — with the mean ratio per method
/// over the scenes of each light, and over every coloured light.
fn write_colored(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    if report.colored.is_empty() {
        return Ok(());
    }
    writeln!(md, "\n## Colour\n")?;
    writeln!(md, "Mean |V − Vref| over the reference's penumbra under each coloured light (per channel, and")?;
    writeln!(md, "all three), under the light's white twin (the same shape in white), and their ratio:")?;
    writeln!(md, "1 means the colours cost the method nothing; a gray method cannot get below about")?;
    writeln!(md, "the error of exact gray visibility.\n")?;
    writeln!(md, "| scene | light | method | V MAE R | V MAE G | V MAE B | V MAE | white twin | V MAE (twin) | colored |")?;
    writeln!(md, "|---|---|---|---:|---:|---:|---:|---|---:|---:|")?;
    for c in &report.colored {
        writeln!(
            md,
            "| {} | {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {} | {:.4} | {:.2} |",
            c.scene, c.light, c.method, c.mae_rgb[0], c.mae_rgb[1], c.mae_rgb[2], c.mae, c.twin, c.twin_mae, c.ratio
        )?;
    }
    let mut methods: Vec<&str> = Vec::new();
    let mut lights: Vec<&str> = Vec::new();
    for c in &report.colored {
        if !methods.contains(&c.method.as_str()) {
            methods.push(&c.method);
        }
        if !lights.contains(&c.light.as_str()) {
            lights.push(&c.light);
        }
    }
    let mean = |f: &dyn Fn(&&super::ColoredRatio) -> bool| {
        let chosen: Vec<f64> = report.colored.iter().filter(f).map(|c| c.ratio).filter(|r| r.is_finite()).collect();
        if chosen.is_empty() {
            "-".to_owned()
        } else {
            format!("{:.2}", chosen.iter().sum::<f64>() / chosen.len() as f64)
        }
    };
    writeln!(md, "\nMean ratio over the scenes:\n")?;
    writeln!(md, "| method | {} | all |", lights.join(" | "))?;
    writeln!(md, "|---|{}---:|", "---:|".repeat(lights.len()))?;
    for method in &methods {
        let cells: Vec<String> =
            lights.iter().map(|light| mean(&|c: &&super::ColoredRatio| c.method == *method && c.light == *light)).collect();
        writeln!(md, "| {method} | {} | {} |", cells.join(" | "), mean(&|c: &&super::ColoredRatio| c.method == *method))?;
    }
    Ok(())
}

/// Jump against standard flooding (Rong & Tan 2006, Fig. 4 and 7), when the suite ran both.
fn write_flooding(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    if !report.flooding.is_empty() {
        writeln!(md, "\n## Flooding experiment: jump against standard flooding\n")?;
        writeln!(md, "Over the pixels either variant puts in a penumbra (Rong & Tan 2006, Fig. 4 and 7): fractions by |ΔV|, and parity (in a penumbra in one only).\n")?;
        writeln!(md, "| case | method | penumbra px | < 0.05 | 0.05–0.1 | 0.1–0.2 | ≥ 0.2 | parity |")?;
        writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|")?;
        for f in &report.flooding {
            writeln!(
                md,
                "| {} | {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
                f.case, f.method, f.penumbra_pixels, f.below_005, f.below_010, f.below_020, f.at_least_020, f.parity
            )?;
        }
    }
    Ok(())
}

/// The error a method estimated for itself (`filtered`'s mean over the pixels it finds in
/// penumbra) against the one measured over the reference's penumbra, with their ratio.
fn write_error_estimates(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    // The truth's own row (measured against itself: no error) says nothing of its estimate.
    let measured = |r: &&Row| r.quality.visibility.penumbra.mae > 0.0;
    let estimated: Vec<(&Row, f64)> =
        report.rows.iter().filter(measured).filter_map(|r| ERROR_ESTIMATE.get(&r.counters).map(|e| (r, e))).collect();
    if estimated.is_empty() {
        return Ok(());
    }
    writeln!(md, "\n## Error estimates\n")?;
    writeln!(md, "The mean |V − Vref| a method estimated for its penumbra, against the V MAE measured over the reference's penumbra.\n")?;
    writeln!(md, "| scene | light | size | method | estimated | measured | estimated ÷ measured |")?;
    writeln!(md, "|---|---|---|---|---:|---:|---:|")?;
    let mut within = 0;
    for &(r, estimate) in &estimated {
        let measured = r.quality.visibility.penumbra.mae;
        let ratio = estimate / measured;
        within += usize::from((0.7..=1.3).contains(&ratio));
        writeln!(
            md,
            "| {} | {} | {}×{} | {} | {estimate:.4} | {measured:.4} | {ratio:.2} |",
            r.scene, r.light, r.width, r.height, r.method
        )?;
    }
    writeln!(md, "\nWithin ±30 %: {within} of {} rows.", estimated.len())
}

/// Every row's error next to the occluders' contacts (`quality::contact_mask`) beside its
/// error over the whole penumbra: a filter that bleeds across a contact shows there.
fn write_contact(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    let rows: Vec<&Row> = report.rows.iter().filter(|r| r.method != "reference").collect();
    if rows.is_empty() {
        return Ok(());
    }
    writeln!(md, "\n## Next to contacts\n")?;
    writeln!(md, "V MAE over the tenth of the reference's penumbra where it is narrowest in the world (next to the occluders' contacts), and over the whole penumbra.\n")?;
    writeln!(md, "| scene | light | size | method | V MAE (contact) | V MAE (penumbra) |")?;
    writeln!(md, "|---|---|---|---|---:|---:|")?;
    for r in rows {
        let q = &r.quality;
        writeln!(
            md,
            "| {} | {} | {}×{} | {} | {:.4} | {:.4} |",
            r.scene, r.light, r.width, r.height, r.method, q.contact_mae, q.visibility.penumbra.mae
        )?;
    }
    Ok(())
}

/// `chun-oh`'s subdivision histogram (Chun & Oh 2016, Table 2), when the suite ran it.
fn write_subdivision(md: &mut String, report: &EvalReport) -> std::fmt::Result {
    let subdivided: Vec<&Row> = report.rows.iter().filter(|r| PIXELS_SUBDIVIDED[0].get(&r.counters).is_some()).collect();
    if !subdivided.is_empty() {
        writeln!(md, "\n## Subdivision histogram\n")?;
        writeln!(md, "Pixels by how often `chun-oh` split their filter (Chun & Oh 2016, Table 2), with shares of the frame.\n")?;
        writeln!(
            md,
            "| scene | light | size | method | background | no subdivision | 1 subdivision | 2 subdivisions | splits forced by the light |"
        )?;
        writeln!(md, "|---|---|---|---|---:|---:|---:|---:|---:|")?;
        for r in subdivided {
            let total = f64::from(r.width) * f64::from(r.height);
            let cell = |key: CounterKey| {
                let n = key.get(&r.counters).unwrap_or(0.0);
                format!("{n:.0} ({:.2} %)", 100.0 * n / total)
            };
            writeln!(
                md,
                "| {} | {} | {}×{} | {} | {} | {} | {} | {} | {:.0} |",
                r.scene,
                r.light,
                r.width,
                r.height,
                r.method,
                cell(BACKGROUND_PIXELS),
                cell(PIXELS_SUBDIVIDED[0]),
                cell(PIXELS_SUBDIVIDED[1]),
                cell(PIXELS_SUBDIVIDED[2]),
                SPLITS_FORCED_BY_LIGHT.get(&r.counters).unwrap_or(0.0)
            )?;
        }
    }
    Ok(())
}

/// The rows of a parameter sweep, in the swept order.
fn write_sweep(md: &mut String, report: &EvalReport, sweep: &Sweep) -> std::fmt::Result {
    {
        writeln!(md, "\n## Sweep of `{}` in `{}`\n", sweep.param, sweep.method)?;
        writeln!(md, "Plots: `sweep-*.svg` (method ms and penumbra V RMSE against the value).\n")?;
        writeln!(md, "| scene | light | size | {} | method ms | total ms | V RMSE (penumbra) | counters |", sweep.param)?;
        writeln!(md, "|---|---|---|---:|---:|---:|---:|---|")?;
        for (x, label) in &sweep.points {
            for r in report.rows.iter().filter(|r| &r.method == label) {
                writeln!(
                    md,
                    "| {} | {} | {}×{} | {x} | {:.1} | {:.1} | {:.4} | {} |",
                    r.scene,
                    r.light,
                    r.width,
                    r.height,
                    method_ms(r),
                    r.timings.total_ms,
                    r.quality.visibility.penumbra.rmse,
                    counters_text(&r.counters)
                )?;
            }
        }
    }
    Ok(())
}

/// Every row with every phase, metric and counter, for spreadsheets.
fn csv(report: &EvalReport) -> Result<String, std::fmt::Error> {
    let mut csv = String::from("scene,light,width,height,shadow_map,method,total_ms,ratio_to_hard");
    for phase in PHASE_COLUMNS {
        write!(csv, ",{phase}_ms")?;
    }
    csv.push_str(",penumbra_pixels");
    for region in ["v_whole", "v_penumbra", "color_whole", "color_penumbra"] {
        for metric in ["rmse", "mae", "psnr_db", "ssim", "flip"] {
            write!(csv, ",{region}_{metric}")?;
        }
    }
    csv.push_str(",counters\n");
    for r in &report.rows {
        write!(
            csv,
            "{},{},{},{},{},{},{:.3},{},{},{}",
            r.scene,
            r.light,
            r.width,
            r.height,
            r.shadow_map,
            r.method,
            r.timings.total_ms,
            r.ratio_to_hard.map(|x| format!("{x:.4}")).unwrap_or_default(),
            phase_cells(&r.timings).join(","),
            r.quality.penumbra_pixels
        )?;
        for m in [r.quality.visibility.whole, r.quality.visibility.penumbra, r.quality.color.whole, r.quality.color.penumbra] {
            write!(
                csv,
                ",{:.6},{:.6},{},{:.6},{:.6}",
                m.rmse,
                m.mae,
                if m.psnr_db.is_finite() { format!("{:.3}", m.psnr_db) } else { "inf".into() },
                m.ssim,
                m.flip
            )?;
        }
        writeln!(csv, ",{}", counters_text(&r.counters).replace(' ', ";"))?;
    }
    Ok(csv)
}
