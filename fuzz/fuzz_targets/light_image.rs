//! Fuzzes the light-image decoder (PNG and EXR) with a small size limit: a header that
//! declares a huge image is refused from the header, and no input panics.
#![no_main]

use libfuzzer_sys::fuzz_target;
use penumbra::light::LightImage;

fuzz_target!(init: penumbra_fuzz_init(), |data: &[u8]| {
    if let Ok(image) = LightImage::decode(data, 64, "light.image") {
        assert!(image.width <= 64 && image.height <= 64);
    }
});

/// A crash is a panic that escapes penumbra's API (libfuzzer-sys aborts on those). libFuzzer's
/// default hook would also abort on a panic penumbra catches on purpose (the glTF loader turns
/// a panic inside the `gltf` crate into `invalid_asset`), so the hook only stays quiet.
fn penumbra_fuzz_init() {
    std::panic::set_hook(Box::new(|_| {}));
}
