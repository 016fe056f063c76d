//! The area light (contract §1): its frame, its RGBA image, the built-in images, and the
//! exact unshadowed irradiance E0 that every method shares.
//!
//! Orientation is part of the contract: with `n = normalize(direction)`,
//! `u = normalize(up − (up·n)n)` and `r = normalize(cross(u, n))`, image row 0 lies along
//! `+u` and column 0 along `−r`, so that someone on the lit side looking back at the light
//! sees the image as an image viewer shows it. `AreaLight::texel_point` is the one place
//! that mapping is written down; the GPU gets corners computed here.

mod image;
mod irradiance;
pub mod tables;

use glam::{Vec2, Vec3};

use crate::error::{JobError, JobResult};
pub use image::{LightImage, BUILTIN_LIGHT_IMAGES};
pub use irradiance::{cells_bounds, edges_acute_from, light_cells, polygon_irradiance, unshadowed_irradiance, LightCell, E0_GRID};

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
    /// Builds the frame of contract §1, or names the field that makes it degenerate.
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
        crate::job::check_light_size_and_intensity(Some(size_m.to_array()), Some(intensity))?;
        Ok(Self { center, n, u, r, size_m, intensity })
    }

    /// World position of image coordinates `(s, t)` ∈ [0,1]²: s to the right from column 0,
    /// t downwards from row 0. Column 0 is at `−r`, row 0 at `+u` (contract §1).
    pub fn image_point(&self, s: f32, t: f32) -> Vec3 {
        self.center + self.r * ((s - 0.5) * self.size_m.x) + self.u * ((0.5 - t) * self.size_m.y)
    }

    /// Where `p` lies in the light's frame: metres along `r` and `u` from its centre (a point
    /// of the light's plane: the inverse of `image_point` up to the image's scale).
    pub fn plane_point(&self, p: Vec3) -> Vec2 {
        let d = p - self.center;
        Vec2::new(d.dot(self.r), d.dot(self.u))
    }

    /// How far `p` lies below the light's plane, along its normal: positive on the side it
    /// lights, 0 on the plane.
    pub fn depth(&self, p: Vec3) -> f32 {
        self.n.dot(p - self.center)
    }

    pub fn area_m2(&self) -> f32 {
        self.size_m.x * self.size_m.y
    }
}
