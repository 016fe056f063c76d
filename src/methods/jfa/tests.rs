//! Unit tests of `jfa`.

use super::*;

#[test]
fn run_lengths_match_the_shaders() {
    crate::gpu::shaders::assert_declares("methods/jfa/silhouette.wgsl", &format!("const ROW_TEXELS: i32 = {SILHOUETTE_ROW};"));
    crate::gpu::shaders::assert_declares("methods/jfa/shading.wgsl", &format!("const ROW_PIXELS: u32 = {FINAL_ROW}u;"));
}

#[test]
fn step_lengths_follow_the_paper() {
    assert_eq!(steps(6, false), vec![32, 16, 8, 4, 2, 1]);
    assert_eq!(steps(6, false).iter().sum::<i32>(), 63);
    assert_eq!(steps(3, true), vec![1; 7]);
}

#[test]
fn the_uniforms_and_bindings_match_the_shaders() {
    crate::gpu::shaders::assert_wgsl_layout!(
        Uniforms,
        "methods/jfa/common.wgsl",
        "JfaParams",
        [
            step,
            silhouette_relative,
            bias_texels,
            slope_bias_texels,
            boundary_relative,
            same_object,
            midpoint,
            light_space,
            edge_model,
            inner,
            map_pitch,
            _pad
        ]
    );
    let shaders =
        ["silhouette", "flood_light", "final_light", "boundary", "flood_eye", "final_eye"].map(|s| format!("methods/jfa/{s}.wgsl"));
    crate::gpu::shaders::assert_bindings(&shaders.each_ref().map(String::as_str), 1, &super::flood::BINDINGS);
}
