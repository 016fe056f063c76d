//! The area light (DESIGN.md §1): its frame, its RGBA image, the built-in images, and the
//! exact unshadowed irradiance E0 that every method shares.
//!
//! Orientation is part of the contract: with `n = normalize(direction)`,
//! `u = normalize(up − (up·n)n)` and `r = normalize(cross(u, n))`, image row 0 lies along
//! `+u` and column 0 along `−r`, so that someone on the lit side looking back at the light
//! sees the image as an image viewer shows it. `AreaLight::texel_point` is the one place
//! that mapping is written down; the GPU gets corners computed here.

use std::io::Cursor;

use glam::{Vec2, Vec3};
use serde_json::{Map, Value};

use crate::error::{ErrorCode, JobError, JobResult};

/// Names of the built-in light images, in the order `GET /v1/methods` lists them.
pub const BUILTIN_LIGHT_IMAGES: &[&str] = &["white", "disk", "star", "stripes", "flame"];

/// Most cells per side of the light grid E0 integrates over. Cells follow texel boundaries
/// and cells of equal colour are merged, so E0 is exact for images of up to this many texels
/// per side and for any image made of large uniform regions (`white`, `stripes`).
pub const E0_GRID: u32 = 8;

/// A light image in linear RGBA: piecewise constant, one uniform sub-rectangle per texel.
#[derive(Debug, Clone, PartialEq)]
pub struct LightImage {
    pub width: u32,
    pub height: u32,
    /// Row-major from the top row, linear RGB (not premultiplied) and alpha.
    texels: Vec<[f32; 4]>,
    /// A hash of the size and texels, computed once: keys what is derived from the image.
    fingerprint: u64,
}

impl LightImage {
    fn new(width: u32, height: u32, texels: Vec<[f32; 4]>) -> Self {
        use std::hash::{Hash, Hasher};
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        (width, height).hash(&mut hasher);
        for texel in &texels {
            texel.map(f32::to_bits).hash(&mut hasher);
        }
        Self { width, height, texels, fingerprint: hasher.finish() }
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

    /// Radiance weight of a texel: `rgb × alpha` (DESIGN.md §1).
    pub fn emission(&self, i: u32, j: u32) -> Vec3 {
        let [r, g, b, a] = self.texels[(j * self.width + i) as usize];
        Vec3::new(r, g, b) * a
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

    /// A built-in light image by name. Built-ins take no parameters yet; any given is an error.
    /// Checks a built-in light image's name and (absent) parameters, at submission and before
    /// building it.
    pub fn check_builtin(name: &str, params: &Map<String, Value>, field: &str) -> JobResult<()> {
        if let Some(key) = params.keys().next() {
            return Err(JobError::field(
                ErrorCode::UnknownField,
                format!("{field}.{key}"),
                format!("the built-in light image `{name}` takes no parameter `{key}`"),
            ));
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

    pub fn builtin(name: &str, params: &Map<String, Value>, field: &str) -> JobResult<Self> {
        Self::check_builtin(name, params, field)?;
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
        // Decoders are untrusted-input parsers too: `cargo fuzz` found a tiled EXR on which the
        // `exr` crate overflows (a panic with overflow checks on). A panic is this job's
        // `invalid_asset`, never a lost worker thread.
        std::panic::catch_unwind(|| Self::decode_unchecked(bytes, max_dim, field))
            .unwrap_or_else(|_| Err(JobError::field(ErrorCode::InvalidAsset, field, "the light image could not be decoded")))
    }

    fn decode_unchecked(bytes: &[u8], max_dim: u32, field: &str) -> JobResult<Self> {
        let invalid = |message: String| JobError::field(ErrorCode::InvalidAsset, field, message);
        let mut reader = image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| invalid(format!("cannot read the light image: {e}")))?;
        let format = reader.format();
        if !matches!(format, Some(image::ImageFormat::Png | image::ImageFormat::OpenExr)) {
            return Err(invalid("a light image must be a PNG or an OpenEXR file".into()));
        }
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(max_dim);
        limits.max_image_height = Some(max_dim);
        limits.max_alloc = Some(u64::from(max_dim) * u64::from(max_dim) * 16 * 2);
        reader.limits(limits);
        let decoded = reader.decode().map_err(|e| match e {
            image::ImageError::Limits(_) => {
                JobError::field(ErrorCode::LimitExceeded, field, format!("the light image exceeds {max_dim}×{max_dim} texels"))
            }
            other => invalid(format!("cannot decode the light image: {other}")),
        })?;
        let linear_input = format == Some(image::ImageFormat::OpenExr);
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

/// The light's rectangle and frame in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AreaLight {
    pub center: Vec3,
    /// Unit normal of the emitting side.
    pub n: Vec3,
    /// Unit image-up direction in the light plane.
    pub u: Vec3,
    /// Unit image-right direction: `cross(u, n)`.
    pub r: Vec3,
    /// Width (along r) and height (along u) in metres.
    pub size_m: Vec2,
    pub intensity: f32,
}

impl AreaLight {
    /// Builds the frame of DESIGN.md §1, or names the field that makes it degenerate.
    pub fn new(center: Vec3, direction: Vec3, up: Vec3, size_m: Vec2, intensity: f32) -> JobResult<Self> {
        let finite = |v: Vec3| v.is_finite();
        if !finite(center) {
            return Err(JobError::invalid("light.center", "must be finite"));
        }
        if !finite(direction) || direction.length() < 1e-6 {
            return Err(JobError::invalid("light.direction", "must be a finite non-zero vector"));
        }
        let n = direction.normalize();
        let up_in_plane = up - up.dot(n) * n;
        if !finite(up) || up_in_plane.length() < 1e-4 * up.length().max(1e-30) || up_in_plane.length() < 1e-6 {
            return Err(JobError::invalid("light.up", "must be finite and not parallel to light.direction"));
        }
        let u = up_in_plane.normalize();
        let r = u.cross(n).normalize();
        for (i, s) in size_m.to_array().into_iter().enumerate() {
            if !s.is_finite() || s <= 0.0 || s > 1e4 {
                return Err(JobError::invalid(format!("light.size[{i}]"), "must be in (0, 10000] metres"));
            }
        }
        if !intensity.is_finite() || !(0.0..=1e9).contains(&intensity) {
            return Err(JobError::invalid("light.intensity", "must be a finite number in [0, 1e9]"));
        }
        Ok(Self { center, n, u, r, size_m, intensity })
    }

    /// World position of image coordinates `(s, t)` ∈ [0,1]²: s to the right from column 0,
    /// t downwards from row 0. Column 0 is at `−r`, row 0 at `+u` (DESIGN.md §1).
    pub fn image_point(&self, s: f32, t: f32) -> Vec3 {
        self.center + self.r * ((s - 0.5) * self.size_m.x) + self.u * ((0.5 - t) * self.size_m.y)
    }

    pub fn area_m2(&self) -> f32 {
        self.size_m.x * self.size_m.y
    }
}

/// A uniform sub-rectangle of the light: corners in world space (counter-clockwise seen
/// from the lit side) and its radiance `intensity × rgb × alpha`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightCell {
    pub corners: [Vec3; 4],
    pub radiance: Vec3,
}

/// Splits the light into at most `E0_GRID`² texel-aligned cells with their mean radiance,
/// merges neighbours of identical radiance into larger rectangles and drops black ones.
/// The result integrates a piecewise-constant image exactly when every cell is uniform.
pub fn light_cells(light: &AreaLight, image: &LightImage) -> Vec<LightCell> {
    let gx = image.width.min(E0_GRID);
    let gy = image.height.min(E0_GRID);
    let col_edge = |k: u32| (k * image.width + gx / 2) / gx;
    let row_edge = |k: u32| (k * image.height + gy / 2) / gy;
    // Mean emission per grid cell.
    let mut grid = vec![Vec3::ZERO; (gx * gy) as usize];
    for cy in 0..gy {
        for cx in 0..gx {
            let (i0, i1, j0, j1) = (col_edge(cx), col_edge(cx + 1), row_edge(cy), row_edge(cy + 1));
            let mut sum = Vec3::ZERO;
            for j in j0..j1 {
                for i in i0..i1 {
                    sum += image.emission(i, j);
                }
            }
            grid[(cy * gx + cx) as usize] = sum / ((i1 - i0) * (j1 - j0)).max(1) as f32;
        }
    }
    // Runs of equal colour along each row, then runs of equal runs down the columns.
    let mut rects: Vec<(u32, u32, u32, u32, Vec3)> = Vec::new(); // (cx0, cx1, cy0, cy1, colour)
    for cy in 0..gy {
        let mut cx = 0;
        while cx < gx {
            let colour = grid[(cy * gx + cx) as usize];
            let mut end = cx + 1;
            while end < gx && grid[(cy * gx + end) as usize] == colour {
                end += 1;
            }
            match rects.iter_mut().find(|r| r.1 == end && r.0 == cx && r.3 == cy && r.4 == colour) {
                Some(rect) => rect.3 = cy + 1,
                None => rects.push((cx, end, cy, cy + 1, colour)),
            }
            cx = end;
        }
    }
    rects
        .into_iter()
        .filter(|r| r.4.max_element() > 0.0)
        .map(|(cx0, cx1, cy0, cy1, colour)| {
            let s0 = col_edge(cx0) as f32 / image.width as f32;
            let s1 = col_edge(cx1) as f32 / image.width as f32;
            let t0 = row_edge(cy0) as f32 / image.height as f32;
            let t1 = row_edge(cy1) as f32 / image.height as f32;
            // (s0,t1) bottom-left, (s1,t1) bottom-right, (s1,t0) top-right, (s0,t0) top-left:
            // counter-clockwise for a viewer on the lit side (right = +r, up = +u).
            LightCell {
                corners: [light.image_point(s0, t1), light.image_point(s1, t1), light.image_point(s1, t0), light.image_point(s0, t0)],
                radiance: colour * light.intensity,
            }
        })
        .collect()
}

/// `∫ cosθx dω` over a polygon seen from `x` with normal `nx`, after clipping the polygon
/// to the hemisphere above x (Lambert's closed form for the vector irradiance: ½ Σ Θᵢ n·Γᵢ).
/// The CPU twin of `polygon_irradiance` in `shaders/common/light.wgsl`.
pub fn polygon_irradiance(x: Vec3, nx: Vec3, corners: &[Vec3; 4]) -> f32 {
    const EPS: f32 = 1e-6;
    let mut clipped: Vec<Vec3> = Vec::with_capacity(5);
    for k in 0..4 {
        let a = corners[k] - x;
        let b = corners[(k + 1) % 4] - x;
        let (da, db) = (a.dot(nx), b.dot(nx));
        if da > EPS {
            clipped.push(a);
        }
        if (da > EPS) != (db > EPS) {
            let t = (EPS - da) / (db - da);
            clipped.push(a + (b - a) * t);
        }
    }
    if clipped.len() < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    for k in 0..clipped.len() {
        let a = clipped[k].normalize();
        let b = clipped[(k + 1) % clipped.len()].normalize();
        let c = a.cross(b);
        let len = c.length();
        if len > 1e-12 {
            sum += len.atan2(a.dot(b)) * nx.dot(c / len);
        }
    }
    0.5 * sum.abs()
}

/// The unshadowed irradiance E0 at x (DESIGN.md §1), per channel: the sum over light cells.
pub fn unshadowed_irradiance(light: &AreaLight, cells: &[LightCell], x: Vec3, nx: Vec3) -> Vec3 {
    // One-sided emitter: only points on the lit side receive anything.
    if (x - light.center).dot(light.n) <= 0.0 {
        return Vec3::ZERO;
    }
    cells.iter().map(|c| c.radiance * polygon_irradiance(x, nx, &c.corners)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn overhead_light(size: f32) -> AreaLight {
        AreaLight::new(Vec3::new(0.0, 2.0, 0.0), -Vec3::Y, -Vec3::Z, Vec2::splat(size), 1.0).unwrap()
    }

    #[test]
    fn frame_follows_design() {
        let light = overhead_light(1.0);
        assert!((light.n - -Vec3::Y).length() < 1e-6);
        assert!((light.u - -Vec3::Z).length() < 1e-6);
        // r = cross(u, n) = cross(−z, −y) = −x.
        assert!((light.r - -Vec3::X).length() < 1e-6);
        // Column 0 (s = 0) is on the −r side, i.e. +x; row 0 (t = 0) on +u, i.e. −z.
        let top_left = light.image_point(0.0, 0.0);
        assert!((top_left - Vec3::new(0.5, 2.0, -0.5)).length() < 1e-6);
    }

    #[test]
    fn small_light_matches_point_source_law() {
        // A tiny square light straight above: E ≈ L·A·cosθx·cosθy / d².
        let light = overhead_light(0.01);
        let cells = light_cells(&light, &LightImage::builtin("white", &Map::new(), "f").unwrap());
        let e = unshadowed_irradiance(&light, &cells, Vec3::ZERO, Vec3::Y);
        let expected = 1e-4 / 4.0;
        assert!((e.x - expected).abs() / expected < 1e-3, "{e} vs {expected}");
    }

    #[test]
    fn large_light_tends_to_pi() {
        // An enormous light covers the whole hemisphere: ∫ cosθ dω = π.
        let light = overhead_light(1e4);
        let cells = light_cells(&light, &LightImage::builtin("white", &Map::new(), "f").unwrap());
        let e = unshadowed_irradiance(&light, &cells, Vec3::ZERO, Vec3::Y);
        assert!((e.x - std::f32::consts::PI).abs() < 1e-2, "{e}");
    }

    #[test]
    fn horizon_clipping_agrees_with_quadrature() {
        // A receiver tilted so that the light straddles its horizon.
        let light = overhead_light(2.0);
        let cells = light_cells(&light, &LightImage::builtin("white", &Map::new(), "f").unwrap());
        let x = Vec3::new(0.3, 0.0, 0.1);
        let nx = Vec3::new(1.0, 0.3, 0.0).normalize();
        let analytic = unshadowed_irradiance(&light, &cells, x, nx).x;
        // Midpoint quadrature of ∫ cosθx cosθy / d² dA.
        let n = 400;
        let mut sum = 0.0f64;
        for j in 0..n {
            for i in 0..n {
                let y = light.image_point((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                let d = y - x;
                let cx = nx.dot(d.normalize()).max(0.0);
                let cy = light.n.dot(-d.normalize()).max(0.0);
                sum += f64::from(cx * cy / d.length_squared());
            }
        }
        let numeric = sum as f32 * light.area_m2() / (n * n) as f32;
        assert!((analytic - numeric).abs() / numeric < 2e-3, "{analytic} vs {numeric}");
    }

    #[test]
    fn cells_merge_uniform_regions_and_drop_black() {
        let light = overhead_light(1.0);
        let none = Map::new();
        assert_eq!(light_cells(&light, &LightImage::builtin("white", &none, "f").unwrap()).len(), 1);
        assert_eq!(light_cells(&light, &LightImage::builtin("stripes", &none, "f").unwrap()).len(), 6);
        let disk = light_cells(&light, &LightImage::builtin("disk", &none, "f").unwrap());
        assert!(disk.len() < 64 && !disk.is_empty());
        // Total flux is preserved by merging: Σ radiance × area equals the image mean × area.
        let image = LightImage::builtin("flame", &none, "f").unwrap();
        let cells = light_cells(&light, &image);
        let flux: Vec3 =
            cells.iter().map(|c| c.radiance * (c.corners[1] - c.corners[0]).length() * (c.corners[3] - c.corners[0]).length()).sum();
        assert!((flux - image.mean_emission()).length() < 1e-4, "{flux} vs {}", image.mean_emission());
    }

    #[test]
    fn stripes_are_red_on_the_minus_r_side() {
        // DESIGN.md §1: column 0 along −r. The first stripe is red, so the receiver point
        // under the −r edge of the light gets more red than blue, and the +r edge the reverse.
        let light = overhead_light(1.0);
        let cells = light_cells(&light, &LightImage::builtin("stripes", &Map::new(), "f").unwrap());
        let under_minus_r = unshadowed_irradiance(&light, &cells, -light.r * 0.8, Vec3::Y);
        let under_plus_r = unshadowed_irradiance(&light, &cells, light.r * 0.8, Vec3::Y);
        assert!(under_minus_r.x > under_minus_r.z);
        assert!(under_plus_r.z > under_plus_r.x);
    }

    #[test]
    fn degenerate_lights_name_the_field() {
        let err = AreaLight::new(Vec3::ZERO, Vec3::ZERO, Vec3::Y, Vec2::ONE, 1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.direction"));
        let err = AreaLight::new(Vec3::ZERO, Vec3::Y, Vec3::Y, Vec2::ONE, 1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.up"));
        let err = AreaLight::new(Vec3::ZERO, Vec3::Y, Vec3::X, Vec2::new(1.0, 0.0), 1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.size[1]"));
        let err = AreaLight::new(Vec3::ZERO, Vec3::Y, Vec3::X, Vec2::ONE, -1.0).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("light.intensity"));
    }
}

#[cfg(test)]
mod fuzz_regressions {
    use super::*;

    /// `cargo fuzz run light_image` found this: a tiled EXR on which the `exr` crate panics
    /// when built with overflow checks (as fuzz builds are); either way it is `invalid_asset`.
    #[test]
    fn a_malformed_tiled_exr_is_an_invalid_asset() {
        let bytes = include_bytes!("../fuzz/regressions/light_image-exr-tiles.exr");
        let error = LightImage::decode(bytes, 64, "light.image").unwrap_err();
        assert_eq!(error.code, ErrorCode::InvalidAsset, "{}", error.message);
    }
}
