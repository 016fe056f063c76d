//! `penumbra eval`'s plots (SVG through `plotters`): a parameter sweep's cost and error, and
//! each method's cost against the shadow map's resolution, the output's size or the scene's
//! triangles.

use std::path::{Path, PathBuf};

use super::pictures::sanitize;
use super::tables::method_ms;
use super::{Row, Sweep};

/// Cost (method phase, ms) and penumbra RMSE of V against the swept value, as an SVG plot.
pub(super) fn plot_sweep(out: &Path, case: &str, sweep: &Sweep, rows: &[Row]) -> anyhow::Result<PathBuf> {
    use plotters::prelude::*;
    let points: Vec<(f64, f64, f64)> = sweep
        .points
        .iter()
        .filter_map(|(x, label)| rows.iter().find(|r| &r.method == label).map(|r| (*x, method_ms(r), r.quality.visibility.penumbra.rmse)))
        .collect();
    let path = out.join(format!("sweep-{case}-{}-{}.svg", sanitize(&sweep.method), sanitize(&sweep.param)));
    let (x_min, x_max) = points.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let ms_max = points.iter().map(|p| p.1).fold(0.0, f64::max) * 1.1 + 1e-3;
    let err_max = points.iter().map(|p| p.2).fold(0.0, f64::max) * 1.1 + 1e-3;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 420)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{}: {} sweep, {case}", sweep.method, sweep.param), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(56)
            .right_y_label_area_size(56)
            .build_cartesian_2d(x_min..x_max.max(x_min + 1e-9), 0.0..ms_max)?
            .set_secondary_coord(x_min..x_max.max(x_min + 1e-9), 0.0..err_max);
        chart.configure_mesh().x_desc(sweep.param.as_str()).y_desc("method ms").draw()?;
        chart.configure_secondary_axes().y_desc("V RMSE in the penumbra").draw()?;
        chart
            .draw_series(LineSeries::new(points.iter().map(|p| (p.0, p.1)), &BLUE).point_size(3))?
            .label("method ms")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
        chart
            .draw_secondary_series(LineSeries::new(points.iter().map(|p| (p.0, p.2)), &RED).point_size(3))?
            .label("V RMSE (penumbra)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED));
        chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
        root.present()?;
    }
    std::fs::write(&path, svg)?;
    Ok(path)
}

/// Method cost against shadow-map resolution (or output pixels), one line per method — the
/// JFA paper's Fig. 8 (cost follows the flooded grid's size). Each method's cost against `x_of` over `rows` (the reference left out), as `name` in `out`.
/// With `wall`, the method phase's wall time (CPU set-up included) rather than its GPU time.
pub(super) fn plot_scaling(
    out: &Path,
    name: &str,
    title: &str,
    x_desc: &str,
    rows: &[&Row],
    x_of: fn(&Row) -> f64,
    wall: bool,
) -> anyhow::Result<PathBuf> {
    use plotters::prelude::*;
    let y_of = |r: &Row| if wall { r.timings.get(crate::timing::PhaseName::Method).map_or(0.0, |p| p.cpu_ms) } else { method_ms(r) };
    let rows: Vec<&Row> = rows.iter().copied().filter(|r| r.method != "reference").collect();
    let mut methods: Vec<&str> = rows.iter().map(|r| r.method.as_str()).collect();
    methods.dedup();
    methods.sort_unstable();
    methods.dedup();
    let (x_min, x_max) = rows.iter().fold((f64::MAX, f64::MIN), |(a, b), r| (a.min(x_of(r)), b.max(x_of(r))));
    let y_max = rows.iter().map(|r| y_of(r)).fold(0.0, f64::max) * 1.1 + 1e-3;
    let path = out.join(name);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 420)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("method cost, {title}"), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(56)
            .build_cartesian_2d(x_min..x_max.max(x_min + 1e-9), 0.0..y_max)?;
        chart.configure_mesh().x_desc(x_desc).y_desc(if wall { "method wall ms" } else { "method ms" }).draw()?;
        for (k, method) in methods.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            let mut points: Vec<(f64, f64)> = rows.iter().filter(|r| r.method == *method).map(|r| (x_of(r), y_of(r))).collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(points, color).point_size(3))?
                .label(*method)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color));
        }
        chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
        root.present()?;
    }
    std::fs::write(&path, svg)?;
    Ok(path)
}

/// `eval --budgets`' plot: each render's measured time and error against the model's
/// prediction, and each progressive round's measured error against its own estimate, in log
/// scale, with the line of a perfect prediction and the band of the goal around it (±25 %,
/// ±30 %).
pub(super) fn plot_budgets(
    out: &Path,
    rendered: &[super::budgets::BudgetRow],
    rounds: &[super::budgets::RoundRow],
) -> anyhow::Result<PathBuf> {
    use plotters::prelude::*;
    let path = out.join("budgets.svg");
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1380, 460)).into_drawing_area();
        root.fill(&WHITE)?;
        let panels = root.split_evenly((1, 3));
        let pairs = |of: fn(&super::budgets::BudgetRow) -> Option<(f64, f64)>| rendered.iter().filter_map(of).collect::<Vec<_>>();
        // (what, (predicted or estimated, measured) pairs, the band counted as right)
        let quantities = [
            ("time, ms", "predicted", pairs(|r| Some((r.predicted_ms, r.measured_ms?))), 0.25f64),
            ("penumbra error", "predicted", pairs(|r| Some((r.predicted_error, r.measured_error?))), 0.25),
            ("progressive rounds' error", "estimated", rounds.iter().map(|r| (r.estimated, r.measured)).collect(), 0.30),
        ];
        for (panel, (what, by, pairs, band)) in panels.iter().zip(quantities) {
            let points: Vec<(f64, f64)> = pairs.iter().filter(|(p, m)| *p > 0.0 && *m > 0.0).map(|(p, m)| (p.log10(), m.log10())).collect();
            let (low, high) = points.iter().fold((f64::MAX, f64::MIN), |(a, b), (p, m)| (a.min(p.min(*m)), b.max(p.max(*m))));
            let (low, high) = if low < high { (low - 0.1, high + 0.1) } else { (0.0, 1.0) };
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("{what}: measured against {by}"), ("sans-serif", 16))
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(56)
                .build_cartesian_2d(low..high, low..high)?;
            chart.configure_mesh().x_desc(format!("log10 {by} {what}")).y_desc(format!("log10 measured {what}")).draw()?;
            for (offset, style) in
                [(0.0, BLACK.stroke_width(1)), ((1.0 + band).log10(), RED.stroke_width(1)), ((1.0 - band).log10(), RED.stroke_width(1))]
            {
                chart.draw_series(LineSeries::new([(low, low + offset), (high, high + offset)], style))?;
            }
            chart.draw_series(points.iter().map(|&(p, m)| Circle::new((p, m), 3, BLUE.filled())))?;
        }
        root.present()?;
    }
    std::fs::write(&path, svg)?;
    Ok(path)
}
