//! `penumbra eval`'s options and how their text is read: methods and scenes with parameters
//! (`name:key=value`), sizes, sweeps.

use std::path::PathBuf;

use anyhow::Context as _;
use serde_json::{Map, Value};

use crate::job::MethodSpec;
use crate::methods::REGISTRY;

/// What to run.
#[derive(Debug, Clone, clap::Args)]
pub struct EvalOptions {
    /// Scenes, comma-separated: built-in ones (`name[:key=value…]`), scene files (`.glb`,
    /// `.gltf`) and folders of them (the real-model suite: `deploy/real-models.sh`). A file is
    /// staged on a floor with the fitted camera and light (contract §3).
    #[arg(long, value_delimiter = ',', default_value = "torus,crowd,columns,terrain")]
    pub scenes: Vec<String>,
    /// Built-in light images, comma-separated, each optionally with parameters
    /// (`flame:white=true`, its white twin).
    #[arg(long, value_delimiter = ',', default_value = "white,stripes")]
    pub lights: Vec<String>,
    /// Also run each light's white twin (the same shape in white) where no listed light is
    /// it, and report every method's penumbra error under the coloured light over its error
    /// under the twin: what the colours cost each method.
    #[arg(long)]
    pub colored: bool,
    /// Methods, comma-separated, each optionally with parameters: `name:key=value:key=value`
    /// (values are JSON). Default: every registered method but `reference`.
    #[arg(long, value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Output sizes, comma-separated, as WIDTHxHEIGHT.
    #[arg(long, value_delimiter = ',', default_value = "512x384")]
    pub sizes: Vec<String>,
    /// Light samples of the reference.
    #[arg(long, default_value_t = 256)]
    pub samples: u32,
    /// Shadow-map resolutions, comma-separated (also the reference's sample maps). With
    /// several, every case runs at each, and `scaling-*.svg` plots cost against resolution.
    #[arg(long, value_delimiter = ',', default_value = "1024")]
    pub shadow_map: Vec<u32>,
    /// Folder for the results.
    #[arg(long, default_value = "eval")]
    pub out: PathBuf,
    /// Instead of the suite: measure this device's cost and quality model (what `auto` and
    /// `POST /v1/estimate` predict by; contract §5), print it as a table and write it to
    /// `model.json` and `model.md` in `--out`.
    #[arg(long)]
    pub model: bool,
    /// Instead of the suite: ask every case of it a range of `auto` budgets (time, as multiples
    /// of its cheapest prediction; error, 0.01 to 0.08), render each choice, and report how many
    /// budgets were kept and how close the predictions came (`budgets.md`; contract §5). Measures
    /// the model first unless `--model-file` gives one.
    #[arg(long)]
    pub budgets: bool,
    /// The model `--budgets` holds to its promises (`model.json` of `eval --model`).
    #[arg(long, requires = "budgets")]
    pub model_file: Option<PathBuf>,
    /// Sweep one numeric parameter of one method, e.g. `brabec:max_radius_texels=4,8,16,32`
    /// (other `key=value` parts stay fixed): adds one row per value and writes a table and a
    /// plot (`sweep-*.svg`) of cost and penumbra error against the value.
    #[arg(long)]
    pub sweep: Option<String>,
    /// Render every method this many times, round-robin, and report each phase's median
    /// time: these machines are noisy, and interleaving lets slow spells hit every method.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeat: u32,
}

/// A parameter sweep: the method label of each value, in order.
pub(super) struct Sweep {
    pub(super) method: String,
    pub(super) param: String,
    pub(super) points: Vec<(f64, String)>,
}

pub(super) fn parse_sweep(text: &str) -> anyhow::Result<Sweep> {
    let mut parts = text.split(':');
    let method = parts.next().unwrap_or_default().to_owned();
    let (mut fixed, mut swept) = (Vec::new(), None);
    for part in parts {
        let (key, values) = part.split_once('=').with_context(|| format!("sweep part `{part}` must be key=value"))?;
        if values.contains(',') {
            anyhow::ensure!(swept.is_none(), "a sweep varies one parameter");
            swept = Some((key.to_owned(), values.split(',').map(str::to_owned).collect::<Vec<_>>()));
        } else {
            fixed.push(part.to_owned());
        }
    }
    let (param, values) = swept.context("a sweep needs one parameter with comma-separated values")?;
    let points = values
        .iter()
        .map(|v| {
            let x: f64 = v.trim().parse().with_context(|| format!("sweep value `{v}` is not a number"))?;
            let label = std::iter::once(method.clone())
                .chain(fixed.iter().cloned())
                .chain([format!("{param}={}", v.trim())])
                .collect::<Vec<_>>()
                .join(":");
            Ok((x, label))
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(Sweep { method, param, points })
}

/// A name with parameters as given on the command line (`job::parse_named`).
pub(super) fn parse_named(text: &str) -> anyhow::Result<(String, Map<String, Value>)> {
    crate::job::parse_named(text).map_err(anyhow::Error::msg)
}

pub(super) fn parse_method(text: &str) -> anyhow::Result<MethodSpec> {
    MethodSpec::parse(text).map_err(anyhow::Error::msg)
}

pub(super) fn parse_size(text: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = text.split_once('x').with_context(|| format!("size `{text}` must be WIDTHxHEIGHT"))?;
    Ok((w.trim().parse()?, h.trim().parse()?))
}

/// Every registered method but `reference` (which the others are measured against), each
/// labelled by its name.
pub(super) fn every_method_but_reference() -> Vec<(String, MethodSpec)> {
    REGISTRY
        .iter()
        .filter(|m| m.name() != "reference")
        .map(|m| (m.name().to_owned(), MethodSpec { name: m.name().into(), params: Map::new() }))
        .collect()
}

/// Methods as given on the command line (`name:key=value`), each labelled by its text.
pub(super) fn parse_methods(listed: &[String]) -> anyhow::Result<Vec<(String, MethodSpec)>> {
    listed.iter().map(|text| Ok((text.clone(), parse_method(text)?))).collect()
}
