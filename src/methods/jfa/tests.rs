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
