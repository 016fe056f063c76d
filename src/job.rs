//! The job contract (contract §3): what a client asks for, parsed and validated.
//!
//! Parsing is strict: unknown fields are errors, and every error names the field by its
//! dotted path so that a client can fix its request without reading server logs. Values that
//! a job leaves out are filled from the scene's defaults later (`render::FrameSpec`), so
//! the types here keep them optional.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::error::{ErrorCode, JobError, JobResult};
use crate::params::Cap;

/// Whether arrays and objects in `bytes` nest deeper than `max` (brackets inside strings do
/// not count). A linear scan before any parsing: a hostile body is refused before it costs
/// a deep recursion or an allocation.
fn nesting_exceeds(bytes: &[u8], max: usize) -> bool {
    let (mut depth, mut in_string, mut escaped) = (0usize, false, false);
    for &b in bytes {
        if in_string {
            match (escaped, b) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match b {
            b'"' => in_string = true,
            b'[' | b'{' => {
                depth += 1;
                if depth > max {
                    return true;
                }
            }
            b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    false
}

/// Default deepest nesting of arrays and objects a job may have (a job needs 4; serde_json's
/// own recursion limit of 128 would still allocate for a hostile body).
pub const MAX_JSON_DEPTH: usize = 16;

/// Limits on what one job may ask for. Every one is configurable (`serve --help`) and
/// enforced before anything is allocated.
#[derive(Debug, Clone, Serialize)]
pub struct Limits {
    /// Largest output width or height in pixels.
    pub max_output_dim: u32,
    /// Largest output image in pixels (width × height).
    pub max_output_pixels: u64,
    /// Largest shadow-map side in texels.
    pub max_shadow_map_resolution: u32,
    /// Most triangles a scene may have (built-in parameters and loaded files alike).
    pub max_triangles: u64,
    /// Largest light image side in texels.
    pub max_light_image_dim: u32,
    /// Largest side of a texture inside a glTF scene.
    pub max_texture_dim: u32,
    /// Most bytes a scene's textures may take decoded, all together (8-bit RGBA: 4 bytes a
    /// texel), each image's decoding buffers included: a small file can hold a large image,
    /// and a body of many such images would otherwise decode to many times the machine's memory.
    pub max_texture_bytes: u64,
    /// Largest request body in bytes (and scene or image file, and buffer a glTF declares).
    pub max_body_bytes: usize,
    /// Deepest nesting of arrays and objects in a job's JSON, refused before parsing.
    pub max_json_depth: usize,
    /// Most vertices a loaded scene may have (summed over the nodes that instance a mesh),
    /// refused from the accessors' declared counts before any is read.
    pub max_vertices: u64,
    /// Most samples a method may take per pixel (`reference`'s `samples`).
    pub max_samples: u32,
    /// Most rounds an iterative method may run (JFA's `rounds`).
    pub max_rounds: u32,
}

impl Limits {
    /// An operator cap on method parameters: its value and the flag that sets it.
    pub fn cap(&self, cap: Cap) -> (i64, &'static str) {
        match cap {
            Cap::Samples => (i64::from(self.max_samples), "max_samples"),
            Cap::Rounds => (i64::from(self.max_rounds), "max_rounds"),
        }
    }
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_output_dim: 8192,
            max_output_pixels: 16 * 1024 * 1024,
            max_shadow_map_resolution: 8192,
            max_triangles: 4_000_000,
            max_light_image_dim: 4096,
            max_texture_dim: 8192,
            max_texture_bytes: 1 << 30,
            max_body_bytes: 64 * 1024 * 1024,
            max_json_depth: MAX_JSON_DEPTH,
            max_vertices: 8_000_000,
            max_samples: 4096,
            max_rounds: 13,
        }
    }
}

/// A scene or light image: built in (with parameters), uploaded (by id) or a file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(try_from = "Map<String, Value>", into = "Map<String, Value>")]
pub enum AssetRef {
    Builtin { name: String, params: Map<String, Value> },
    Id(String),
    Path(PathBuf),
}

impl AssetRef {
    pub fn builtin(name: &str) -> Self {
        AssetRef::Builtin { name: name.to_owned(), params: Map::new() }
    }
}

impl TryFrom<Map<String, Value>> for AssetRef {
    type Error = String;

    fn try_from(mut map: Map<String, Value>) -> Result<Self, String> {
        let keys = ["builtin", "id", "path"];
        let present: Vec<&str> = keys.iter().copied().filter(|k| map.contains_key(*k)).collect();
        if present.len() != 1 {
            return Err("expected exactly one of `builtin`, `id` or `path`".into());
        }
        let value = map.remove(present[0]).unwrap_or_default();
        let Value::String(text) = value else {
            return Err(format!("`{}` must be a string", present[0]));
        };
        match present[0] {
            "builtin" => Ok(AssetRef::Builtin { name: text, params: map }),
            other => {
                if let Some(extra) = map.keys().next() {
                    return Err(format!("unknown field `{extra}` next to `{other}`"));
                }
                if other == "id" {
                    Ok(AssetRef::Id(text))
                } else {
                    Ok(AssetRef::Path(PathBuf::from(text)))
                }
            }
        }
    }
}

impl From<AssetRef> for Map<String, Value> {
    fn from(asset: AssetRef) -> Self {
        match asset {
            AssetRef::Builtin { name, mut params } => {
                params.insert("builtin".into(), Value::String(name));
                params
            }
            AssetRef::Id(id) => Map::from_iter([("id".to_owned(), Value::String(id))]),
            AssetRef::Path(path) => Map::from_iter([("path".to_owned(), Value::String(path.to_string_lossy().into_owned()))]),
        }
    }
}

/// The job's scene: the asset, and whether a floor is added under it (contract §3).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(try_from = "Map<String, Value>", into = "Map<String, Value>")]
pub struct SceneRef {
    pub asset: AssetRef,
    pub floor: Option<FloorSpec>,
}

impl From<AssetRef> for SceneRef {
    fn from(asset: AssetRef) -> Self {
        SceneRef { asset, floor: None }
    }
}

impl TryFrom<Map<String, Value>> for SceneRef {
    type Error = String;

    fn try_from(mut map: Map<String, Value>) -> Result<Self, String> {
        let floor = match map.remove("floor") {
            None | Some(Value::Bool(false)) => None,
            Some(Value::Bool(true)) => Some(FloorSpec::default()),
            Some(value @ Value::Object(_)) => {
                let floor: FloorSpec = serde_json::from_value(value).map_err(|e| format!("`floor`: {e}"))?;
                floor.check().map_err(|e| format!("`floor`: {e}"))?;
                Some(floor)
            }
            Some(_) => return Err("`floor` must be true, false or {\"albedo\": [r, g, b], \"margin\": m}".into()),
        };
        Ok(SceneRef { asset: AssetRef::try_from(map)?, floor })
    }
}

impl From<SceneRef> for Map<String, Value> {
    fn from(scene: SceneRef) -> Self {
        let mut map = Map::from(scene.asset);
        if let Some(floor) = scene.floor {
            map.insert("floor".into(), serde_json::to_value(floor).unwrap_or(Value::Bool(true)));
        }
        map
    }
}

/// A receiving ground plane under the scene's bounds: a square centred under them, wider
/// than them by `margin` times the scene's bounding radius on every side (contract §3).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FloorSpec {
    /// Lambertian albedo, linear RGB in [0, 1].
    pub albedo: [f32; 3],
    /// How far the floor reaches past the bounds, in bounding radii (0–100).
    pub margin: f32,
}

impl Default for FloorSpec {
    fn default() -> Self {
        FloorSpec { albedo: [0.8, 0.8, 0.8], margin: 2.0 }
    }
}

impl FloorSpec {
    fn check(&self) -> Result<(), String> {
        if !self.albedo.iter().all(|a| (0.0..=1.0).contains(a)) {
            return Err(format!("albedo {:?} must lie in [0, 1]", self.albedo));
        }
        if !(0.0..=100.0).contains(&self.margin) {
            return Err(format!("margin {} must lie in [0, 100]", self.margin));
        }
        Ok(())
    }
}

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

/// A shadow method by name, with its own parameters next to the name.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
pub struct MethodSpec {
    pub name: String,
    #[serde(flatten)]
    pub params: Map<String, Value>,
}

impl Default for MethodSpec {
    fn default() -> Self {
        Self { name: "hard".into(), params: Map::new() }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShadowMapSpec {
    /// Side of the square light-space shadow map in texels.
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
    /// Linear float: R,G,B,A, visibility.R/G/B and depth.
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
    pub width: u32,
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
        }
    }

    /// The `reference` job for the same scene, view, light and size: what `compare`
    /// measures against. Its visibility is always read back.
    pub fn reference_job(&self) -> Job {
        Job {
            method: MethodSpec { name: "reference".into(), params: Map::new() },
            output: OutputSpec { format: OutputFormat::Exr, exposure: 0.0, ..self.output.clone() },
            compare: false,
            ..self.clone()
        }
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
    /// shadow-map sizes, exposure, ambient. The method, its parameters and built-in names are
    /// checked by `engine::check_job`; camera and light once merged with the scene's defaults.
    pub fn validate(&self, limits: &Limits) -> JobResult<()> {
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
                if !a.is_finite() || *a < 0.0 {
                    return Err(JobError::invalid(format!("ambient[{i}]"), "must be a finite number ≥ 0"));
                }
            }
        }
        Ok(())
    }
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
