//! Helpers shared by the integration tests: one warm engine per test binary, EXR decoding,
//! and golden-image comparison with FLIP in the style of wgpu's own test harness.

#![allow(dead_code)]

use std::collections::HashMap;
use std::io::Cursor;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use penumbra::engine::{Engine, PathPolicy};
use penumbra::gpu::{AdapterChoice, GpuContext};
use penumbra::job::Limits;

/// One engine for the whole test binary: the device, pipelines and scenes stay warm between
/// tests as they do in the daemon.
pub fn engine() -> Arc<Engine> {
    static ENGINE: OnceLock<Arc<Engine>> = OnceLock::new();
    ENGINE
        .get_or_init(|| {
            let gpu = GpuContext::new(AdapterChoice::Auto).expect("a Vulkan adapter (lavapipe: apt-get install mesa-vulkan-drivers)");
            Arc::new(Engine::new(Arc::new(gpu), Limits::default(), PathPolicy::Any))
        })
        .clone()
}

/// Decodes an EXR written by penumbra into channels by name, and its size.
pub fn decode_exr(bytes: &[u8]) -> (usize, usize, HashMap<String, Vec<f32>>) {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .expect("a valid EXR");
    let size = image.layer_data.size;
    let channels =
        image.layer_data.channel_data.list.iter().map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect())).collect();
    (size.0, size.1, channels)
}

/// Compares a rendered PNG with `tests/golden/NAME.png` under FLIP: the mean error and the
/// 99th percentile must stay under the given thresholds. On failure, `NAME-actual.png` and
/// `NAME-difference.png` are written next to the golden image. A missing golden image is
/// written and the test fails, so it is looked at before it is trusted.
pub fn check_golden(name: &str, png: &[u8], max_mean: f32, max_p99: f32) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden");
    let golden_path = dir.join(format!("{name}.png"));
    let actual = image::load_from_memory(png).expect("a PNG").to_rgb8();
    if !golden_path.exists() {
        actual.save(&golden_path).unwrap();
        panic!("golden image {} was missing; written from this run — inspect it and commit it", golden_path.display());
    }
    let golden = image::open(&golden_path).unwrap().to_rgb8();
    assert_eq!(golden.dimensions(), actual.dimensions(), "{name}: size differs from the golden image");
    let (w, h) = golden.dimensions();
    let error = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, golden.as_raw()),
        nv_flip::FlipImageRgb8::with_data(w, h, actual.as_raw()),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mut pool = nv_flip::FlipPool::from_image(&error);
    let (mean, p99) = (pool.mean(), pool.get_percentile(0.99, true));
    if mean > max_mean || p99 > max_p99 {
        actual.save(dir.join(format!("{name}-actual.png"))).unwrap();
        let heat = error.apply_color_lut(&nv_flip::magma_lut());
        image::RgbImage::from_raw(w, h, heat.to_vec()).unwrap().save(dir.join(format!("{name}-difference.png"))).unwrap();
        panic!(
            "{name}: FLIP mean {mean:.4} (max {max_mean}), p99 {p99:.4} (max {max_p99}); see {name}-actual.png and {name}-difference.png"
        );
    }
}
