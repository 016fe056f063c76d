//! Light images (contract §1): decoded PNG (sRGB) or EXR (linear) files and the built-in
//! images, as linear RGBA, piecewise constant — one uniform sub-rectangle per texel.

use glam::{Vec2, Vec3};
use serde_json::{Map, Value};

use crate::color::srgb_to_linear;
use crate::error::{ErrorCode, JobError, JobResult};

/// Names of the built-in light images, in the order `GET /v1/methods` lists them.
pub const BUILTIN_LIGHT_IMAGES: &[&str] = &["white", "disk", "star", "stripes", "flame", "quadrants", "mosaic"];

/// A light image in linear RGBA: piecewise constant, one uniform sub-rectangle per texel.
#[derive(Debug, Clone, PartialEq)]
pub struct LightImage {
    pub width: u32,
    pub height: u32,
    /// Row-major from the top row, linear RGB (not premultiplied) and alpha.
    texels: Vec<[f32; 4]>,
    /// A hash of the size and texels, computed once: keys what is derived from the image.
    fingerprint: u64,
    /// Whether every texel emits the same radiance, computed once (`is_uniform`).
    uniform: bool,
}

impl LightImage {
    fn new(width: u32, height: u32, texels: Vec<[f32; 4]>) -> Self {
        use std::hash::{Hash, Hasher};
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        (width, height).hash(&mut hasher);
        for texel in &texels {
            texel.map(f32::to_bits).hash(&mut hasher);
        }
        let emission = |[r, g, b, a]: [f32; 4]| [r * a, g * a, b * a];
        let uniform = texels.iter().all(|&t| emission(t) == emission(texels[0]));
        Self { width, height, texels, fingerprint: hasher.finish(), uniform }
    }

    /// Whether every texel emits the same radiance: then each channel's share of any part of
    /// the light is its share of the area, and the methods need no per-light tables.
    pub fn is_uniform(&self) -> bool {
        self.uniform
    }

    /// A hash of the image's size and texels: keys what is derived from it and cached.
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    pub fn from_fn(width: u32, height: u32, f: impl Fn(f32, f32) -> [f32; 4]) -> Self {
        let mut texels = Vec::with_capacity((width * height) as usize);
        for j in 0..height {
            for i in 0..width {
                // Texel centre in [0,1]², s to the right, t downwards.
                let s = (i as f32 + 0.5) / width as f32;
                let t = (j as f32 + 0.5) / height as f32;
                texels.push(f(s, t));
            }
        }
        Self::new(width, height, texels)
    }

    /// Radiance weight of a texel: `rgb × alpha` (contract §1).
    pub fn emission(&self, i: u32, j: u32) -> Vec3 {
        let [r, g, b, a] = self.texels[(j * self.width + i) as usize];
        Vec3::new(r, g, b) * a
    }

    /// The texel holding image point (s, t) ∈ [0, 1]² (s right, t down): the image is
    /// piecewise constant, one uniform sub-rectangle per texel (contract §1).
    pub fn texel_at(&self, s: f32, t: f32) -> (u32, u32) {
        (((s * self.width as f32) as u32).min(self.width - 1), ((t * self.height as f32) as u32).min(self.height - 1))
    }

    /// Alpha of a texel.
    pub fn alpha(&self, i: u32, j: u32) -> f32 {
        self.texels[(j * self.width + i) as usize][3]
    }

    /// Mean emission over the whole image (what a gray method sees of the light's colour).
    pub fn mean_emission(&self) -> Vec3 {
        let mut sum = Vec3::ZERO;
        for j in 0..self.height {
            for i in 0..self.width {
                sum += self.emission(i, j);
            }
        }
        sum / (self.width * self.height) as f32
    }

    /// The light's white twin: the same shape — alpha, and which texels emit at all — with
    /// every emitting texel white. What a method's error under a coloured light is compared
    /// with to measure what the colours cost it (`penumbra eval --colored`).
    pub fn white_twin(&self) -> Self {
        let texels =
            self.texels.iter().map(|&[r, g, b, a]| if r.max(g).max(b) > 0.0 { [1.0, 1.0, 1.0, a] } else { [0.0, 0.0, 0.0, a] }).collect();
        Self::new(self.width, self.height, texels)
    }

    /// Checks a built-in light image's name and parameters, at submission and before building
    /// it. The one parameter is `white` (boolean): the image's white twin (`white_twin`).
    pub fn check_builtin(name: &str, params: &Map<String, Value>, field: &str) -> JobResult<()> {
        for (key, value) in params {
            if key != "white" {
                return Err(JobError::field(
                    ErrorCode::UnknownField,
                    format!("{field}.{key}"),
                    format!("the built-in light image `{name}` takes no parameter `{key}` (only `white`)"),
                ));
            }
            if !value.is_boolean() {
                return Err(JobError::field(ErrorCode::InvalidField, format!("{field}.{key}"), "`white` must be true or false"));
            }
        }
        if !BUILTIN_LIGHT_IMAGES.contains(&name) {
            return Err(JobError::field(
                ErrorCode::UnknownBuiltin,
                format!("{field}.builtin"),
                format!("unknown built-in light image `{name}`; known: {}", BUILTIN_LIGHT_IMAGES.join(", ")),
            ));
        }
        Ok(())
    }

    /// A built-in light image by name; `white: true` gives its white twin.
    pub fn builtin(name: &str, params: &Map<String, Value>, field: &str) -> JobResult<Self> {
        Self::check_builtin(name, params, field)?;
        let image = Self::builtin_image(name, field)?;
        Ok(if params.get("white") == Some(&Value::Bool(true)) { image.white_twin() } else { image })
    }

    fn builtin_image(name: &str, field: &str) -> JobResult<Self> {
        let white = [1.0, 1.0, 1.0, 1.0];
        let black = [0.0, 0.0, 0.0, 0.0];
        Ok(match name {
            "white" => Self::from_fn(1, 1, |_, _| white),
            "disk" => Self::from_fn(64, 64, |s, t| if Vec2::new(s - 0.5, t - 0.5).length() <= 0.5 { white } else { black }),
            "star" => Self::from_fn(64, 64, |s, t| if inside_star(Vec2::new(s - 0.5, 0.5 - t)) { white } else { black }),
            // Saturated bands left to right, so the image is asymmetric in both colour and
            // position: the first band (red) is column 0, on the light's −r side.
            "stripes" => {
                const BANDS: [[f32; 4]; 6] = [
                    [1.0, 0.0, 0.0, 1.0],
                    [1.0, 1.0, 0.0, 1.0],
                    [0.0, 1.0, 0.0, 1.0],
                    [0.0, 1.0, 1.0, 1.0],
                    [0.0, 0.0, 1.0, 1.0],
                    [1.0, 0.0, 1.0, 1.0],
                ];
                Self::from_fn(6, 1, |s, _| BANDS[((s * 6.0) as usize).min(5)])
            }
            // A flame: a teardrop, deep red at the bottom to yellow-white at the top.
            "flame" => Self::from_fn(32, 32, |s, t| {
                let x = (s - 0.5) * 2.0;
                let y = 1.0 - t; // 0 at the bottom row, 1 at the top row
                let half_width = 0.9 * (1.0 - y).sqrt() * (y * 3.0).min(1.0);
                if x.abs() > half_width {
                    return black;
                }
                let heat = y.clamp(0.0, 1.0);
                [1.0, 0.15 + 0.8 * heat, 0.02 + 0.5 * heat * heat, 1.0]
            }),
            // Four saturated quadrants, one per corner, so that an edge in any direction
            // hides a different mix of colours: red top-left, green top-right, blue
            // bottom-left, yellow bottom-right.
            "quadrants" => Self::from_fn(2, 2, |s, t| match (s < 0.5, t < 0.5) {
                (true, true) => [1.0, 0.0, 0.0, 1.0],
                (false, true) => [0.0, 1.0, 0.0, 1.0],
                (true, false) => [0.0, 0.0, 1.0, 1.0],
                (false, false) => [1.0, 1.0, 0.0, 1.0],
            }),
            // Stained glass: 8 × 8 panes, no two of one colour — red growing to the right,
            // green upwards, blue in a third pattern — so that E0 sums the most cells it ever
            // does (`light::irradiance::E0_GRID`²), as under a photograph of a light.
            "mosaic" => Self::from_fn(8, 8, |s, t| {
                let (i, j) = (((s * 8.0) as u32).min(7), 7 - ((t * 8.0) as u32).min(7));
                let level = |k: u32| (k + 1) as f32 / 8.0;
                [level(i), level(j), level((3 * i + 5 * j) % 8), 1.0]
            }),
            _ => {
                return Err(JobError::field(
                    ErrorCode::UnknownBuiltin,
                    format!("{field}.builtin"),
                    format!("unknown built-in light image `{name}`; known: {}", BUILTIN_LIGHT_IMAGES.join(", ")),
                ))
            }
        })
    }

    /// Decodes a PNG (sRGB, decoded to linear) or an EXR (linear) light image, refusing
    /// images larger than `max_dim` from the header, before decoding the pixels.
    pub fn decode(bytes: &[u8], max_dim: u32, field: &str) -> JobResult<Self> {
        use crate::image_input::{self, Refusal};
        let limits = image_input::Limits { max_dim, max_alloc: u64::from(max_dim) * u64::from(max_dim) * 16 * 2 };
        let formats = [image::ImageFormat::Png, image::ImageFormat::OpenExr];
        let (decoded, format) = image_input::decode(bytes, &formats, limits).map_err(|refusal| match refusal {
            Refusal::Format(_) => JobError::field(ErrorCode::InvalidAsset, field, "a light image must be a PNG or an OpenEXR file"),
            Refusal::TooLarge(what) => JobError::field(ErrorCode::LimitExceeded, field, format!("the light image is too large: {what}")),
            Refusal::Invalid(why) => JobError::field(ErrorCode::InvalidAsset, field, format!("cannot decode the light image: {why}")),
        })?;
        let linear_input = format == image::ImageFormat::OpenExr;
        let rgba = decoded.into_rgba32f();
        let (width, height) = rgba.dimensions();
        let texels = rgba
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                let decode = |c: f32| if linear_input { c.max(0.0) } else { srgb_to_linear(c) };
                let texel = [decode(r), decode(g), decode(b), a.clamp(0.0, 1.0)];
                if texel.iter().all(|c| c.is_finite()) {
                    texel
                } else {
                    [0.0; 4]
                }
            })
            .collect();
        Ok(Self::new(width, height, texels))
    }
}

/// A five-pointed star with one point up, inscribed in the unit-diameter disk.
fn inside_star(p: Vec2) -> bool {
    let outer = 0.5;
    let inner = 0.2;
    let vertices: Vec<Vec2> = (0..10)
        .map(|k| {
            let angle = std::f32::consts::FRAC_PI_2 + k as f32 * std::f32::consts::PI / 5.0;
            let radius = if k % 2 == 0 { outer } else { inner };
            Vec2::new(angle.cos(), angle.sin()) * radius
        })
        .collect();
    // Even-odd rule.
    let mut inside = false;
    for k in 0..vertices.len() {
        let (a, b) = (vertices[k], vertices[(k + 1) % vertices.len()]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_white_twin_keeps_the_shape_and_drops_the_colours() {
        let flame = LightImage::builtin("flame", &Map::new(), "light.image").unwrap();
        let params = Map::from_iter([("white".to_owned(), Value::Bool(true))]);
        let twin = LightImage::builtin("flame", &params, "light.image").unwrap();
        assert_eq!(twin, flame.white_twin());
        for j in 0..flame.height {
            for i in 0..flame.width {
                let (e, w) = (flame.emission(i, j), twin.emission(i, j));
                assert_eq!(e.max_element() > 0.0, w.max_element() > 0.0, "texel ({i}, {j}) keeps whether it emits");
                assert!(w == Vec3::ZERO || w == Vec3::ONE * flame.alpha(i, j), "texel ({i}, {j}) is white: {w}");
            }
        }
        // `white: false` is the image itself.
        let plain = LightImage::builtin("flame", &Map::from_iter([("white".to_owned(), Value::Bool(false))]), "light.image").unwrap();
        assert_eq!(plain, flame);
    }

    /// The decoder's refusals name the job's field: too large (here an EXR whose data window
    /// exceeds the limit behind a small display window, which `cargo fuzz` found) is
    /// `limit_exceeded`, anything else not a light image `invalid_asset`.
    #[test]
    fn undecodable_light_images_are_refused_naming_the_field() {
        let huge = include_bytes!("../../fuzz/regressions/light_image-exr-data-window.exr");
        let error = LightImage::decode(huge, 64, "light.image").unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::LimitExceeded, Some("light.image")), "{}", error.message);
        assert!(error.message.contains("data window"), "{}", error.message);
        let error = LightImage::decode(b"GIF89a", 64, "light.image").unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::InvalidAsset, Some("light.image")), "{}", error.message);
    }

    #[test]
    fn built_in_parameters_are_checked_by_name_and_type() {
        let bad = |key: &str, value: Value| {
            LightImage::builtin("stripes", &Map::from_iter([(key.to_owned(), value)]), "light.image").unwrap_err()
        };
        let unknown = bad("hue", Value::Bool(true));
        assert_eq!((unknown.code, unknown.field.as_deref()), (ErrorCode::UnknownField, Some("light.image.hue")));
        let wrong = bad("white", Value::from(1));
        assert_eq!((wrong.code, wrong.field.as_deref()), (ErrorCode::InvalidField, Some("light.image.white")));
    }
}
