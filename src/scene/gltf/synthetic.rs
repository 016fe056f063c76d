//! GLB files made in code: height fields of a chosen size, for `bench-daemon`, load tests
//! and the loader's tests.

use super::pack::glb;

/// A GLB height field of `n × n` vertices (2 (n−1)² triangles) over a 4 m square with bumps
/// set by `seed`: distinct bytes for every seed, for benchmarks and load tests that need many
/// different scenes of a chosen size.
pub fn height_field_glb(n: u32, seed: u32) -> Vec<u8> {
    let (document, bin) = height_field(n, seed);
    glb(&document, &bin)
}

/// `height_field_glb(3, 1)` drawn in one part per entry of `colors`, each with a material of
/// its own whose base colour is a `side × side` PNG of that colour type (3 bytes a texel
/// decoded for RGB, 4 as a texture): for tests of what textures may take.
pub fn textured_height_field_glb(colors: &[image::ColorType], side: u32) -> Vec<u8> {
    let images: Vec<Vec<u8>> = colors
        .iter()
        .enumerate()
        .map(|(k, &color)| {
            let texels = vec![(40 * k) as u8; (side * side) as usize * usize::from(color.bytes_per_pixel())];
            let mut png = Vec::new();
            image::ImageEncoder::write_image(image::codecs::png::PngEncoder::new(&mut png), &texels, side, side, color.into())
                .expect("a PNG of whole texels encodes");
            png
        })
        .collect();
    height_field_with_images(&images)
}

/// `height_field_glb(3, 1)` drawn in one part per image file of `images` (stored in the BIN
/// chunk as they are), each part with a material whose base colour is that image.
pub(super) fn height_field_with_images(images: &[Vec<u8>]) -> Vec<u8> {
    let (mut document, mut bin) = height_field(3, 1);
    let mut views = Vec::new();
    for file in images {
        views.push(serde_json::json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": file.len()}));
        bin.extend_from_slice(file);
        bin.resize(bin.len().next_multiple_of(4), 0);
    }
    let parts = images.len();
    document["buffers"][0]["byteLength"] = bin.len().into();
    document["bufferViews"].as_array_mut().expect("the height field's views").extend(views);
    document["images"] = (0..parts).map(|k| serde_json::json!({"bufferView": 2 + k, "mimeType": "image/png"})).collect();
    document["textures"] = (0..parts).map(|k| serde_json::json!({"source": k})).collect();
    document["materials"] = (0..parts).map(|k| serde_json::json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": k}}})).collect();
    let primitive = document["meshes"][0]["primitives"][0].clone();
    document["meshes"][0]["primitives"] = (0..parts)
        .map(|k| {
            let mut primitive = primitive.clone();
            primitive["material"] = k.into();
            primitive
        })
        .collect();
    glb(&document, &bin)
}

/// The glTF document of `height_field_glb` and its binary buffer (buffer 0, without `uri`).
pub(super) fn height_field(n: u32, seed: u32) -> (serde_json::Value, Vec<u8>) {
    let n = n.max(2);
    let mut bin = Vec::new();
    let (fx, fz) = (1.0 + (seed % 7) as f32, 1.0 + (seed / 7 % 5) as f32);
    for z in 0..n {
        for x in 0..n {
            let (u, v) = (x as f32 / (n - 1) as f32, z as f32 / (n - 1) as f32);
            let y = 0.3 * (fx * u * std::f32::consts::TAU).sin() * (fz * v * std::f32::consts::TAU).cos() + 0.4;
            for c in [4.0 * u - 2.0, y, 4.0 * v - 2.0] {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    let positions = bin.len();
    for z in 0..n - 1 {
        for x in 0..n - 1 {
            let i = z * n + x;
            for k in [i, i + n, i + 1, i + 1, i + n, i + n + 1] {
                bin.extend_from_slice(&k.to_le_bytes());
            }
        }
    }
    let indices = bin.len() - positions;
    let document = serde_json::json!({
        "asset": {"version": "2.0", "generator": format!("penumbra height field {n}x{n} seed {seed}")},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "field", "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": positions},
            {"buffer": 0, "byteOffset": positions, "byteLength": indices}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n * n, "type": "VEC3",
             "min": [-2.0, 0.1, -2.0], "max": [2.0, 0.7, 2.0]},
            {"bufferView": 1, "componentType": 5125, "count": 6 * (n - 1) * (n - 1), "type": "SCALAR"}
        ]
    });
    (document, bin)
}
