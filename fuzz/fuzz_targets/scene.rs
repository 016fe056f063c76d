//! Fuzzes the glTF / GLB loader with small limits: any bytes give a scene within the limits or
//! an `invalid_asset` / `limit_exceeded` error, never a panic or an allocation the declared
//! sizes asked for.
#![no_main]

use libfuzzer_sys::fuzz_target;
use penumbra::job::Limits;

fuzz_target!(init: penumbra_fuzz_init(), |data: &[u8]| {
    let limits = Limits { max_triangles: 100_000, max_texture_dim: 256, max_body_bytes: 1 << 20, ..Limits::default() };
    if let Ok(scene) = penumbra::scene::gltf::load(data, &limits, "scene") {
        assert!(scene.indices.len() as u64 / 3 <= limits.max_triangles);
    }
});

/// A crash is a panic that escapes penumbra's API (libfuzzer-sys aborts on those). libFuzzer's
/// default hook would also abort on a panic penumbra catches on purpose (the glTF loader turns
/// a panic inside the `gltf` crate into `invalid_asset`), so the hook only stays quiet.
fn penumbra_fuzz_init() {
    std::panic::set_hook(Box::new(|_| {}));
}
