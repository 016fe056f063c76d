//! Image encoding: PNG (8-bit sRGB after exposure, alpha = coverage) and OpenEXR (linear
//! float: `R,G,B,A` colour, `visibility.R/G/B`, and `depth`), through the `image`/`png` and
//! `exr` crates.

use std::io::Cursor;

use crate::color::srgb8;
use crate::error::{JobError, JobResult};
use crate::job::OutputFormat;
use crate::render::FrameOutput;

/// Encodes a frame in the requested format.
pub fn encode(frame: &FrameOutput, format: OutputFormat, exposure: f32) -> JobResult<Vec<u8>> {
    match format {
        OutputFormat::Png => encode_png(frame, exposure),
        OutputFormat::Exr => encode_exr(frame),
    }
}

/// An upper bound on the bytes of an encoded result and its record, for promising disk space
/// before rendering: PNG holds at most 4 bytes a pixel and a filter byte a row, EXR eight f32
/// channels; neither codec expands incompressible data by 1/64 (deflate's stored blocks add 5
/// bytes per 64 KiB, RLE one per 128), and headers, timings and counters fit in 64 KiB.
pub fn max_result_bytes(width: u32, height: u32, format: OutputFormat) -> u64 {
    let pixels = u64::from(width) * u64::from(height);
    let raw = match format {
        OutputFormat::Png => pixels * 4 + u64::from(height),
        OutputFormat::Exr => pixels * 8 * 4,
    };
    raw + raw / 64 + 64 * 1024
}

/// A PNG at most `size` pixels on its longest side, from an encoded PNG or EXR result. EXR's
/// linear values are sRGB-encoded as PNG output is (exposure 0), so previews look alike.
pub fn thumbnail(encoded: &[u8], size: u32) -> JobResult<Vec<u8>> {
    let image = image::load_from_memory(encoded).map_err(|e| JobError::internal(format!("cannot decode a kept result: {e}")))?;
    // Only ever down: `thumbnail` would also enlarge small results, with box-filter seams.
    let small =
        if image.width().max(image.height()) <= size { image } else { image.resize(size, size, image::imageops::FilterType::Triangle) };
    let rgb = if matches!(small, image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_)) {
        let linear = small.to_rgb32f();
        let bytes = linear.as_raw().iter().map(|&c| srgb8(c)).collect();
        image::RgbImage::from_raw(linear.width(), linear.height(), bytes).expect("buffer sized from the image")
    } else {
        small.to_rgb8()
    };
    let mut bytes = Cursor::new(Vec::new());
    rgb.write_to(&mut bytes, image::ImageFormat::Png).map_err(|e| JobError::internal(format!("PNG encoding failed: {e}")))?;
    Ok(bytes.into_inner())
}

fn encode_png(frame: &FrameOutput, exposure: f32) -> JobResult<Vec<u8>> {
    let converted;
    let rgba: &[u8] = match &frame.srgb8 {
        // Made by the composite pass (`shaders/composite.wgsl`, `srgb8`) with this exposure.
        Some(pixels) => pixels,
        None => {
            let scale = exposure.exp2();
            let mut rgba = Vec::with_capacity(frame.color.len() * 4);
            for [r, g, b, a] in &frame.color {
                for c in [r, g, b] {
                    rgba.push(srgb8(c * scale));
                }
                rgba.push((a.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
            }
            converted = rgba;
            &converted
        }
    };
    // Fast deflate with adaptive filters, chosen (it is also `image`'s default): stronger
    // levels cost several times as long at 1080p for files only somewhat smaller.
    let mut bytes = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    );
    image::ImageEncoder::write_image(encoder, rgba, frame.width, frame.height, image::ExtendedColorType::Rgba8)
        .map_err(|e| JobError::internal(format!("PNG encoding failed: {e}")))?;
    Ok(bytes)
}

fn encode_exr(frame: &FrameOutput) -> JobResult<Vec<u8>> {
    use exr::prelude::*;
    let size = (frame.width as usize, frame.height as usize);
    let color = |k: usize| FlatSamples::F32(frame.color.iter().map(|p| p[k]).collect());
    let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (k, name) in ["R", "G", "B", "A"].iter().enumerate() {
        channels.push(AnyChannel::new(*name, color(k)));
    }
    if let Some(visibility) = &frame.visibility {
        for (k, name) in ["visibility.R", "visibility.G", "visibility.B"].iter().enumerate() {
            channels.push(AnyChannel::new(*name, FlatSamples::F32(visibility.iter().map(|v| v[k]).collect())));
        }
    }
    if let Some(error) = &frame.error_estimate {
        channels.push(AnyChannel::new("error", FlatSamples::F32(error.clone())));
    }
    if let Some(depth) = &frame.depth {
        channels.push(AnyChannel::new("depth", FlatSamples::F32(depth.clone())));
    }
    let layer = Layer::new(size, LayerAttributes::named("penumbra"), Encoding::FAST_LOSSLESS, AnyChannels::sort(channels));
    let mut bytes = Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut bytes).map_err(|e| JobError::internal(format!("EXR encoding failed: {e}")))?;
    Ok(bytes.into_inner())
}
