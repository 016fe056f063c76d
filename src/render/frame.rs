//! What one frame renders, resolved from a job and a scene: the job's camera and light
//! merged over the scene's defaults and checked, the light cut into cells for E0, the
//! method with its validated parameters, and the light-space projection of the shadow map.

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3};

use crate::error::{JobError, JobResult};
use crate::gpu::scene::GpuScene;
use crate::job::{Job, OutputFormat};
use crate::light::{edges_acute_from, light_cells, AreaLight, LightCell, LightImage, E0_GRID};
use crate::params::Params;
use crate::render::method::ShadowMethod;
use crate::scene::SceneDefaults;

/// The eye camera, complete and valid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub fov_y_deg: f32,
    pub near: f32,
    pub far: f32,
}

impl Camera {
    pub fn forward(&self) -> Vec3 {
        (self.target - self.eye).normalize()
    }

    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        Mat4::perspective_rh(self.fov_y_deg.to_radians(), aspect, self.near, self.far) * Mat4::look_at_rh(self.eye, self.target, self.up)
    }
}

/// The shadow map's projection: a square frustum from the light centre along `n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightProjection {
    pub view_proj: Mat4,
    /// Tangent of the frustum's half angle (the same horizontally and vertically).
    pub tan_half: f32,
    pub near: f32,
    pub far: f32,
    /// Depth along n of the scene's nearest bounding-box corner, at least `near`: no
    /// occluder lies closer to the light, which bounds the regions blocker searches scan.
    pub nearest: f32,
}

/// Widest half angle of the shadow frustum. Beyond it surfaces are lit at grazing angles
/// where E0 is tiny, and texels would be stretched too thin to be useful.
const MAX_LIGHT_HALF_ANGLE_DEG: f32 = 80.0;

impl LightProjection {
    /// Fits the frustum to the part of `points` in front of the light: the corners of the
    /// scene's bounding box, or what `GpuScene::shadow_fit_points` says must be in view.
    pub fn fit(light: &AreaLight, points: &[Vec3]) -> Self {
        let tan_max = MAX_LIGHT_HALF_ANGLE_DEG.to_radians().tan();
        let (lo, hi) = points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let radius = ((hi - lo) * 0.5).length().max(1e-3);
        let mut tan_half: f32 = 0.05;
        let mut far: f32 = 0.0;
        let mut min_depth = f32::INFINITY;
        for p in points {
            let d = *p - light.center;
            let depth = d.dot(light.n);
            far = far.max(depth);
            min_depth = min_depth.min(depth);
            let lateral = d.dot(light.r).abs().max(d.dot(light.u).abs());
            tan_half = if depth > 1e-3 * radius { tan_half.max(lateral / depth) } else { tan_max };
            if tan_half >= tan_max {
                tan_half = tan_max;
            }
        }
        let far = (far * 1.05).max(1e-2);
        let near = if min_depth > 0.0 { (min_depth * 0.5).max(far * 1e-4) } else { far * 1e-4 };
        let view = Mat4::look_to_rh(light.center, light.n, light.u);
        let proj = Mat4::perspective_rh(2.0 * tan_half.atan(), 1.0, near, far);
        Self { view_proj: proj * view, tan_half, near, far, nearest: min_depth.max(near).max(1e-3) }
    }
}

/// Which images the caller needs back from the GPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExtraImages {
    pub visibility: bool,
    pub depth: bool,
    /// The linear float colour (EXR, comparisons, callers that inspect the frame); without
    /// it only the PNG's 8-bit sRGB pixels come back, made on the GPU (a quarter of the
    /// bytes, and no per-pixel transfer function on the CPU).
    pub float_color: bool,
}

impl ExtraImages {
    /// EXR carries visibility and depth; a comparison needs the visibility. The linear
    /// colour always comes back: what `Engine::render_frame`'s callers inspect.
    pub fn for_job(job: &Job) -> Self {
        let exr = job.output.format == OutputFormat::Exr;
        Self { visibility: exr || job.compare, depth: exr, float_color: true }
    }

    /// What encoding the job's output needs, no more: a PNG without a comparison needs only
    /// its 8-bit pixels.
    pub fn for_encoding(job: &Job) -> Self {
        let exr = job.output.format == OutputFormat::Exr;
        Self { float_color: exr || job.compare, ..Self::for_job(job) }
    }
}

/// The camera, light and floor a frame was rendered with, complete, in the job's own terms
/// (contract §3): what a client needs to render the same image again, or to move the light
/// from where penumbra put it. `fitted` lists the fields the job left out, which came from
/// the scene's defaults (fitted to its bounds, for a file).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Staging {
    pub camera: StagedCamera,
    pub light: StagedLight,
    /// The floor under the scene (`"scene": {"floor": …}`), where the job asked for one.
    pub floor: Option<StagedFloor>,
    /// Fields taken from the scene's defaults: `camera.eye`, `light.center`, `light.image` …
    pub fitted: Vec<&'static str>,
}

#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct StagedCamera {
    pub eye: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
    pub fov_y_deg: f32,
    pub near: f32,
    pub far: f32,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StagedLight {
    pub center: [f32; 3],
    pub direction: [f32; 3],
    pub up: [f32; 3],
    pub size: [f32; 2],
    pub intensity: f32,
    pub image: crate::job::AssetRef,
}

impl Default for StagedLight {
    /// No light: a frame made without one (tests of what reads frames).
    fn default() -> Self {
        Self {
            center: [0.0; 3],
            direction: [0.0; 3],
            up: [0.0; 3],
            size: [0.0; 2],
            intensity: 0.0,
            image: crate::job::AssetRef::builtin("white"),
        }
    }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StagedFloor {
    pub albedo: [f32; 3],
    pub margin: f32,
    /// Its height (y), a hair below the lowest point of what stands on it.
    pub height: f32,
}

impl Staging {
    /// What `job` resolved to over `scene`'s defaults: `camera` and `light` as checked, the
    /// light's `direction` and `up` as given (the frame derives its axes from them).
    fn new(job: &Job, scene: &GpuScene, camera: &Camera, light: &AreaLight, (direction, up): (Vec3, Vec3)) -> Self {
        let (c, l) = (&job.camera, &job.light);
        let given = [
            ("camera.eye", c.eye.is_some()),
            ("camera.target", c.target.is_some()),
            ("camera.up", c.up.is_some()),
            ("camera.fov_y_deg", c.fov_y_deg.is_some()),
            ("camera.near", c.near.is_some()),
            ("camera.far", c.far.is_some()),
            ("light.center", l.center.is_some()),
            ("light.direction", l.direction.is_some()),
            ("light.up", l.up.is_some()),
            ("light.size", l.size.is_some()),
            ("light.intensity", l.intensity.is_some()),
            ("light.image", l.image.is_some()),
        ];
        Staging {
            camera: StagedCamera {
                eye: camera.eye.to_array(),
                target: camera.target.to_array(),
                up: camera.up.to_array(),
                fov_y_deg: camera.fov_y_deg,
                near: camera.near,
                far: camera.far,
            },
            light: StagedLight {
                center: light.center.to_array(),
                direction: direction.to_array(),
                up: up.to_array(),
                size: light.size_m.to_array(),
                intensity: light.intensity,
                image: l.image.clone().unwrap_or_else(|| scene.defaults.light_image.clone()),
            },
            floor: job.scene.floor.zip(scene.on_floor).map(|(floor, on)| StagedFloor {
                albedo: floor.albedo,
                margin: floor.margin,
                height: on.height,
            }),
            fitted: given.iter().filter(|(_, given)| !given).map(|(name, _)| *name).collect(),
        }
    }
}

/// Everything a frame needs, validated.
pub struct FrameSpec {
    pub camera: Camera,
    pub light: AreaLight,
    pub cells: Vec<LightCell>,
    /// No receiver sees an edge of the light under more than a right angle
    /// (`light::edges_acute_from`): Lambert's sums are specialised (`ACUTE_EDGES`).
    pub acute_edges: bool,
    pub light_image: Arc<LightImage>,
    pub method: &'static dyn ShadowMethod,
    pub params: Params,
    pub shadow_resolution: u32,
    pub width: u32,
    pub height: u32,
    pub ambient: Vec3,
    /// The PNG's exposure in stops (the 8-bit colour is made on the GPU).
    pub exposure: f32,
    pub extra_images: ExtraImages,
    /// The camera, light and floor as resolved, for the job's answer.
    pub staging: Staging,
}

impl FrameSpec {
    /// `acute_edges` as the pipeline constant of `shaders/common/light.wgsl`, for every pipeline
    /// whose shaders sum Lambert's edge terms (E0, `wedges`).
    pub fn acute_edges_constant(&self) -> (&'static str, f64) {
        ("ACUTE_EDGES", f64::from(u8::from(self.acute_edges)))
    }

    /// The light's cells are its whole `E0_GRID` × `E0_GRID` grid, none merged and none black
    /// (so listed row by row from the image's top, left to right: `light_cells`), as under a
    /// photograph: E0 sums each of the grid's corners and edges once for the cells that share
    /// it (`GRID` in `shaders/e0/grid.wgsl`).
    pub fn full_grid(&self) -> bool {
        self.cells.len() == (E0_GRID * E0_GRID) as usize
    }

    /// Merges the job over the scene's defaults and checks what the merge produced; `method`
    /// is the job's method with its checked parameters (`engine::check_job`).
    pub fn resolve(
        job: &Job,
        scene: &GpuScene,
        light_image: Arc<LightImage>,
        (method, params): (&'static dyn ShadowMethod, &Params),
    ) -> JobResult<Self> {
        let (camera, light, (direction, up)) = resolve_view(job, &scene.defaults, &scene.corners())?;
        let staging = Staging::new(job, scene, &camera, &light, (direction, up));
        Ok(Self {
            camera,
            cells: light_cells(&light, &light_image),
            acute_edges: edges_acute_from(&light, scene.bounds_min, scene.bounds_max),
            light_image,
            light,
            method,
            params: params.clone(),
            shadow_resolution: job.shadow_map.resolution,
            width: job.output.width,
            height: job.output.height,
            ambient: job.ambient.map(Vec3::from).unwrap_or(Vec3::ZERO),
            exposure: job.output.exposure,
            extra_images: ExtraImages::for_job(job),
            staging,
        })
    }
}

/// The job's camera and light merged over the scene's `defaults`, the camera's near and far
/// fitted to the scene's bounds (`corners`); with the light's direction and up as given.
pub fn resolve_view(job: &Job, defaults: &SceneDefaults, corners: &[Vec3; 8]) -> JobResult<(Camera, AreaLight, (Vec3, Vec3))> {
    let d = defaults;
    let v3 = |v: Option<[f32; 3]>, default: Vec3| v.map(Vec3::from).unwrap_or(default);
    let camera = resolve_camera(
        v3(job.camera.eye, d.eye),
        v3(job.camera.target, d.target),
        v3(job.camera.up, d.up),
        job.camera.fov_y_deg.unwrap_or(d.fov_y_deg),
        job.camera.near,
        job.camera.far,
        corners,
    )?;
    let l = &job.light;
    let (direction, up) = (v3(l.direction, d.light_direction), v3(l.up, d.light_up));
    let light = AreaLight::new(
        v3(l.center, d.light_center),
        direction,
        up,
        l.size.map(Vec2::from).unwrap_or(d.light_size_m),
        l.intensity.unwrap_or(d.light_intensity),
    )?;
    Ok((camera, light, (direction, up)))
}

fn resolve_camera(
    eye: Vec3,
    target: Vec3,
    up: Vec3,
    fov_y_deg: f32,
    near: Option<f32>,
    far: Option<f32>,
    corners: &[Vec3; 8],
) -> JobResult<Camera> {
    let given = crate::job::CameraSpec {
        eye: Some(eye.to_array()),
        target: Some(target.to_array()),
        up: Some(up.to_array()),
        fov_y_deg: Some(fov_y_deg),
        near,
        far,
    };
    given.check_given()?;
    if (target - eye).length() < 1e-6 {
        return Err(JobError::invalid("camera.target", "must differ from camera.eye"));
    }
    let forward = (target - eye).normalize();
    if up.length() < 1e-6 || up.normalize().cross(forward).length() < 1e-4 {
        return Err(JobError::invalid("camera.up", "must be non-zero and not parallel to the view direction"));
    }
    // Fit near and far to the scene's depth range along the view direction.
    let depths: Vec<f32> = corners.iter().map(|p| (*p - eye).dot(forward)).collect();
    let fitted_far = (depths.iter().copied().fold(f32::MIN, f32::max) * 1.02).max(1e-2);
    let fitted_near = {
        let nearest = depths.iter().copied().fold(f32::MAX, f32::min);
        if nearest > 0.0 {
            (nearest * 0.9).max(fitted_far * 1e-4)
        } else {
            fitted_far * 1e-4
        }
    };
    let near = near.unwrap_or(fitted_near);
    let far = far.unwrap_or(fitted_far.max(near * 2.0));
    if !(near.is_finite() && near > 0.0) {
        return Err(JobError::invalid("camera.near", "must be a finite number > 0"));
    }
    if !(far.is_finite() && far > near) {
        return Err(JobError::invalid("camera.far", "must be finite and greater than camera.near"));
    }
    Ok(Camera { eye, target, up, fov_y_deg, near, far })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn corners() -> [Vec3; 8] {
        [0, 1, 2, 3, 4, 5, 6, 7].map(|k| Vec3::new((k & 1) as f32 * 2.0 - 1.0, (k >> 1 & 1) as f32, (k >> 2 & 1) as f32 * 2.0 - 1.0))
    }

    #[test]
    fn degenerate_cameras_name_the_field() {
        let c = corners();
        let eye = Vec3::new(0.0, 2.0, 5.0);
        let err = resolve_camera(eye, eye, Vec3::Y, 45.0, None, None, &c).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("camera.target"));
        for fov in [0.0, 180.0, -3.0, f32::NAN] {
            let err = resolve_camera(eye, Vec3::ZERO, Vec3::Y, fov, None, None, &c).unwrap_err();
            assert_eq!(err.field.as_deref(), Some("camera.fov_y_deg"));
        }
        let err = resolve_camera(Vec3::Y * 3.0, Vec3::ZERO, Vec3::Y, 45.0, None, None, &c).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("camera.up"));
        let err = resolve_camera(eye, Vec3::ZERO, Vec3::Y, 45.0, Some(2.0), Some(1.0), &c).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("camera.far"));
    }

    #[test]
    fn fitted_range_contains_the_scene() {
        let camera = resolve_camera(Vec3::new(0.0, 2.0, 5.0), Vec3::ZERO, Vec3::Y, 45.0, None, None, &corners()).unwrap();
        for p in corners() {
            let depth = (p - camera.eye).dot(camera.forward());
            assert!(depth > camera.near && depth < camera.far);
        }
    }

    #[test]
    fn light_frustum_contains_the_scene_below() {
        let light = AreaLight::new(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, -Vec3::Z, Vec2::ONE, 1.0).unwrap();
        let projection = LightProjection::fit(&light, &corners());
        for p in corners() {
            let clip = projection.view_proj * p.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            assert!(ndc.x.abs() <= 1.0 + 1e-5 && ndc.y.abs() <= 1.0 + 1e-5 && (0.0..=1.0).contains(&ndc.z), "{p} → {ndc}");
        }
        // Image up (+u = −z) is NDC +y, i.e. shadow-map row 0.
        let clip = projection.view_proj * Vec3::new(0.0, 0.0, -1.0).extend(1.0);
        assert!(clip.y / clip.w > 0.0);
    }
}
