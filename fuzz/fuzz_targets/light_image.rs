//! Fuzzes the light-image decoder (PNG and EXR) with a small size limit: a header that
//! declares a huge image is refused from the header, and no input panics.
#![no_main]

use libfuzzer_sys::fuzz_target;
use penumbra::light::LightImage;

fuzz_target!(|data: &[u8]| {
    if let Ok(image) = LightImage::decode(data, 64, "light.image") {
        assert!(image.width <= 64 && image.height <= 64);
    }
});
