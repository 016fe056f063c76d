//! The job contract (contract §3): what a client asks for, parsed and validated.
//!
//! Parsing is strict: unknown fields are errors, and every error names the field by its
//! dotted path so that a client can fix its request without reading server logs. Values that
//! a job leaves out are filled from the scene's defaults later (`render::FrameSpec`), so
//! the types here keep them optional.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::error::{ErrorCode, JobError, JobResult};

mod assets;
pub mod auto;
mod limits;
pub mod progressive;
pub mod submission;
pub mod summary;

pub use assets::{AssetRef, FloorSpec, SceneRef};
use limits::nesting_exceeds;
pub use limits::{Limits, MAX_JSON_DEPTH};

/// The eye camera; absent fields come from the scene's default view.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub eye: Option<[f32; 3]>,
    pub target: Option<[f32; 3]>,
    pub up: Option<[f32; 3]>,
    pub fov_y_deg: Option<f32>,
    pub near: Option<f32>,
    pub far: Option<f32>,
}

/// The area light (contract §1); absent fields come from the scene's default light.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    pub center: Option<[f32; 3]>,
    pub direction: Option<[f32; 3]>,
    pub up: Option<[f32; 3]>,
    pub size: Option<[f32; 2]>,
    pub intensity: Option<f32>,
    pub image: Option<AssetRef>,
}

/// The method of a job that names none.
pub const DEFAULT_METHOD: &str = "hard";

/// A shadow method by name, with its own parameters next to the name.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
pub struct MethodSpec {
    pub name: String,
    #[serde(flatten)]
    pub params: Map<String, Value>,
}

impl MethodSpec {
    /// A method written `name:key=value:key=value` (`parse_named`), as `eval` takes and labels
    /// methods and `auto`'s candidates are named.
    pub fn parse(text: &str) -> Result<Self, String> {
        let (name, params) = parse_named(text)?;
        Ok(Self { name, params })
    }
}

/// A name with parameters, `name:key=value:key=value` (values in JSON, else strings): methods,
/// scenes and light images as command lines and labels write them.
pub fn parse_named(text: &str) -> Result<(String, Map<String, Value>), String> {
    let mut parts = text.split(':');
    let name = parts.next().unwrap_or_default().trim().to_owned();
    let mut params = Map::new();
    for part in parts {
        let (key, value) = part.split_once('=').ok_or_else(|| format!("parameter `{part}` of `{name}` must be key=value"))?;
        let value: Value = serde_json::from_str(value).unwrap_or_else(|_| Value::String(value.to_owned()));
        params.insert(key.to_owned(), value);
    }
    Ok((name, params))
}

impl Default for MethodSpec {
    fn default() -> Self {
        Self { name: DEFAULT_METHOD.into(), params: Map::new() }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShadowMapSpec {
    /// Side of the square light-space shadow map in texels.
    #[serde(deserialize_with = "whole_number")]
    pub resolution: u32,
}

impl Default for ShadowMapSpec {
    fn default() -> Self {
        Self { resolution: 1024 }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputFormat {
    /// 8-bit sRGB with alpha, after exposure.
    Png,
    /// Linear float: R,G,B,A, visibility.R/G/B, the error estimate of a method that makes one,
    /// and depth.
    Exr,
}

impl OutputFormat {
    pub fn mime(self) -> &'static str {
        match self {
            OutputFormat::Png => "image/png",
            OutputFormat::Exr => "image/x-exr",
        }
    }

    /// Picks the format from an output file name, as `penumbra render -o` does.
    pub fn from_extension(path: &std::path::Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "png" => Some(OutputFormat::Png),
            "exr" => Some(OutputFormat::Exr),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputSpec {
    #[serde(deserialize_with = "whole_number")]
    pub width: u32,
    #[serde(deserialize_with = "whole_number")]
    pub height: u32,
    pub format: OutputFormat,
    /// Exposure in stops applied before the sRGB encoding of PNG output (EXR stays linear).
    pub exposure: f32,
}

impl Default for OutputSpec {
    fn default() -> Self {
        Self { width: 512, height: 512, format: OutputFormat::Png, exposure: 0.0 }
    }
}

/// A submitted job's status (contract §3), as records and events carry it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    /// Accepted, waiting for the device.
    #[default]
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobStatus {
    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Succeeded => "succeeded",
            JobStatus::Failed => "failed",
            JobStatus::Cancelled => "cancelled",
        }
    }

    /// Whether the job has ended: succeeded, failed or cancelled.
    pub fn finished(self) -> bool {
        matches!(self, JobStatus::Succeeded | JobStatus::Failed | JobStatus::Cancelled)
    }
}

impl std::fmt::Display for JobStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The seed of the reference a job is compared with (`Job::reference_job`).
pub const TRUTH_SEED: u32 = 7;

/// One render job, as sent by a client.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Job {
    pub scene: SceneRef,
    #[serde(default)]
    pub camera: CameraSpec,
    #[serde(default)]
    pub light: LightSpec,
    #[serde(default)]
    pub method: MethodSpec,
    #[serde(default)]
    pub shadow_map: ShadowMapSpec,
    #[serde(default)]
    pub output: OutputSpec,
    /// Optional constant ambient irradiance added to every visible point, linear RGB.
    /// contract §1: no ambient term unless the job asks for one.
    #[serde(default)]
    pub ambient: Option<[f32; 3]>,
    /// Also render `reference` for the same scene, view and light (cached) and report
    /// quality metrics against it.
    #[serde(default)]
    pub compare: bool,
    /// A submitted `reference` that answers in rounds until an error or a time is met
    /// (contract §5, `progressive.rs`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub progressive: Option<progressive::Progressive>,
}

impl Job {
    /// The job the CLI renders when it is given none: the `torus` scene with hard shadows.
    pub fn embedded_default() -> Self {
        Self {
            scene: AssetRef::builtin("torus").into(),
            camera: CameraSpec::default(),
            light: LightSpec::default(),
            method: MethodSpec::default(),
            shadow_map: ShadowMapSpec::default(),
            output: OutputSpec::default(),
            ambient: None,
            compare: false,
            progressive: None,
        }
    }

    /// The `reference` job for the same scene, view, light and size: what `compare`
    /// measures against. Its visibility is always read back.
    /// Its seed is one of its own (`TRUTH_SEED`): a reference's samples are the first of one
    /// sequence per seed, so a truth of the default seed would hold every sample of a tested
    /// `reference` of fewer, and their errors would cancel.
    pub fn reference_job(&self) -> Job {
        Job {
            method: MethodSpec { name: "reference".into(), params: Map::from_iter([("seed".to_owned(), TRUTH_SEED.into())]) },
            output: OutputSpec { format: OutputFormat::Exr, exposure: 0.0, ..self.output.clone() },
            compare: false,
            progressive: None,
            ..self.clone()
        }
    }

    /// `reference_job` with `samples` light samples and sample maps of `resolution`² (a
    /// reference to measure against, its maps those of the job's methods).
    pub fn reference_with(&self, samples: u32, resolution: u32) -> Job {
        let mut reference = self.reference_job();
        reference.method.params.insert("samples".into(), samples.into());
        reference.method.params.insert("resolution".into(), resolution.into());
        reference
    }

    /// Parses a job from JSON bytes under the default limits; type errors name the field by
    /// its path.
    pub fn from_json(bytes: &[u8]) -> JobResult<Self> {
        Self::from_json_limited(bytes, &Limits::default())
    }

    /// Parses a job from JSON bytes, refusing nesting deeper than `limits.max_json_depth`
    /// before anything is allocated for it.
    pub fn from_json_limited(bytes: &[u8], limits: &Limits) -> JobResult<Self> {
        // serde would accept a struct written as an array of its fields; a job is an object.
        if bytes.iter().find(|b| !b.is_ascii_whitespace()) != Some(&b'{') {
            return Err(JobError::new(ErrorCode::InvalidJson, "a job is a JSON object"));
        }
        let depth = limits.max_json_depth;
        if nesting_exceeds(bytes, depth) {
            return Err(JobError::new(ErrorCode::InvalidJson, format!("the JSON nests deeper than {depth} levels (max_json_depth)")));
        }
        let de = &mut serde_json::Deserializer::from_slice(bytes);
        serde_path_to_error::deserialize(de).map_err(|err| {
            let path = err.path().to_string();
            let inner = err.into_inner();
            // A number no float can hold (1e999) is well-formed JSON to a reader: a bad value
            // of the field being read, not a syntax error.
            let out_of_range = inner.to_string().starts_with("number out of range");
            let code = if out_of_range {
                ErrorCode::InvalidField
            } else if inner.is_syntax() || inner.is_eof() {
                ErrorCode::InvalidJson
            } else if inner.to_string().starts_with("unknown field") {
                ErrorCode::UnknownField
            } else {
                ErrorCode::InvalidField
            };
            let message = inner.to_string();
            let mut error = JobError::new(code, message.clone());
            // A syntax error has a position, not a field: the path is where parsing stopped.
            if code != ErrorCode::InvalidJson && path != "." && !path.is_empty() {
                error.field = Some(path.clone());
            }
            // A missing field is named by serde in the message only: the field is the path of
            // the object it is missing from, and its name.
            if let Some(name) = message.strip_prefix("missing field `").and_then(|m| m.split('`').next()) {
                let parent = if path == "." || path.is_empty() { String::new() } else { format!("{path}.") };
                error.field = Some(format!("{parent}{name}"));
            }
            error
        })
    }

    /// Range checks that need neither a scene nor the methods' registry: output and
    /// shadow-map sizes, exposure, ambient, the light's size and intensity. The method, its
    /// parameters and built-in names are checked by `engine::check_job`; camera and light
    /// directions once merged with the scene's defaults.
    pub fn validate(&self, limits: &Limits) -> JobResult<()> {
        if let Some(progressive) = &self.progressive {
            progressive.check(self)?;
        }
        self.light.check_given()?;
        self.camera.check_given()?;
        let out = &self.output;
        check_dim("output.width", out.width, limits.max_output_dim)?;
        check_dim("output.height", out.height, limits.max_output_dim)?;
        if u64::from(out.width) * u64::from(out.height) > limits.max_output_pixels {
            return Err(JobError::field(
                ErrorCode::LimitExceeded,
                "output",
                format!("{}×{} pixels exceeds the limit of {} pixels", out.width, out.height, limits.max_output_pixels),
            ));
        }
        if !out.exposure.is_finite() || out.exposure.abs() > 32.0 {
            return Err(JobError::invalid("output.exposure", "must be a number in [-32, 32]"));
        }
        let res = self.shadow_map.resolution;
        if !(16..=limits.max_shadow_map_resolution).contains(&res) {
            return Err(JobError::field(
                if res > limits.max_shadow_map_resolution { ErrorCode::LimitExceeded } else { ErrorCode::InvalidField },
                "shadow_map.resolution",
                format!("must be in [16, {}]", limits.max_shadow_map_resolution),
            ));
        }
        if let Some(ambient) = self.ambient {
            for (i, a) in ambient.iter().enumerate() {
                if !a.is_finite() || !(0.0..=MAX_LIGHT_INTENSITY).contains(a) {
                    return Err(JobError::invalid(format!("ambient[{i}]"), format!("must be a number in [0, {MAX_LIGHT_INTENSITY}]")));
                }
            }
        }
        Ok(())
    }
}

/// A whole number, written `161` or `161.0` (`params::whole_number`); `161.5`, a negative
/// number or one past `u32` is refused.
fn whole_number<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<u32, D::Error> {
    let number = serde_json::Number::deserialize(deserializer)?;
    crate::params::whole_number(&Value::Number(number.clone()))
        .and_then(|n| u32::try_from(n).ok())
        .ok_or_else(|| serde::de::Error::custom(format!("expected a whole number from 0 to {}, found {number}", u32::MAX)))
}

/// Largest coordinate of a camera's points and vectors, metres.
pub const MAX_COORDINATE: f32 = 1e7;

impl CameraSpec {
    /// The ranges of the fields given, alone: points and vectors finite within ±10⁷, the
    /// field of view in (0, 180)°, near and far finite and > 0, far beyond near. Checked at
    /// submission (a 202 never fails later for these), and by the renderer on the camera
    /// merged with a scene's defaults, with what needs the scene (target ≠ eye, up not along
    /// the view).
    pub fn check_given(&self) -> JobResult<()> {
        check_coordinates([("camera.eye", self.eye), ("camera.target", self.target), ("camera.up", self.up)])?;
        if self.fov_y_deg.is_some_and(|f| !(f.is_finite() && f > 0.0 && f < 180.0)) {
            return Err(JobError::invalid("camera.fov_y_deg", "must be in (0, 180) degrees"));
        }
        if self.near.is_some_and(|n| !(n.is_finite() && n > 0.0)) {
            return Err(JobError::invalid("camera.near", "must be a finite number > 0"));
        }
        if self.far.is_some_and(|f| !(f.is_finite() && f > 0.0 && self.near.is_none_or(|n| f > n))) {
            return Err(JobError::invalid("camera.far", "must be finite and greater than camera.near"));
        }
        Ok(())
    }
}

impl LightSpec {
    /// The ranges of the fields given, alone: points and vectors finite within ±10⁷, size
    /// and intensity (`check_light_size_and_intensity`). Checked at submission; the renderer
    /// checks the light merged with a scene's defaults, with what needs the whole light (a
    /// non-zero direction, `up` not along it).
    pub fn check_given(&self) -> JobResult<()> {
        check_coordinates([("light.center", self.center), ("light.direction", self.direction), ("light.up", self.up)])?;
        check_light_size_and_intensity(self.size, self.intensity)
    }
}

/// Points and vectors, where given: every coordinate finite and within ±10⁷.
fn check_coordinates(fields: [(&str, Option<[f32; 3]>); 3]) -> JobResult<()> {
    for (name, v) in fields {
        if v.is_some_and(|v| v.iter().any(|c| !c.is_finite() || c.abs() > MAX_COORDINATE)) {
            return Err(JobError::invalid(name, format!("must be finite, within ±{MAX_COORDINATE}")));
        }
    }
    Ok(())
}

/// Largest light side, metres.
pub const MAX_LIGHT_SIZE_M: f32 = 1e4;
/// Largest light intensity. Values are read as 32-bit floats: every integer up to 2²⁴ is
/// exact, so one past either bound is refused as sent, not rounded onto the bound.
pub const MAX_LIGHT_INTENSITY: f32 = 1e6;

/// The light's size (each side in (0, 10⁴] m) and intensity ([0, 10⁶]), where given: checked
/// at submission, and again by `AreaLight::new` on the values merged with a scene's defaults.
pub fn check_light_size_and_intensity(size: Option<[f32; 2]>, intensity: Option<f32>) -> JobResult<()> {
    for (i, s) in size.into_iter().flatten().enumerate() {
        if !s.is_finite() || s <= 0.0 || s > MAX_LIGHT_SIZE_M {
            return Err(JobError::invalid(format!("light.size[{i}]"), format!("must be in (0, {MAX_LIGHT_SIZE_M}] metres")));
        }
    }
    if let Some(intensity) = intensity {
        if !intensity.is_finite() || !(0.0..=MAX_LIGHT_INTENSITY).contains(&intensity) {
            return Err(JobError::invalid("light.intensity", format!("must be a finite number in [0, {MAX_LIGHT_INTENSITY}]")));
        }
    }
    Ok(())
}

fn check_dim(field: &str, value: u32, max: u32) -> JobResult<()> {
    if value == 0 {
        return Err(JobError::invalid(field, "must be at least 1"));
    }
    if value > max {
        return Err(JobError::field(ErrorCode::LimitExceeded, field, format!("{value} exceeds the limit of {max}")));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
