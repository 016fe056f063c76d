//! Checking a job completely before it is admitted (contract §3: a 202 never turns into a
//! failure for a bad field later): its own fields and limits, its method and parameters under
//! the operator's caps, and its built-in scene and light names. Needs the methods' registry,
//! so it lives above the methods, with the engine.

use crate::error::{ErrorCode, JobError, JobResult};
use crate::job::{AssetRef, Job, Limits};
use crate::light::LightImage;
use crate::methods::{self, ShadowMethod};
use crate::params::Params;

/// Checks everything about `job` that needs no file, upload or GPU, and answers its method
/// and checked parameters. A parameter left out counts with its default: a server capped
/// below a default needs the value given.
pub fn check_job(job: &Job, limits: &Limits) -> JobResult<(&'static dyn ShadowMethod, Params)> {
    job.validate(limits)?;
    let method = methods::find(&job.method.name)?;
    let params = Params::parse(method.params(), &job.method.params)?;
    for spec in method.params() {
        let Some(cap) = spec.cap else { continue };
        let (max, flag) = limits.cap(cap);
        let value = params.integer(spec.name).unwrap_or(0);
        if value > max {
            return Err(JobError::field(
                ErrorCode::LimitExceeded,
                format!("method.{}", spec.name),
                format!("{value} exceeds this server's limit of {max} ({flag})"),
            ));
        }
    }
    // Built-in assets are known now: a misspelt one is refused at submission, not later.
    if let AssetRef::Builtin { name, params } = &job.scene.asset {
        crate::scene::builtin::parse(name, params, "scene", limits)?;
    }
    if let Some(AssetRef::Builtin { name, params }) = &job.light.image {
        LightImage::check_builtin(name, params, "light.image")?;
    }
    Ok((method, params))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(json: &str) -> Job {
        Job::from_json(json.as_bytes()).unwrap()
    }

    #[test]
    fn method_parameters_and_builtins_are_checked_with_their_field_named() {
        let limits = Limits { max_samples: 64, ..Limits::default() };
        let cases = [
            (r#"{"scene": {"builtin": "torus"}, "method": {"name": "nope"}}"#, ErrorCode::UnknownMethod, "method.name"),
            (r#"{"scene": {"builtin": "torus"}, "method": {"name": "hard", "radius": 1}}"#, ErrorCode::UnknownField, "method.radius"),
            (
                r#"{"scene": {"builtin": "torus"}, "method": {"name": "reference", "samples": 65}}"#,
                ErrorCode::LimitExceeded,
                "method.samples",
            ),
            // The default of 256 samples exceeds this server's cap of 64.
            (r#"{"scene": {"builtin": "torus"}, "method": {"name": "reference"}}"#, ErrorCode::LimitExceeded, "method.samples"),
            (r#"{"scene": {"builtin": "teapot"}}"#, ErrorCode::UnknownBuiltin, "scene.builtin"),
            (
                r#"{"scene": {"builtin": "torus"}, "light": {"image": {"builtin": "moon"}}}"#,
                ErrorCode::UnknownBuiltin,
                "light.image.builtin",
            ),
        ];
        for (json, code, field) in cases {
            let Err(error) = check_job(&job(json), &limits) else { panic!("{json} passed") };
            assert_eq!((error.code, error.field.as_deref()), (code, Some(field)), "{json}");
        }
        check_job(&job(r#"{"scene": {"builtin": "torus"}, "method": {"name": "reference", "samples": 64}}"#), &limits).unwrap();
    }
}
