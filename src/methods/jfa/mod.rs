//! Methods `jfa-l` and `jfa-e`: soft shadows by jump flooding (Rong & Tan 2006) in light
//! space (§4) and in eye space (§5), with the intensity look-up of §3 made coloured
//! (`light::tables`). Shaders: `shaders/methods/jfa/`. Both share one pass driver (`flood`): seed,
//! `rounds` rounds of flooding between two record buffers, final pass.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#jfa-l-and-jfa-e.

mod flood;

use flood::flood;

use super::{Cap, Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod, BIAS_TEXELS, SLOPE_BIAS_TEXELS};
use crate::error::JobResult;
use crate::params::choice;

pub struct JfaL;
pub struct JfaE;

const ROUNDS: Param<u32> = Param::integer(
    "rounds",
    6,
    1,
    13,
    "jump-flooding rounds: occluders travel up to 2^rounds − 1 pixels (log2 of the resolution floods fully)",
)
.capped(Cap::Rounds);
choice! {
    /// How records travel: by halving jumps (the paper's method) or one texel a round.
    pub(super) enum Flooding { Jump = "jump", Standard = "standard" }
}
choice! {
    /// The occluder edge that bounds the visible light.
    enum EdgeModel { Silhouette = "silhouette", Paper = "paper" }
}
const FLOODING: Param<Flooding> =
    Param::choice("flooding", "jump flooding, or standard flooding (step 1, 2^rounds − 1 rounds) for the paper's experiment");

const SILHOUETTE_RELATIVE: Param<f32> = Param::float(
    "silhouette_relative",
    0.01,
    0.0,
    1.0,
    "a shadow-map neighbour deeper by more than depth × this lies beyond a silhouette (jfa-l's seeds; both methods' edge directions)",
);
const BOUNDARY_RELATIVE: Param<f32> = Param::float(
    "boundary_relative",
    0.02,
    0.0,
    1.0,
    "a lit neighbour closer in 3D than view depth × this makes a hard-shadow pixel a boundary pixel",
);
const SAME_OBJECT: Param<bool> = Param::boolean("same_object", true, "§5.2 remedy: flood only to pixels of the boundary pixel's object");
const MIDPOINT: Param<bool> =
    Param::boolean("midpoint", true, "§5.2 remedy: the midpoint towards the boundary pixel must already be in a penumbra");

const EDGE_MODEL: Param<EdgeModel> = Param::choice(
    "edge",
    "the occluder edge that bounds the visible light: the silhouette's own direction at the occluder point, or the paper's line orthogonal to c→q (§3)",
);
const INNER: Param<bool> = Param::boolean(
    "inner",
    true,
    "inner penumbra: silhouettes flood into the occluders' footprints and hard-shadowed pixels take their intensity (past the paper; false is the paper's outer penumbra only)",
);

const PARAMS_L: &[ParamSpec] =
    &[ROUNDS.spec, FLOODING.spec, SILHOUETTE_RELATIVE.spec, EDGE_MODEL.spec, INNER.spec, BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec];

const PARAMS_E: &[ParamSpec] = &[
    ROUNDS.spec,
    FLOODING.spec,
    BOUNDARY_RELATIVE.spec,
    SAME_OBJECT.spec,
    MIDPOINT.spec,
    SILHOUETTE_RELATIVE.spec,
    EDGE_MODEL.spec,
    BIAS_TEXELS.spec,
    SLOPE_BIAS_TEXELS.spec,
];

/// Laid out as `JfaParams` in `shaders/methods/jfa/common.wgsl`, one 256-byte slot per pass.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    step: i32,
    silhouette_relative: f32,
    bias_texels: f32,
    slope_bias_texels: f32,
    boundary_relative: f32,
    same_object: u32,
    midpoint: u32,
    light_space: u32,
    edge_model: u32,
    inner: u32,
    map_pitch: u32,
    _pad: u32,
}

/// The flood's workgroups are `TILE`² cells (`TILE` in `neighbours.wgsl`).
pub(super) const TILE: u32 = 8;
/// Texels per invocation of jfa-l's silhouette pass (`ROW_TEXELS` in silhouette.wgsl).
const SILHOUETTE_ROW: u32 = 4;
/// Pixels per invocation of both final passes' `main` (`ROW_PIXELS` in shading.wgsl).
const FINAL_ROW: u32 = 8;

/// The step lengths of the flood: 2^(rounds−1) … 1, or 1 repeated for standard flooding.
pub fn steps(rounds: u32, standard: bool) -> Vec<i32> {
    if standard {
        vec![1; (1usize << rounds) - 1]
    } else {
        (0..rounds).rev().map(|k| 1 << k).collect()
    }
}

/// Which flood: the grid it runs over and its three shaders.
struct Flood {
    name: &'static str,
    seed: (&'static str, &'static str),
    round: (&'static str, &'static str),
    finish: (&'static str, &'static str),
    light_space: bool,
    /// Bytes of one cell's record (`common.wgsl`): an occluder, plus its origin for jfa-e.
    record_bytes: u64,
}

const LIGHT_SPACE: Flood = Flood {
    name: "jfa-l",
    seed: ("jfa-l.silhouette", "methods/jfa/silhouette.wgsl"),
    round: ("jfa-l.flood", "methods/jfa/flood_light.wgsl"),
    finish: ("jfa-l.final", "methods/jfa/final_light.wgsl"),
    light_space: true,
    record_bytes: 16,
};

const EYE_SPACE: Flood = Flood {
    name: "jfa-e",
    seed: ("jfa-e.boundary", "methods/jfa/boundary.wgsl"),
    round: ("jfa-e.flood", "methods/jfa/flood_eye.wgsl"),
    finish: ("jfa-e.final", "methods/jfa/final_eye.wgsl"),
    light_space: false,
    record_bytes: 32,
};

impl ShadowMethod for JfaL {
    fn name(&self) -> &'static str {
        LIGHT_SPACE.name
    }

    fn summary(&self) -> &'static str {
        "Rong & Tan 2006 §4: silhouette pixels in the shadow map, jump flooding of occluders in light space, intensity by ray to the light through the coloured edge table; outer penumbra, and the inner one past the paper"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS_L
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let uniforms = Uniforms { inner: u32::from(params.get(&INNER)), ..common_uniforms(params) };
        let (seeds, penumbra, steps, flooded) = flood(ctx, &LIGHT_SPACE, params, uniforms)?;
        Ok(Counters::from([
            ("occluders_thin".to_owned(), super::light_view::thin_occluders(ctx, "jfa-l", "Rong & Tan 2006 §3, §4.1")),
            ("rounds".to_owned(), steps.len() as f64),
            ("max_reach_texels".to_owned(), f64::from(steps.iter().sum::<i32>())),
            ("silhouette_texels".to_owned(), f64::from(seeds)),
            ("penumbra_pixels".to_owned(), f64::from(penumbra)),
            ("flooded_tile_fraction".to_owned(), flooded),
        ]))
    }
}

impl ShadowMethod for JfaE {
    fn name(&self) -> &'static str {
        EYE_SPACE.name
    }

    /// The boundary and the flood compare object ids (§5's check against jumping too far).
    fn reads_object_ids(&self) -> bool {
        true
    }

    fn summary(&self) -> &'static str {
        "Rong & Tan 2006 §5: hard shadows with 3D positions, boundary pixels, eye-space jump flooding for inner and outer penumbrae, object-id and midpoint checks against jumping too far"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS_E
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let uniforms = Uniforms {
            boundary_relative: params.get(&BOUNDARY_RELATIVE),
            same_object: u32::from(params.get(&SAME_OBJECT)),
            midpoint: u32::from(params.get(&MIDPOINT)),
            ..common_uniforms(params)
        };
        let (seeds, penumbra, steps, flooded) = flood(ctx, &EYE_SPACE, params, uniforms)?;
        Ok(Counters::from([
            ("occluders_thin".to_owned(), super::light_view::thin_occluders(ctx, "jfa-e", "Rong & Tan 2006 §3, §5.1")),
            ("rounds".to_owned(), steps.len() as f64),
            ("max_reach_pixels".to_owned(), f64::from(steps.iter().sum::<i32>())),
            ("boundary_pixels".to_owned(), f64::from(seeds)),
            ("penumbra_pixels".to_owned(), f64::from(penumbra)),
            ("flooded_tile_fraction".to_owned(), flooded),
        ]))
    }
}

fn common_uniforms(params: &Params) -> Uniforms {
    Uniforms {
        step: 0,
        silhouette_relative: params.get(&SILHOUETTE_RELATIVE),
        bias_texels: params.get(&BIAS_TEXELS),
        slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS),
        boundary_relative: 0.0,
        same_object: 0,
        midpoint: 0,
        light_space: 0,
        edge_model: match params.get(&EDGE_MODEL) {
            EdgeModel::Paper => 0,
            EdgeModel::Silhouette => 1,
        },
        inner: 0,
        map_pitch: 0,
        _pad: 0,
    }
}

#[cfg(test)]
mod tests;
