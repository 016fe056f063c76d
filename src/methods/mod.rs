//! Shadow methods as plug-ins (DESIGN.md §2). Each method is one module implementing
//! `ShadowMethod`: its name, its parameters (defaults, ranges, validation) and the passes it
//! records to turn the frame's G-buffer and shadow map into a visibility target. `REGISTRY`
//! lists them; adding a method adds a module, its shaders and one line there.

pub mod brabec;
pub mod chun_oh;
pub mod hard;
pub mod jfa;
pub mod jfa_lut;
pub mod pcss;
pub mod reference;
pub mod wedges;

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::{Map, Value};

use crate::error::{ErrorCode, JobError, JobResult};
use std::sync::Arc;

use crate::gpu::pool::{DerivedResources, PipelineKey, PipelinePool};
use crate::gpu::scene::GpuScene;
use crate::gpu::timing::GpuTimer;
use crate::gpu::GpuContext;
use crate::render::{FrameInputs, FrameSpec, LightProjection, Observer};

/// Every method penumbra serves, in the order `GET /v1/methods` lists them.
pub static REGISTRY: &[&dyn ShadowMethod] =
    &[&hard::Hard, &pcss::Pcss, &brabec::Brabec, &jfa::JfaL, &jfa::JfaE, &chun_oh::ChunOh, &wedges::Wedges, &reference::Reference];

/// Looks a method up by its job name.
pub fn find(name: &str) -> JobResult<&'static dyn ShadowMethod> {
    REGISTRY.iter().copied().find(|m| m.name() == name).ok_or_else(|| {
        let known: Vec<&str> = REGISTRY.iter().map(|m| m.name()).collect();
        JobError::field(ErrorCode::UnknownMethod, "method.name", format!("unknown method `{name}`; known: {}", known.join(", ")))
    })
}

/// Method-specific counters (JFA rounds, searches skipped …), reported with the timings.
pub type Counters = BTreeMap<String, f64>;

/// What a method gets to record its passes.
pub struct MethodContext<'a> {
    pub gpu: &'a GpuContext,
    pub pipelines: &'a mut PipelinePool,
    /// Resources derived from the job's inputs and kept for later jobs (look-up tables).
    pub derived: &'a mut DerivedResources,
    /// Group 0 of every screen-space pass: frame constants, G-buffer, shadow map.
    pub inputs: &'a FrameInputs,
    /// Where the method writes its visibility: `rgba32float`, rgb = V per channel.
    pub visibility: &'a wgpu::TextureView,
    pub width: u32,
    pub height: u32,
    pub encoder: &'a mut wgpu::CommandEncoder,
    pub timer: &'a mut GpuTimer,
    /// The scene, for methods that draw it again (from light samples, as wedges …).
    pub scene: &'a GpuScene,
    /// The whole frame: light, light image, camera, sizes.
    pub spec: &'a FrameSpec,
    /// The shadow map's projection from the light centre, as the frame rendered it.
    pub projection: &'a LightProjection,
    /// Hears the progress of long methods (steps done, steps in all); a long method asks it
    /// between batches whether to stop (`Observer::cancelled`).
    pub observer: &'a dyn Observer,
}

impl MethodContext<'_> {
    /// Submits what has been recorded so far and waits for it, leaving a fresh encoder:
    /// for methods that run many passes and report progress between them.
    pub fn flush(&mut self) {
        let fresh = self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("MethodContext::encoder") });
        let done = std::mem::replace(self.encoder, fresh);
        self.gpu.queue.submit([done.finish()]);
        self.gpu.wait_idle();
    }

    /// A screen-space compute pipeline from the pool: group 0 the frame inputs, group 1 the
    /// bindings listed in `io` (bind groups for it come from `get_bind_group_layout(1)`).
    pub fn screen_pipeline(
        &mut self,
        key: PipelineKey,
        shader: &'static str,
        io: &[wgpu::BindGroupLayoutEntry],
    ) -> Arc<wgpu::ComputePipeline> {
        let device = &self.gpu.device;
        let inputs_layout = &self.inputs.layout;
        self.pipelines.compute(key, || {
            let io_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(key.name), entries: io });
            crate::render::screen_compute_pipeline(device, inputs_layout, key.name, shader, &io_layout)
        })
    }

    /// Workgroup counts covering the output with 8×8 workgroups.
    pub fn dispatch_size(&self) -> (u32, u32) {
        (self.width.div_ceil(8), self.height.div_ceil(8))
    }
}

pub trait ShadowMethod: Send + Sync {
    /// The job name (`method.name`).
    fn name(&self) -> &'static str;
    /// One line for `GET /v1/methods`: what it is and where it comes from.
    fn summary(&self) -> &'static str;
    /// Parameters with their defaults and ranges.
    fn params(&self) -> &'static [ParamSpec];
    /// Records the passes that fill `ctx.visibility`.
    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> Counters;
}

/// The depth bias of a shadow-map test from the light centre, the same for every method that
/// makes one (`hard`, `pcss`, `chun-oh`, `brabec`, `jfa-l`, `jfa-e`): constant and
/// slope-scaled, in texels at the receiver's depth (`depth_bias` in `common/shadow.wgsl`).
pub(super) const BIAS_TEXELS: ParamSpec = ParamSpec {
    name: "bias_texels",
    kind: ParamKind::Float { default: 1.5, min: 0.0, max: 64.0 },
    doc: "constant depth bias of the shadow-map test, in texels at the receiver's depth",
};
pub(super) const SLOPE_BIAS_TEXELS: ParamSpec = ParamSpec {
    name: "slope_bias_texels",
    kind: ParamKind::Float { default: 1.0, min: 0.0, max: 64.0 },
    doc: "slope-scaled depth bias: texels × tan of the angle between normal and light",
};

/// The type, default and range of one method parameter.
#[derive(Debug, Clone, Copy, Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ParamKind {
    Float { default: f64, min: f64, max: f64 },
    Integer { default: i64, min: i64, max: i64 },
    Boolean { default: bool },
    Choice { default: &'static str, options: &'static [&'static str] },
}

#[derive(Debug, Clone, Copy, Serialize)]
pub struct ParamSpec {
    pub name: &'static str,
    #[serde(flatten)]
    pub kind: ParamKind,
    pub doc: &'static str,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ParamValue {
    Float(f64),
    Integer(i64),
    Boolean(bool),
    Choice(&'static str),
}

/// Validated parameters: every declared parameter present, every value in range.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Params(BTreeMap<&'static str, ParamValue>);

impl Params {
    /// Checks the parameters a job gave against `specs`, filling in defaults. Unknown names
    /// are errors, not ignored (DESIGN.md §3).
    pub fn parse(specs: &[ParamSpec], given: &Map<String, Value>) -> JobResult<Self> {
        if let Some(unknown) = given.keys().find(|k| !specs.iter().any(|s| s.name == k.as_str())) {
            let known: Vec<&str> = specs.iter().map(|s| s.name).collect();
            return Err(JobError::field(
                ErrorCode::UnknownField,
                format!("method.{unknown}"),
                format!(
                    "unknown parameter `{unknown}`; this method takes: {}",
                    if known.is_empty() { "none".into() } else { known.join(", ") }
                ),
            ));
        }
        let mut values = BTreeMap::new();
        for spec in specs {
            let field = format!("method.{}", spec.name);
            let value = given.get(spec.name);
            let parsed = match (spec.kind, value) {
                (ParamKind::Float { default, .. }, None) => ParamValue::Float(default),
                (ParamKind::Float { min, max, .. }, Some(v)) => match v.as_f64() {
                    Some(x) if x.is_finite() && (min..=max).contains(&x) => ParamValue::Float(x),
                    _ => return Err(JobError::invalid(field, format!("must be a number in [{min}, {max}]"))),
                },
                (ParamKind::Integer { default, .. }, None) => ParamValue::Integer(default),
                (ParamKind::Integer { min, max, .. }, Some(v)) => match v.as_i64() {
                    Some(x) if (min..=max).contains(&x) => ParamValue::Integer(x),
                    _ => return Err(JobError::invalid(field, format!("must be an integer in [{min}, {max}]"))),
                },
                (ParamKind::Boolean { default }, None) => ParamValue::Boolean(default),
                (ParamKind::Boolean { .. }, Some(v)) => match v.as_bool() {
                    Some(b) => ParamValue::Boolean(b),
                    None => return Err(JobError::invalid(field, "must be true or false")),
                },
                (ParamKind::Choice { default, .. }, None) => ParamValue::Choice(default),
                (ParamKind::Choice { options, .. }, Some(v)) => match v.as_str().and_then(|s| options.iter().find(|o| **o == s)) {
                    Some(option) => ParamValue::Choice(option),
                    None => return Err(JobError::invalid(field, format!("must be one of: {}", options.join(", ")))),
                },
            };
            values.insert(spec.name, parsed);
        }
        Ok(Self(values))
    }

    pub fn f32(&self, name: &str) -> f32 {
        match self.0.get(name) {
            Some(ParamValue::Float(x)) => *x as f32,
            Some(ParamValue::Integer(x)) => *x as f32,
            other => panic!("parameter `{name}` is not a number: {other:?}"),
        }
    }

    pub fn u32(&self, name: &str) -> u32 {
        match self.0.get(name) {
            Some(ParamValue::Integer(x)) => *x as u32,
            other => panic!("parameter `{name}` is not an integer: {other:?}"),
        }
    }

    pub fn bool(&self, name: &str) -> bool {
        match self.0.get(name) {
            Some(ParamValue::Boolean(b)) => *b,
            other => panic!("parameter `{name}` is not a boolean: {other:?}"),
        }
    }

    pub fn choice(&self, name: &str) -> &'static str {
        match self.0.get(name) {
            Some(ParamValue::Choice(c)) => c,
            other => panic!("parameter `{name}` is not a choice: {other:?}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SPECS: &[ParamSpec] = &[
        ParamSpec { name: "bias", kind: ParamKind::Float { default: 1.0, min: 0.0, max: 10.0 }, doc: "" },
        ParamSpec { name: "rounds", kind: ParamKind::Integer { default: 6, min: 1, max: 12 }, doc: "" },
        ParamSpec { name: "mode", kind: ParamKind::Choice { default: "adaptive", options: &["adaptive", "fixed"] }, doc: "" },
    ];

    fn given(json: &str) -> Map<String, Value> {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn defaults_and_ranges() {
        let p = Params::parse(SPECS, &given(r#"{"rounds": 3}"#)).unwrap();
        assert_eq!(p.f32("bias"), 1.0);
        assert_eq!(p.u32("rounds"), 3);
        assert_eq!(p.choice("mode"), "adaptive");
        let err = Params::parse(SPECS, &given(r#"{"rounds": 13}"#)).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("method.rounds"));
        let err = Params::parse(SPECS, &given(r#"{"bias": "x"}"#)).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("method.bias"));
        let err = Params::parse(SPECS, &given(r#"{"mode": "other"}"#)).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("method.mode"));
        let err = Params::parse(SPECS, &given(r#"{"radius": 1}"#)).unwrap_err();
        assert_eq!((err.code, err.field.as_deref()), (ErrorCode::UnknownField, Some("method.radius")));
    }

    #[test]
    fn registry_names_are_unique_and_params_valid() {
        let mut names: Vec<&str> = REGISTRY.iter().map(|m| m.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), REGISTRY.len());
        for method in REGISTRY {
            // Every default is itself a valid value.
            Params::parse(method.params(), &Map::new()).unwrap();
        }
        assert_eq!(find("nope").err().map(|e| e.code), Some(ErrorCode::UnknownMethod));
    }
}
