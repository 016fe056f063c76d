//! Shadow methods as plug-ins (contract §2). Each method is one module implementing
//! `ShadowMethod` (`render/method.rs`): its name, its parameters (defaults, ranges, caps) and
//! the passes it records to turn the frame's G-buffer and shadow map into a visibility target.
//! `REGISTRY` lists them; adding a method adds a module, its shaders and one line there.

pub mod brabec;
pub mod chun_oh;
pub mod filter;
pub mod hard;
pub mod jfa;
pub mod light_view;
pub mod pcss;
pub mod reference;
pub mod testing;
pub mod wedges;

use crate::error::{ErrorCode, JobError, JobResult};
pub use crate::params::{Cap, Param, ParamKind, ParamSpec, ParamValue, Params};
pub use crate::render::method::{CounterKey, Counters, MethodContext, ShadowMethod};

/// Every method penumbra serves, in the order `GET /v1/methods` lists them.
pub static REGISTRY: &[&dyn ShadowMethod] = &[
    &hard::Hard,
    &pcss::Pcss,
    &brabec::Brabec,
    &jfa::JfaL,
    &jfa::JfaE,
    &chun_oh::ChunOh,
    &wedges::Wedges,
    &reference::Filtered,
    &reference::Reference,
];

/// Looks a method up by its job name.
pub fn find(name: &str) -> JobResult<&'static dyn ShadowMethod> {
    REGISTRY.iter().copied().find(|m| m.name() == name).ok_or_else(|| {
        let known: Vec<&str> = REGISTRY.iter().map(|m| m.name()).collect();
        JobError::field(ErrorCode::UnknownMethod, "method.name", format!("unknown method `{name}`; known: {}", known.join(", ")))
    })
}

/// `method` as it renders a job whose shadow maps are `resolution`² texels: a method that
/// draws maps of its own light samples (`reference`'s and `filtered`'s `resolution`) and leaves
/// their resolution unset draws them at the job's, so that what it is measured or predicted
/// against (a reference of the same maps) measures the method, not the maps.
pub fn with_map_resolution(method: &crate::job::MethodSpec, resolution: u32) -> crate::job::MethodSpec {
    let mut method = method.clone();
    if find(&method.name).is_ok_and(|m| m.params().iter().any(|p| p.name == "resolution")) {
        method.params.entry("resolution").or_insert_with(|| resolution.into());
    }
    method
}

/// The depth bias of a shadow-map test from the light centre, the same for every method that
/// makes one (`hard`, `pcss`, `chun-oh`, `brabec`, `jfa-l`, `jfa-e`): constant and
/// slope-scaled, in texels at the receiver's depth (`depth_bias` in `common/shadow.wgsl`).
pub(super) const BIAS_TEXELS: Param<f32> =
    Param::float("bias_texels", 1.5, 0.0, 64.0, "constant depth bias of the shadow-map test, in texels at the receiver's depth");
pub(super) const SLOPE_BIAS_TEXELS: Param<f32> =
    Param::float("slope_bias_texels", 1.0, 0.0, 64.0, "slope-scaled depth bias: texels × tan of the angle between normal and light");

#[cfg(test)]
mod tests {
    use serde_json::Map;

    use super::*;

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

    #[test]
    fn samples_and_rounds_are_capped_by_the_operator() {
        let capped = |name: &str| -> Vec<(&str, Option<Cap>)> {
            find(name).unwrap().params().iter().filter(|p| p.cap.is_some()).map(|p| (p.name, p.cap)).collect()
        };
        assert_eq!(capped("reference"), [("samples", Some(Cap::Samples))]);
        assert_eq!(capped("jfa-l"), [("rounds", Some(Cap::Rounds))]);
        assert_eq!(capped("jfa-e"), [("rounds", Some(Cap::Rounds))]);
        assert!(capped("hard").is_empty());
    }
}
