//! Helpers shared by the integration tests: one warm engine per test binary, the spawned
//! daemon (`daemon.rs`), EXR decoding,
//! golden-image comparison with FLIP in the style of wgpu's own test harness, and a small
//! glTF scene as glTF JSON and as GLB.

#![allow(dead_code)]

pub mod daemon;

use std::collections::HashMap;
use std::io::Cursor;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use base64::Engine as _;
use penumbra::engine::{Engine, PathPolicy};
use penumbra::gpu::{AdapterChoice, GpuContext};
use penumbra::job::Limits;
use serde_json::json;

/// One engine for the whole test binary: the device, pipelines and scenes stay warm between
/// tests as they do in the daemon.
pub fn engine() -> Arc<Engine> {
    static ENGINE: OnceLock<Arc<Engine>> = OnceLock::new();
    ENGINE.get_or_init(|| Arc::new(own_engine())).clone()
}

/// An engine of the test's own, for a test that changes the renderer's state (its E0 mode),
/// which the shared engine's other tests must not see.
pub fn own_engine() -> Engine {
    let gpu = GpuContext::new(AdapterChoice::Auto).expect("a Vulkan adapter (lavapipe: apt-get install mesa-vulkan-drivers)");
    Engine::new(Arc::new(gpu), Limits::default(), PathPolicy::Any)
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

/// A small glTF made here: node 0 (no mesh, translated up 0.5) has child node 2 (a textured
/// triangle, further up 0.5); node 1 is a red floor quad. Mesh nodes are 1 and 2, so the floor
/// is object 0 and the triangle object 1.
pub fn test_gltf() -> (serde_json::Value, Vec<u8>) {
    test_gltf_with_texture(2, 2)
}

/// `test_gltf` with a green texture of `width × height` texels on the triangle.
pub fn test_gltf_with_texture(width: u32, height: u32) -> (serde_json::Value, Vec<u8>) {
    let mut bin: Vec<u8> = Vec::new();
    let mut push = |bytes: &[u8]| {
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        (offset, bytes.len())
    };
    let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let quad_pos = push(&f32s(&[-2., 0., -2., 2., 0., -2., 2., 0., 2., -2., 0., 2.]));
    let quad_nrm = push(&f32s(&[0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1., 0.]));
    let quad_idx = push(&[0u16, 2, 1, 0, 3, 2].iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>());
    let tri_pos = push(&f32s(&[-0.4, 0., -0.4, 0.4, 0., -0.4, 0., 0., 0.4]));
    let tri_uv = push(&f32s(&[0., 0., 1., 0., 0.5, 1.]));
    let mut png = Cursor::new(Vec::new());
    image::RgbaImage::from_pixel(width, height, image::Rgba([0, 255, 0, 255])).write_to(&mut png, image::ImageFormat::Png).unwrap();
    let png = push(png.get_ref());
    let views: Vec<serde_json::Value> = [quad_pos, quad_nrm, quad_idx, tri_pos, tri_uv, png]
        .iter()
        .map(|(o, l)| json!({"buffer": 0, "byteOffset": o, "byteLength": l}))
        .collect();
    let gltf = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"name": "group", "translation": [0, 0.5, 0], "children": [2]},
            {"name": "floor", "mesh": 0},
            {"name": "leaf", "mesh": 1, "translation": [-0.8, 0.5, -0.8]}
        ],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": 0}]},
            {"primitives": [{"attributes": {"POSITION": 3, "TEXCOORD_0": 4}, "material": 1}]}
        ],
        "materials": [
            {"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1.0]}},
            {"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}
        ],
        "textures": [{"source": 0}],
        "images": [{"bufferView": 5, "mimeType": "image/png"}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-2, 0, -2], "max": [2, 0, 2]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC3", "min": [-0.4, 0, -0.4], "max": [0.4, 0, 0.4]},
            {"bufferView": 4, "componentType": 5126, "count": 3, "type": "VEC2"}
        ],
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}]
    });
    (gltf, bin)
}

pub fn as_gltf_with_data_uri() -> Vec<u8> {
    let (mut gltf, bin) = test_gltf();
    gltf["buffers"][0]["uri"] =
        json!(format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin)));
    serde_json::to_vec(&gltf).unwrap()
}

pub fn as_glb() -> Vec<u8> {
    let (gltf, bin) = test_gltf();
    penumbra::scene::gltf::glb(&gltf, &bin)
}

/// A small PNG light image, `size` texels square, in warm colours.
pub fn png_light(size: u32) -> Vec<u8> {
    let mut png = Cursor::new(Vec::new());
    image::RgbaImage::from_fn(size, size, |x, y| image::Rgba([255, (x * 255 / size) as u8, (y * 255 / size) as u8, 255]))
        .write_to(&mut png, image::ImageFormat::Png)
        .unwrap();
    png.into_inner()
}

/// Runs headless Chromium on `url` with `extra` flags; returns its standard output (the DOM for
/// `--dump-dom`) or, for `--screenshot=PATH`, the path. `PENUMBRA_CHROMIUM` names the binary.
pub fn chromium(extra: &[&str], url: &str) -> String {
    let binary = std::env::var("PENUMBRA_CHROMIUM").unwrap_or_else(|_| "chromium".into());
    // One profile per run: tests open Chromium concurrently, and a profile is single-instance.
    static RUNS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let run = RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let profile = std::env::temp_dir().join(format!("penumbra-chromium-{}-{run}", std::process::id()));
    let output = std::process::Command::new(&binary)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--hide-scrollbars", "--window-size=1280,1300"])
        // Virtual time runs the page's timers without waiting for them: three polls or so.
        .arg("--virtual-time-budget=5000")
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output()
        .unwrap_or_else(|e| panic!("cannot run `{binary}` ({e}); install Debian's chromium: apt-get install -y chromium"));
    std::fs::remove_dir_all(&profile).ok();
    assert!(output.status.success(), "chromium failed: {}", String::from_utf8_lossy(&output.stderr));
    match extra.iter().find_map(|f| f.strip_prefix("--screenshot=")) {
        Some(path) => path.to_owned(),
        None => String::from_utf8(output.stdout).expect("UTF-8 DOM"),
    }
}

/// The `<body …>` tag of a dumped DOM, where the dashboard writes what it drew.
pub fn body_tag(dom: &str) -> String {
    dom.split("<body").nth(1).and_then(|b| b.split('>').next()).expect("a body element").to_owned()
}

/// An attribute's value in a tag ("" when it is absent).
pub fn attribute(tag: &str, name: &str) -> String {
    tag.split(&format!(" {name}=\"")).nth(1).and_then(|v| v.split('"').next()).unwrap_or("").to_owned()
}
