//! The suite's two comparisons besides each method against the reference: jump against
//! standard flooding (Rong & Tan 2006's experiment), and each coloured light against its white
//! twin (what the colours cost a method).

use serde::Serialize;

use super::options::parse_named;
use super::Row;
use crate::render::FrameOutput;

/// The flooding experiment of Rong & Tan 2006 (Fig. 4, Fig. 7): over the pixels either
/// variant puts in a penumbra, the fractions whose visibility differs by < 0.05, 0.05–0.1,
/// 0.1–0.2 and ≥ 0.2 (largest channel), and the fraction in a penumbra in one only (parity).
#[derive(Debug, Clone, Serialize)]
pub struct FloodingComparison {
    pub case: String,
    pub method: String,
    pub penumbra_pixels: usize,
    pub below_005: f64,
    pub below_010: f64,
    pub below_020: f64,
    pub at_least_020: f64,
    pub parity: f64,
}

/// A light of the suite: its label (`name[:key=value…]`), what identifies its image, and the
/// label of the light in the suite that is its white twin (itself when it is white).
#[derive(Debug, Clone)]
pub struct SuiteLight {
    pub label: String,
    pub(super) identity: LightIdentity,
    pub(super) twin: String,
}

/// Images that light a scene the same way: a uniform image by its one emission, whatever its
/// size (`white` and the white twin of `stripes`), any other by its fingerprint.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum LightIdentity {
    Uniform([u32; 3]),
    Image(u64),
}

impl LightIdentity {
    pub(super) fn of(image: &crate::light::LightImage) -> Self {
        if image.is_uniform() {
            LightIdentity::Uniform(image.emission(0, 0).to_array().map(f32::to_bits))
        } else {
            LightIdentity::Image(image.fingerprint())
        }
    }
}

/// The listed lights, plus (with `colored`) each one's white twin where no listed light has
/// the twin's image.
pub(super) fn with_white_twins(labels: &[String], colored: bool) -> anyhow::Result<Vec<SuiteLight>> {
    let image = |label: &str| -> anyhow::Result<crate::light::LightImage> {
        let (name, params) = parse_named(label)?;
        crate::light::LightImage::builtin(&name, &params, "light").map_err(|e| anyhow::anyhow!("light `{label}`: {}", e.message))
    };
    let mut lights: Vec<SuiteLight> = labels
        .iter()
        .map(|label| Ok(SuiteLight { label: label.clone(), identity: LightIdentity::of(&image(label)?), twin: String::new() }))
        .collect::<anyhow::Result<_>>()?;
    for k in 0..lights.len() {
        let twin = LightIdentity::of(&image(&lights[k].label)?.white_twin());
        let label = match lights.iter().find(|l| l.identity == twin) {
            Some(found) => found.label.clone(),
            None if colored => {
                let (name, _) = parse_named(&lights[k].label)?;
                let label = format!("{name}:white=true");
                lights.push(SuiteLight { label: label.clone(), identity: twin, twin: label.clone() });
                label
            }
            None => String::new(),
        };
        lights[k].twin = label;
    }
    Ok(lights)
}

/// A method's penumbra visibility error (mean |V − Vref|, and per channel) under a coloured
/// light and under its white twin, in one scene, and their ratio.
#[derive(Debug, Clone, Serialize)]
pub struct ColoredRatio {
    pub scene: String,
    pub light: String,
    pub twin: String,
    pub method: String,
    pub mae: f64,
    pub mae_rgb: [f64; 3],
    pub twin_mae: f64,
    pub ratio: f64,
}

pub(super) fn colored_ratios(rows: &[Row], lights: &[SuiteLight]) -> Vec<ColoredRatio> {
    let mut out = Vec::new();
    for row in rows.iter().filter(|r| r.method != "reference") {
        let Some(light) = lights.iter().find(|l| l.label == row.light && l.twin != l.label && !l.twin.is_empty()) else { continue };
        let twin = rows.iter().find(|t| {
            t.scene == row.scene
                && t.light == light.twin
                && t.method == row.method
                && (t.width, t.height, t.shadow_map) == (row.width, row.height, row.shadow_map)
        });
        if let Some(twin) = twin {
            let (mae, twin_mae) = (row.quality.visibility.penumbra.mae, twin.quality.visibility.penumbra.mae);
            out.push(ColoredRatio {
                scene: row.scene.clone(),
                light: row.light.clone(),
                twin: twin.light.clone(),
                method: row.method.clone(),
                mae,
                mae_rgb: row.quality.visibility.penumbra.mae_rgb,
                twin_mae,
                ratio: if twin_mae > 0.0 { mae / twin_mae } else { f64::NAN },
            });
        }
    }
    out
}

/// The label of the jump-flooding twin of a standard-flooding method label, if it is one.
pub(super) fn jump_twin(label: &str) -> Option<String> {
    label.contains("flooding=\"standard\"").then(|| label.replace(":flooding=\"standard\"", ""))
}

pub fn compare_flooding(case: &str, method: &str, jump: &FrameOutput, standard: &FrameOutput) -> FloodingComparison {
    let in_penumbra = |v: &[f32; 3]| v.iter().any(|&c| c > 0.0 && c < 1.0);
    let (a, b) = (jump.visibility.as_ref().expect("visibility"), standard.visibility.as_ref().expect("visibility"));
    let mut bins = [0usize; 4];
    let (mut total, mut parity) = (0usize, 0usize);
    for (x, y) in a.iter().zip(b) {
        let (px, py) = (in_penumbra(x), in_penumbra(y));
        if !(px || py) {
            continue;
        }
        total += 1;
        if px != py {
            parity += 1;
        }
        let d = (0..3).map(|k| (x[k] - y[k]).abs()).fold(0.0, f32::max);
        bins[if d < 0.05 {
            0
        } else if d < 0.1 {
            1
        } else if d < 0.2 {
            2
        } else {
            3
        }] += 1;
    }
    let f = |n: usize| if total > 0 { n as f64 / total as f64 } else { 0.0 };
    FloodingComparison {
        case: case.into(),
        method: method.into(),
        penumbra_pixels: total,
        below_005: f(bins[0]),
        below_010: f(bins[1]),
        below_020: f(bins[2]),
        at_least_020: f(bins[3]),
        parity: f(parity),
    }
}
