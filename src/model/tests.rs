//! The model's fit, its choice under a budget, its error look-up and its storage, on made-up
//! measurements (the measurement itself runs on the device: tests/render.rs).

use super::measure::fit;
use super::*;
use crate::job::auto::AutoBudget;

fn features(pixels: u64, triangles: u64, texels: u64, light: &str) -> Features {
    let light = light.into();
    Features { pixels, texels, map_share: 1.0, triangles, triangles_known: true, light, scene: Some("torus".into()), pace: 1.0 }
}

/// A measured time of a white `torus` job.
fn timed(pixels: u64, triangles: u64, texels: u64, ms: f64) -> TimePoint {
    TimePoint { scene: "torus".into(), light: "white".into(), pixels, texels, triangles, map_share: 1.0, ms }
}

#[test]
fn the_fit_finds_the_costs_it_was_made_from() {
    let truth = Cost { base_ms: 12.0, per_mpixel: 300.0, per_mtriangle: 40.0, per_mtexel: 0.0, per_mtexel_whole: 0.0 };
    let mut samples = Vec::new();
    for pixels in [19_200, 76_800, 307_200] {
        for triangles in [2_000, 9_000, 30_000] {
            for texels in [1 << 18, 1 << 20] {
                samples.push(timed(pixels, triangles, texels, truth.ms(features(pixels, triangles, texels, "white").vector(false))));
            }
        }
    }
    let fitted = fit(samples.iter(), false);
    for (got, want) in fitted.as_array().iter().zip(truth.as_array()) {
        assert!((got - want).abs() < 1e-6 * want.max(1.0), "{fitted:?} against {truth:?}");
    }
}

#[test]
fn a_cropping_method_is_fitted_and_predicted_on_the_texels_it_draws() {
    // Maps cost by the texels drawn, and a little by the whole map's: a view cropped to a
    // fifth of each map draws a fifth.
    let truth = Cost { base_ms: 5.0, per_mpixel: 200.0, per_mtriangle: 3_000.0, per_mtexel: 50.0, per_mtexel_whole: 8.0 };
    let mut samples = Vec::new();
    for (triangles, share) in [(3_000, 1.0), (9_000, 1.0), (30_000, 1.0), (6_000, 0.2)] {
        for pixels in [19_200, 307_200] {
            for texels in [1 << 18, 1 << 20] {
                let drawn = Features { map_share: share, ..features(pixels, triangles, texels, "white") };
                samples.push(TimePoint { map_share: share, ..timed(pixels, triangles, texels, truth.ms(drawn.vector(true))) });
            }
        }
    }
    let fitted = fit(samples.iter(), true);
    for (got, want) in fitted.as_array().iter().zip(truth.as_array()) {
        assert!((got - want).abs() < 1e-6 * want.max(1.0), "{fitted:?} against {truth:?}");
    }
    // Predicted: the reference's maps shrink with the crop, `hard`'s map does not.
    let costs: Costs = [("white".to_owned(), truth)].into();
    let job = |share| Features { map_share: share, ..features(76_800, 6_000, 1 << 20, "white") };
    let reference = Candidate { cost: costs.clone(), ..candidate("reference:samples=64", Costs::new(), 0.01) };
    let hard = Candidate { cost: costs, ..candidate("hard", Costs::new(), 0.2) };
    assert!(reference.cropped() && !hard.cropped());
    let not_cropped = Candidate { cost: reference.cost.clone(), ..candidate("reference:crop=false", Costs::new(), 0.01) };
    assert!(!not_cropped.cropped());
    assert!((reference.ms(&job(1.0)) - reference.ms(&job(0.2)) - 0.8 * 50.0 * 1.048_576).abs() < 1e-9);
    assert_eq!(hard.ms(&job(1.0)), hard.ms(&job(0.2)));
}

#[test]
fn no_cost_term_is_fitted_negative() {
    // Times that fall with the pixels: least squares alone would give a negative term.
    let samples: Vec<_> = [(19_200, 30.0), (76_800, 29.0), (307_200, 28.0)].map(|(px, ms)| timed(px, 1_000, 1 << 20, ms)).into();
    assert!(fit(samples.iter(), false).as_array().iter().all(|c| *c >= 0.0));
}

fn candidate(label: &str, cost: Costs, error: f64) -> Candidate {
    let errors = [("white", 1.0), ("stripes", 1.5), ("flame", 2.0)]
        .into_iter()
        .flat_map(|(light, coloured)| {
            [("torus", 1.0), ("terrain", 2.0)].map(|(scene, worse)| ErrorPoint {
                scene: scene.into(),
                light: light.into(),
                pixels: 19_200,
                error: error * worse * coloured,
            })
        })
        .collect();
    Candidate { label: label.into(), method: MethodSpec::parse(label).unwrap(), cost, errors, errors_measured: true, times: vec![] }
}

fn model() -> Model {
    let ms = |base_ms| -> Costs {
        [("white", 1.0), ("stripes", 1.5), ("flame", 1.2)]
            .map(|(light, more)| (light.to_owned(), Cost { base_ms: base_ms * more, ..Cost::default() }))
            .into()
    };
    Model {
        key: ModelKey { adapter: "a".into(), driver: "d".into(), build: "b".into() },
        source: "measured".into(),
        measured_unix_ms: 0,
        measure_seconds: 0.0,
        candidates: vec![
            candidate("hard", ms(10.0), 0.2),
            candidate("wedges", ms(40.0), 0.03),
            candidate("reference:samples=64", ms(100.0), 0.02),
            candidate("reference:samples=256", ms(400.0), 0.01),
        ],
    }
}

#[test]
fn auto_takes_the_most_faithful_in_time_and_the_cheapest_in_error() {
    let model = model();
    let f = features(19_200, 1_000, 1 << 20, "white");
    let choose = |max_ms, max_error| model.choose(&AutoBudget { max_ms, max_error }, &f).map(|(c, _)| c.label);
    // The margin: 100 ms × 1.25 does not fit 120 ms.
    assert_eq!(choose(Some(120.0), None).unwrap(), "wedges");
    assert_eq!(choose(Some(125.0), None).unwrap(), "reference:samples=64");
    assert_eq!(choose(None, Some(0.03)).unwrap(), "reference:samples=64");
    assert_eq!(choose(None, Some(0.04)).unwrap(), "wedges");
    assert_eq!(choose(Some(1000.0), Some(0.5)).unwrap(), "hard");
    // Nothing fits: the field, and the closest candidate named.
    let unmet = model.choose(&AutoBudget { max_ms: Some(5.0), max_error: None }, &f).unwrap_err();
    assert_eq!((unmet.field, unmet.closest.as_str()), ("method.max_ms", "hard"));
    let unmet = model.choose(&AutoBudget { max_ms: Some(200.0), max_error: Some(0.005) }, &f).unwrap_err();
    assert_eq!((unmet.field, unmet.closest.as_str()), ("method.max_error", "reference:samples=64"));
    assert!(unmet.message.contains("reference:samples=64"), "{}", unmet.message);
}

#[test]
fn a_users_scene_is_predicted_by_the_worst_kind() {
    let model = model();
    let mut f = features(19_200, 1_000, 1 << 20, "white");
    assert_eq!(model.candidates[1].error(&f), 0.03);
    f.scene = None;
    assert_eq!(model.candidates[1].error(&f), 0.06);
    f.scene = Some("columns".into());
    assert_eq!(model.candidates[1].error(&f), 0.06, "a built-in kind the suite did not measure counts as unknown");
}

#[test]
fn a_light_the_suite_did_not_measure_is_predicted_as_the_worst_coloured_one() {
    let model = model();
    let wedges = &model.candidates[1];
    let mut f = features(19_200, 1_000, 1 << 20, "stripes");
    assert_eq!((wedges.ms(&f), wedges.error(&f)), (60.0, 0.045));
    f.light = USER_IMAGE.into();
    assert_eq!((wedges.ms(&f), wedges.error(&f)), (60.0, 0.06), "stripes' time, flame's error: the worst of each");
}

#[test]
fn errors_are_interpolated_over_log_pixels_and_held_at_the_ends() {
    let points = [(10_000, 0.04), (1_000_000, 0.02)];
    assert_eq!(interpolate_log(&points, 1_000), 0.04);
    assert_eq!(interpolate_log(&points, 4_000_000), 0.02);
    assert!((interpolate_log(&points, 100_000) - 0.03).abs() < 1e-12);
}

#[test]
fn the_shipped_model_has_every_candidate_and_a_stored_one_is_read_back_for_its_key_only() {
    let shipped = Model::shipped();
    assert_eq!(shipped.source, "default");
    let labels: Vec<&str> = shipped.candidates.iter().map(|c| c.label.as_str()).collect();
    for label in measure::CANDIDATES.iter().copied().chain(["reference:samples=1024"]) {
        assert!(labels.contains(&label), "{label} missing from the shipped model: {labels:?}");
    }
    let dir = std::env::temp_dir().join(format!("penumbra-model-{}", std::process::id()));
    let model = model();
    save(&dir, &model).unwrap();
    assert_eq!(load(&dir, &model.key), Some(model.clone()));
    let other = ModelKey { build: "another build".into(), ..model.key.clone() };
    assert_eq!(load(&dir, &other), None);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn the_pace_follows_the_devices_recent_renders() {
    let pace = Pace::default();
    // Too few renders to say: the model as fitted.
    for _ in 0..PACE_FIRST - 1 {
        pace.observe(100.0, 150.0);
    }
    assert_eq!(pace.factor(), 1.0);
    pace.observe(100.0, 150.0);
    assert_eq!(pace.factor(), 1.5);
    // A render unlike the rest moves the median little; a slower minute moves it all.
    pace.observe(100.0, 900.0);
    assert_eq!(pace.factor(), 1.5);
    for _ in 0..PACE_WINDOW {
        pace.observe(50.0, 40.0);
    }
    assert_eq!(pace.observed(), PACE_WINDOW);
    assert!((pace.factor() - 0.8).abs() < 1e-12);
    // Bounded both ways, and blind to renders that say nothing.
    for _ in 0..PACE_WINDOW {
        pace.observe(10.0, 1_000.0);
        pace.observe(0.0, 10.0);
        pace.observe(10.0, f64::NAN);
    }
    assert_eq!(pace.factor(), PACE_LIMIT);
    // Every time predicted follows it; errors do not.
    let model = model();
    let at = features(76_800, 10_000, 1 << 20, "white");
    let (fitted, paced) = (model.predictions(&at), model.predictions(&Features { pace: 1.5, ..at.clone() }));
    for ((_, a), (_, b)) in fitted.iter().zip(&paced) {
        assert!((b.ms - 1.5 * a.ms).abs() < 1e-9 && a.error == b.error);
    }
}

/// The shipped model's costs are what this build fits to its times: a change of the fit
/// reaches it too (`PENUMBRA_BLESS=1 cargo test --release --lib shipped_model` fits it again
/// and writes `default.json`).
#[test]
fn the_shipped_model_is_fitted_as_this_build_fits() {
    let shipped: Model = serde_json::from_str(SHIPPED).unwrap();
    let mut refitted = shipped.clone();
    super::measure::refit(&mut refitted);
    if std::env::var_os("PENUMBRA_BLESS").is_some() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/model/default.json");
        std::fs::write(path, serde_json::to_string_pretty(&refitted).unwrap()).unwrap();
        return;
    }
    assert_eq!(shipped.candidates.len(), refitted.candidates.len());
    for (stored, fitted) in shipped.candidates.iter().zip(&refitted.candidates) {
        assert_eq!(stored.cost.keys().collect::<Vec<_>>(), fitted.cost.keys().collect::<Vec<_>>(), "{}", stored.label);
        for (light, cost) in &stored.cost {
            for (a, b) in cost.as_array().iter().zip(fitted.cost[light].as_array()) {
                assert!(
                    (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                    "{} under {light}: {cost:?} stored, {:?} fitted",
                    stored.label,
                    fitted.cost[light]
                );
            }
        }
    }
}
