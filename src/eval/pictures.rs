//! `penumbra eval`'s pictures: each case's contact sheet (the reference, then every method,
//! with |V − Vref| heat-maps under them) and the heat-maps on their own.

use std::path::{Path, PathBuf};

use crate::quality;
use crate::render::FrameOutput;

/// Linear radiance → 8-bit sRGB, background black.
fn display(frame: &FrameOutput) -> image::RgbImage {
    let bytes = frame.color.iter().flat_map(|c| [0, 1, 2].map(|k| crate::color::srgb8(c[k]))).collect();
    image::RgbImage::from_raw(frame.width, frame.height, bytes).expect("sized from the frame")
}

/// |V − Vref| through the magma colour map, 0 black to 1 bright yellow.
fn heat_map(error: &[f32], width: u32, height: u32) -> image::RgbImage {
    let lut = nv_flip::magma_lut().to_vec();
    let entries = lut.len() / 3;
    let bytes = error
        .iter()
        .flat_map(|e| {
            let k = ((e.clamp(0.0, 1.0) * (entries - 1) as f32).round() as usize) * 3;
            [lut[k], lut[k + 1], lut[k + 2]]
        })
        .collect();
    image::RgbImage::from_raw(width, height, bytes).expect("sized from the frame")
}

pub(super) fn write_pictures(
    out: &Path,
    case: &str,
    reference: &FrameOutput,
    frames: &[(String, FrameOutput)],
) -> anyhow::Result<Vec<PathBuf>> {
    let (w, h) = (reference.width, reference.height);
    let columns = frames.len() as u32 + 1;
    let mut sheet = image::RgbImage::new(w * columns, h * 2);
    image::imageops::replace(&mut sheet, &display(reference), 0, 0);
    // Under the reference: Vref itself (as gray), so the penumbra the errors refer to shows.
    let vref: Vec<f32> = reference.visibility.as_ref().map(|v| v.iter().map(|p| p[0].max(p[1]).max(p[2])).collect()).unwrap_or_default();
    let gray = image::RgbImage::from_raw(w, h, vref.iter().flat_map(|v| [(v * 255.0) as u8; 3]).collect()).expect("sized");
    image::imageops::replace(&mut sheet, &gray, 0, i64::from(h));
    let mut files = Vec::new();
    for (k, (label, frame)) in frames.iter().enumerate() {
        let x = i64::from(w * (k as u32 + 1));
        image::imageops::replace(&mut sheet, &display(frame), x, 0);
        let heat = heat_map(&quality::visibility_error(frame, reference), w, h);
        image::imageops::replace(&mut sheet, &heat, x, i64::from(h));
        let path = out.join(format!("error-{case}-{}.png", sanitize(label)));
        heat.save(&path)?;
        files.push(path);
    }
    let path = out.join(format!("sheet-{case}.png"));
    sheet.save(&path)?;
    files.push(path);
    Ok(files)
}

pub(super) fn sanitize(label: &str) -> String {
    label.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect()
}

/// The real models a method does worst on, as many as a sheet shows.
const WORST_SHOWN: usize = 4;

/// Per light and method, a sheet of its worst real models (`worst-{light}-{method}.png`), one
/// row each, worst first: the reference, the method, and under them Vref and |V − Vref|, cut
/// from the cases' sheets (the method's column is its place in `methods`).
pub(super) fn write_worst_sheets(
    out: &Path,
    summaries: &[super::RealSummary],
    methods: &[(String, crate::job::MethodSpec)],
) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for summary in summaries {
        let Some(column) = methods.iter().position(|(label, _)| *label == summary.method) else { continue };
        let mut tiles = Vec::new();
        for (_, case, _) in summary.ranked.iter().take(WORST_SHOWN) {
            let sheet = image::open(out.join(format!("sheet-{case}.png")))?.into_rgb8();
            let (w, h) = (sheet.width() / (methods.len() as u32 + 1), sheet.height());
            let mut tile = image::RgbImage::new(2 * w, h);
            for (to, from) in [(0, 0), (1, column as u32 + 1)] {
                let part = image::imageops::crop_imm(&sheet, from * w, 0, w, h).to_image();
                image::imageops::replace(&mut tile, &part, i64::from(to * w), 0);
            }
            tiles.push(tile);
        }
        let Some(first) = tiles.first() else { continue };
        let (w, h) = (first.width(), first.height());
        let mut sheet = image::RgbImage::new(w, h * tiles.len() as u32);
        for (k, tile) in tiles.iter().enumerate() {
            image::imageops::replace(&mut sheet, tile, 0, i64::from(h) * k as i64);
        }
        let path = out.join(format!("worst-{}-{}.png", sanitize(&summary.light), sanitize(&summary.method)));
        sheet.save(&path)?;
        files.push(path);
    }
    Ok(files)
}
