//! The sRGB transfer functions, written once: decoding sRGB images (light images, albedo
//! textures) to linear, and encoding linear radiance for display (PNG output, thumbnails,
//! metrics on displayed colour, eval's pictures).

pub fn srgb_to_linear(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear radiance → an 8-bit sRGB value, clamped to [0, 1] first.
pub fn srgb8(linear: f32) -> u8 {
    (linear_to_srgb(linear) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_transfer_functions_invert_each_other() {
        for k in 0..=255u8 {
            let c = f32::from(k) / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5, "{k}");
            assert_eq!(srgb8(srgb_to_linear(c)), k);
        }
        assert_eq!((srgb8(-1.0), srgb8(2.0)), (0, 255));
    }
}
