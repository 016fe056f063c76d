//! Fuzzes the glTF / GLB loader with small limits: any bytes give a scene within the limits or
//! an `invalid_asset` / `limit_exceeded` error, never a panic or an allocation the declared
//! sizes asked for.
#![no_main]

use libfuzzer_sys::fuzz_target;
use penumbra::job::Limits;

fuzz_target!(|data: &[u8]| {
    let limits = Limits { max_triangles: 100_000, max_texture_dim: 256, max_body_bytes: 1 << 20, ..Limits::default() };
    if let Ok(scene) = penumbra::scene::gltf::load(data, &limits, "scene") {
        assert!(scene.indices.len() as u64 / 3 <= limits.max_triangles);
    }
});
