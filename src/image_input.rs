//! Images from users — light images and glTF textures — decoded under limits: the size from
//! the header before any pixel, an EXR's every part checked before the `exr` crate allocates
//! for it, and a panic inside a decoder turned into an error, never a lost worker.

use std::io::Cursor;

use image::{DynamicImage, ImageFormat};

/// Why an image was refused; each caller words it for its own field.
#[derive(Debug, Clone, PartialEq)]
pub enum Refusal {
    /// A format the caller does not take (or none recognised).
    Format(Option<ImageFormat>),
    /// Larger than the caller's limits: what is too large, and the limit.
    TooLarge(String),
    /// Malformed: the decoder's own words.
    Invalid(String),
}

/// The caller's limits: the longest side in texels, and the bytes a decoder may allocate.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub max_dim: u32,
    pub max_alloc: u64,
}

/// Decodes `bytes` if their format is one of `formats`, within `limits`.
pub fn decode(bytes: &[u8], formats: &[ImageFormat], limits: Limits) -> Result<(DynamicImage, ImageFormat), Refusal> {
    // Decoders are untrusted-input parsers too: `cargo fuzz` found a tiled EXR on which the
    // `exr` crate overflows (a panic with overflow checks on).
    std::panic::catch_unwind(|| decode_unchecked(bytes, formats, limits))
        .unwrap_or_else(|_| Err(Refusal::Invalid("the decoder failed on malformed data".into())))
}

fn decode_unchecked(bytes: &[u8], formats: &[ImageFormat], limits: Limits) -> Result<(DynamicImage, ImageFormat), Refusal> {
    let mut reader = image::ImageReader::new(Cursor::new(bytes)).with_guessed_format().map_err(|e| Refusal::Invalid(e.to_string()))?;
    let format = reader.format().filter(|f| formats.contains(f)).ok_or(Refusal::Format(reader.format()))?;
    if format == ImageFormat::OpenExr {
        check_exr_parts(bytes, limits)?;
    }
    let mut image_limits = image::Limits::default();
    image_limits.max_image_width = Some(limits.max_dim);
    image_limits.max_image_height = Some(limits.max_dim);
    image_limits.max_alloc = Some(limits.max_alloc);
    reader.limits(image_limits);
    let decoded = reader.decode().map_err(|e| match e {
        image::ImageError::Limits(limit) => Refusal::TooLarge(match limit.kind() {
            image::error::LimitErrorKind::DimensionError => format!("more than {0}×{0} texels", limits.max_dim),
            _ => format!("more than {} bytes to decode", limits.max_alloc),
        }),
        other => Refusal::Invalid(other.to_string()),
    })?;
    Ok((decoded, format))
}

/// The `image` crate checks an EXR's *display* window against its limits, but the `exr` crate
/// allocates each part's *data* window and blocks as the header declares them: `cargo fuzz`
/// found an 8×8 display window over a data window 117 million texels wide, whose 30 GB
/// allocation aborts the process. So every part's data window, its bytes at the header's
/// channel list, and its tiles are held to the limits first.
fn check_exr_parts(bytes: &[u8], limits: Limits) -> Result<(), Refusal> {
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(|e| Refusal::Invalid(e.to_string()))?;
    let max_dim = limits.max_dim as usize;
    for header in &meta.headers {
        let size = header.layer_size;
        if size.0 > max_dim || size.1 > max_dim {
            return Err(Refusal::TooLarge(format!("an EXR data window of {}×{} texels, more than {max_dim}×{max_dim}", size.0, size.1)));
        }
        let bytes = (size.0 as u64) * (size.1 as u64) * header.channels.bytes_per_pixel as u64;
        if bytes > limits.max_alloc {
            return Err(Refusal::TooLarge(format!(
                "an EXR part of {bytes} bytes ({} channels), more than {} bytes",
                header.channels.list.len(),
                limits.max_alloc
            )));
        }
        // A tile larger than the limit holds nothing a smaller one could not; the `exr`
        // crate's block arithmetic overflows on absurd ones.
        if let exr::meta::BlockDescription::Tiles(tiles) = &header.blocks {
            if tiles.tile_size.0 > max_dim || tiles.tile_size.1 > max_dim {
                return Err(Refusal::TooLarge(format!(
                    "EXR tiles of {}×{} texels, more than {max_dim}×{max_dim}",
                    tiles.tile_size.0, tiles.tile_size.1
                )));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits { max_dim: 64, max_alloc: 64 * 64 * 32 };

    fn exr(width: usize, height: usize, tiles: Option<usize>) -> Vec<u8> {
        use exr::prelude::*;
        let pixels = SpecificChannels::rgba(|_: Vec2<usize>| (0.5_f32, 0.25_f32, 1.0_f32, 1.0_f32));
        let mut layer = Layer::new((width, height), LayerAttributes::default(), Encoding::FAST_LOSSLESS, pixels);
        if let Some(tile) = tiles {
            layer.encoding.blocks = Blocks::Tiles(Vec2(tile, tile));
        }
        let mut bytes = Vec::new();
        Image::from_layer(layer).write().to_buffered(Cursor::new(&mut bytes)).unwrap();
        bytes
    }

    #[test]
    fn an_exr_within_the_limits_decodes_scan_lines_or_tiles() {
        for tiles in [None, Some(16)] {
            let (image, format) = decode(&exr(40, 30, tiles), &[ImageFormat::OpenExr], LIMITS).unwrap();
            assert_eq!((image.width(), image.height(), format), (40, 30, ImageFormat::OpenExr));
        }
    }

    #[test]
    fn an_exr_beyond_the_limits_is_refused_from_its_header() {
        let refused = |bytes: &[u8], limits| matches!(decode(bytes, &[ImageFormat::OpenExr], limits), Err(Refusal::TooLarge(_)));
        assert!(refused(&exr(65, 8, None), LIMITS), "data window too wide");
        assert!(refused(&exr(8, 8, Some(128)), LIMITS), "tiles too large");
        assert!(refused(&exr(64, 64, None), Limits { max_dim: 64, max_alloc: 64 * 64 * 16 - 1 }), "too many bytes");
    }

    #[test]
    fn a_format_not_asked_for_is_refused_by_name() {
        let refusal = decode(&exr(8, 8, None), &[ImageFormat::Png], LIMITS).unwrap_err();
        assert_eq!(refusal, Refusal::Format(Some(ImageFormat::OpenExr)));
        assert_eq!(decode(b"not an image", &[ImageFormat::Png], LIMITS).unwrap_err(), Refusal::Format(None));
    }

    /// `cargo fuzz run light_image` found both: an 8×8 display window over a data window 117
    /// million texels wide (a 30 GB allocation that aborted the process), and a tiled EXR
    /// whose absurd tiles overflow the `exr` crate's arithmetic.
    #[test]
    fn fuzzed_exrs_that_crashed_the_decoder_are_refused() {
        for bytes in [
            &include_bytes!("../fuzz/regressions/light_image-exr-data-window.exr")[..],
            &include_bytes!("../fuzz/regressions/light_image-exr-tiles.exr")[..],
        ] {
            let refusal = decode(bytes, &[ImageFormat::OpenExr], Limits { max_dim: 4096, max_alloc: 4096 * 4096 * 32 }).unwrap_err();
            assert!(matches!(refusal, Refusal::TooLarge(_)), "{refusal:?}");
        }
    }
}
