//! The engine's frames on the device: one at a time under the device lock, inside a GPU
//! validation scope, and — when the device is lost before or during a job — on a new device
//! with the job retried once, so a driver reset costs one slow job, not the daemon.

use std::sync::Arc;
use std::time::Instant;

use super::{check_job, Engine, RenderState};
use crate::error::{JobError, JobResult};
use crate::gpu::GpuContext;
use crate::job::Job;
use crate::methods::ShadowMethod;
use crate::params::Params;
use crate::render::{ExtraImages, FrameOutput, FrameSpec, Renderer};
use crate::supervise::{cancelled_error, Supervisor};
use crate::timing::PhaseName;
use crate::timing::Timings;

impl Engine {
    /// Checks and renders one job, returning the linear float frame (what `output::encode`
    /// turns into PNG or EXR, and what quality measurements compare) and its timings.
    pub fn render_frame(&self, job: &Job, supervisor: &dyn Supervisor) -> JobResult<(FrameOutput, Timings)> {
        self.render_frame_reading(job, supervisor, ExtraImages::for_job)
    }

    /// `render_frame`, reading back what `images` says the job needs (`Engine::render`
    /// reads a PNG's 8-bit pixels only).
    pub(super) fn render_frame_reading(
        &self,
        job: &Job,
        supervisor: &dyn Supervisor,
        images: fn(&Job) -> ExtraImages,
    ) -> JobResult<(FrameOutput, Timings)> {
        let (method, params) = check_job(job, &self.limits)?;
        let mut state = self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        // Stopped while it waited for the device: nothing to render.
        if supervisor.cancelled() {
            return Err(cancelled_error());
        }
        if state.renderer.gpu().is_lost() {
            self.recover_device(&mut state)?;
        }
        match self.render_on_device(&mut state, job, (method, &params), images, supervisor) {
            Err(_) if state.renderer.gpu().is_lost() => {
                self.recover_device(&mut state)?;
                tracing::warn!("retrying the job once on the new device");
                self.render_on_device(&mut state, job, (method, &params), images, supervisor)
            }
            outcome => outcome,
        }
    }

    /// How every later frame evaluates E0 (`penumbra bench` measures the interpolation
    /// against the exact sum with it).
    pub fn set_e0_mode(&self, mode: crate::render::E0Mode) {
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).renderer.e0_mode = mode;
    }

    fn render_on_device(
        &self,
        state: &mut RenderState,
        job: &Job,
        method: (&'static dyn ShadowMethod, &Params),
        images: fn(&Job) -> ExtraImages,
        supervisor: &dyn Supervisor,
    ) -> JobResult<(FrameOutput, Timings)> {
        let mut timings = Timings::default();
        let start = Instant::now();
        let scene = self.scene(state, &job.scene, &mut timings)?;
        timings.scene_triangles = scene.triangles;
        timings.scene_textures = scene.textures;
        let image_ref = job.light.image.clone().unwrap_or_else(|| scene.defaults.light_image.clone());
        let light_image = self.light_image(state, &image_ref)?;
        let spec = FrameSpec { extra_images: images(job), ..FrameSpec::resolve(job, &scene, light_image, method)? };
        timings.phase(PhaseName::Scene, start);
        // Validation errors inside wgpu are bugs in penumbra, never the client's fault; they
        // fail this job alone with a generic message and are logged in full. A failed map or
        // poll (a lost device, typically) comes back as this job's error.
        let gpu = state.renderer.gpu().clone();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let frame = state.renderer.render(&scene, &spec, &mut timings, supervisor);
        if let Some(error) = pollster::block_on(scope.pop()) {
            tracing::error!(%error, "GPU validation error while rendering");
            return Err(JobError::internal("the renderer failed on the GPU"));
        }
        Ok((frame?, timings))
    }

    /// Replaces a lost device: a new device on the same kind of adapter, a new renderer (its
    /// pipelines and pools belonged to the old device) and no GPU scenes; CPU caches stay.
    fn recover_device(&self, state: &mut RenderState) -> JobResult<()> {
        let choice = state.renderer.gpu().choice;
        let gpu = GpuContext::new(choice).map_err(|error| {
            tracing::error!(%error, "GPU device lost and no new device could be opened");
            JobError::internal("the GPU device was lost and could not be reopened")
        })?;
        let gpu = Arc::new(gpu);
        state.renderer = Renderer::new(gpu.clone());
        state.renderer.set_pool_budget(self.pool_bytes);
        state.renderer.cpu_working_bytes = self.limits.max_cpu_working_bytes;
        state.scenes.clear();
        *self.gpu.write().unwrap_or_else(|p| p.into_inner()) = gpu.clone();
        let resets = self.device_resets.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        tracing::warn!(adapter = %gpu.adapter.name, resets, "GPU device lost: opened a new device; pipelines and scenes are rebuilt on demand");
        Ok(())
    }

    /// Times the device was lost and replaced.
    pub fn device_resets(&self) -> u64 {
        self.device_resets.load(std::sync::atomic::Ordering::Relaxed)
    }
}
