//! The engine: the warm state behind every interface. It owns the renderer (device,
//! pipelines, target pool) and the caches of GPU scenes, decoded light images and reference
//! frames, turns a `Job` into an encoded image with its timing breakdown, and is shared by the
//! CLI (`penumbra render`) and the HTTP server alike, so both take exactly the same path.
//!
//! Frames go through the device one at a time (the renderer's targets and timer are per
//! frame: `state`), but a job's CPU work around its frame — decoding its assets on a cache
//! miss, comparing with the reference, encoding the image — runs outside that lock, so
//! several jobs in progress overlap one's CPU work with another's frame.

mod assets;
mod check;
mod device;
mod ingest;
mod lru;
mod stats;

use std::sync::{Arc, Mutex};
use std::time::Instant;

pub use assets::PathPolicy;
pub use check::check_job;
pub use ingest::UploadReceipt;
pub use stats::EngineStats;

use crate::error::JobResult;
use crate::gpu::scene::GpuScene;
pub use crate::gpu::AdapterSummary;
use crate::gpu::GpuContext;
use crate::job::{AssetRef, Job, Limits, OutputFormat};
use crate::light::LightImage;
use crate::methods::Counters;
use crate::quality::QualityReport;
use crate::render::{FrameOutput, Renderer};
use crate::supervise::Supervisor;
use crate::timing::PhaseName;
use crate::timing::Timings;
use crate::upload_store::{Kind, UploadStore};
use lru::Lru;

/// A finished render: the encoded image and what it cost.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// The method that rendered it (`method.name` of the job).
    pub method: String,
    pub bytes: Vec<u8>,
    pub format: OutputFormat,
    pub width: u32,
    pub height: u32,
    pub timings: Timings,
    pub counters: Counters,
    /// Metrics against `reference`, when the job asked to `compare`.
    pub quality: Option<QualityReport>,
    /// What penumbra left out of the scene or repaired in it (contract §3).
    pub warnings: Vec<String>,
    /// The camera, light and floor it was rendered with (contract §3).
    pub staging: crate::render::Staging,
    /// The SHA-256 of `bytes`, computed when first asked for (records and `ETag`s).
    pub digest: std::sync::OnceLock<String>,
    /// What `auto` chose, when the job asked for it (set by the server, which resolves it).
    pub auto: Option<crate::job::auto::AutoChoice>,
    /// A progressive job's rounds and why it stopped (set by the server, which runs them).
    pub progressive: Option<crate::job::progressive::ProgressiveOutcome>,
}

impl Rendered {
    /// The lowercase hex SHA-256 of the encoded image: what a job's record names and its
    /// image's `ETag` is.
    pub fn image_sha256(&self) -> &str {
        self.digest.get_or_init(|| crate::upload_store::content_id(&self.bytes))
    }
}

/// Reference frames kept for `compare` (each is a few MB of floats).
const REFERENCE_CACHE_ENTRIES: usize = 8;

/// Most scenes kept on the GPU at once (least recently used ones are dropped first).
const SCENE_CACHE_ENTRIES: usize = 16;

/// Most decoded light images kept at once.
const LIGHT_CACHE_ENTRIES: usize = 16;

/// Default byte budget of the upload cache.
pub const DEFAULT_CACHE_BYTES: u64 = 1 << 30;

/// What the device is used with, one frame at a time: the renderer and the GPU copies of
/// scenes; decoded light images beside them (their cache keys need the upload store's lock).
struct RenderState {
    renderer: Renderer,
    scenes: Lru<String, Arc<GpuScene>>,
    lights: Lru<String, Arc<LightImage>>,
}

pub struct Engine {
    /// The device in use; replaced (under the state lock) when the device is lost.
    gpu: std::sync::RwLock<Arc<GpuContext>>,
    device_resets: std::sync::atomic::AtomicU64,
    limits: Limits,
    paths: PathPolicy,
    uploads: Mutex<UploadStore>,
    /// `stats()` as of the last time the renderer was free.
    last_stats: Mutex<EngineStats>,
    /// One frame at a time on the device.
    state: Mutex<RenderState>,
    references: Mutex<Lru<String, Arc<FrameOutput>>>,
    /// The renderer's pool budget (`with_pool_budget`), kept for a renderer made anew.
    pool_bytes: u64,
    /// Built-in scenes' shapes by asset key, for estimates (`scene_shape`).
    builtin_shapes: Mutex<std::collections::HashMap<String, crate::scene::Shape>>,
}

impl Engine {
    pub fn new(gpu: Arc<GpuContext>, mut limits: Limits, paths: PathPolicy) -> Self {
        // A frame's per-pixel buffers (visibility, E0: a `vec4<f32>` a pixel) are bound whole,
        // so the device's largest storage binding caps a frame's pixels (lavapipe's 128 MiB:
        // 8,388,608). Beyond it every job would fail on the device; lowered, they are refused
        // up front with the field named, and `/v1/limits` says the limit that holds.
        let device_pixels = gpu.limits.max_storage_buffer_binding_size / 16;
        if limits.max_output_pixels > device_pixels {
            // Said as a warning only when the operator asked for more than the default.
            if limits.max_output_pixels > Limits::default().max_output_pixels {
                tracing::warn!(
                    max_output_pixels = limits.max_output_pixels,
                    device_pixels,
                    "output pixels lowered to what the device binds"
                );
            } else {
                tracing::info!(
                    max_output_pixels = limits.max_output_pixels,
                    device_pixels,
                    "output pixels lowered to what the device binds"
                );
            }
            limits.max_output_pixels = device_pixels;
        }
        // Honoured as configured (a scene over the device's limit then fails its own job at
        // upload), but said once, since it is almost certainly not what the operator meant.
        let device_max = gpu.limits.max_texture_dimension_2d;
        if limits.max_texture_dim > device_max {
            tracing::warn!(max_texture_dim = limits.max_texture_dim, device_max, "textures above the device's limit will fail their jobs");
        }
        let mut renderer = Renderer::new(gpu.clone());
        renderer.cpu_working_bytes = limits.max_cpu_working_bytes;
        let state = RenderState { renderer, scenes: Lru::new(SCENE_CACHE_ENTRIES), lights: Lru::new(LIGHT_CACHE_ENTRIES) };
        Self {
            gpu: std::sync::RwLock::new(gpu),
            device_resets: Default::default(),
            limits,
            paths,
            state: Mutex::new(state),
            references: Mutex::new(Lru::new(REFERENCE_CACHE_ENTRIES)),
            uploads: Mutex::new(UploadStore::new(DEFAULT_CACHE_BYTES)),
            last_stats: Mutex::new(EngineStats::default()),
            pool_bytes: crate::gpu::pool::DEFAULT_POOL_BYTES,
            builtin_shapes: Mutex::default(),
        }
    }

    /// Sets the upload cache's byte budget (scenes count their CPU and GPU copies).
    pub fn with_cache_budget(self, bytes: u64) -> Self {
        Self { uploads: Mutex::new(UploadStore::new(bytes)), ..self }
    }

    /// Sets how many bytes of idle GPU targets and scratch buffers the renderer keeps for
    /// later frames (`Renderer::set_pool_budget`), now and after a device is replaced.
    pub fn with_pool_budget(self, bytes: u64) -> Self {
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).renderer.set_pool_budget(bytes);
        Self { pool_bytes: bytes, ..self }
    }

    /// What the engine renders on now: the adapter's name, backend, kind and driver.
    pub fn adapter(&self) -> AdapterSummary {
        self.gpu().adapter.clone()
    }

    /// The device in use now (another engine may share it: tests, several configurations).
    pub fn gpu(&self) -> Arc<GpuContext> {
        self.gpu.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Checks a job before it is accepted to run later: everything `check_job` checks, and
    /// that the files it names may be read (a 202 must not turn into `path_not_allowed`
    /// later). With `uploads_here`, also that the uploads it names are held (a shared store
    /// may hold them for another replica instead). An upload can still be evicted before the
    /// job runs.
    pub fn check(&self, job: &Job, uploads_here: bool) -> JobResult<()> {
        check_job(job, &self.limits)?;
        let light = job.light.image.as_ref();
        for (kind, asset, field) in [(Kind::Scene, Some(&job.scene.asset), "scene"), (Kind::Light, light, "light.image")] {
            match asset {
                Some(AssetRef::Path(path)) => drop(self.resolve_path(path, &format!("{field}.path"))?),
                Some(AssetRef::Id(id)) if uploads_here && !self.holds_upload(kind, id) => {
                    return Err(assets::not_uploaded(id, &format!("{field}.id")));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Renders a tiny frame with every method so that the first real job finds its
    /// pipelines compiled and the default scene uploaded.
    pub fn warm_up(&self) -> JobResult<()> {
        for method in crate::methods::REGISTRY {
            let mut job = Job::embedded_default();
            job.method.name = method.name().into();
            // The cheapest valid setting of every integer parameter (sample counts,
            // resolutions): warm-up is about compiling pipelines, not about the picture.
            for spec in method.params() {
                if let crate::params::ParamKind::Integer { min, .. } = spec.kind {
                    job.method.params.insert(spec.name.into(), min.into());
                }
            }
            job.output.width = 8;
            job.output.height = 8;
            job.shadow_map.resolution = 64;
            self.render(&job, &|_, _| {})?;
        }
        Ok(())
    }

    /// Checks, renders and encodes one job, reporting the progress of long methods to
    /// `supervisor` (steps done, steps in all), which may also stop it.
    pub fn render(&self, job: &Job, supervisor: &dyn Supervisor) -> JobResult<Rendered> {
        self.render_compared(job, &job.reference_job(), supervisor)
    }

    /// `render`, measured (where the job asks to `compare`) against `reference` rather than
    /// the default reference: an `auto` job is measured against the truth its model's errors
    /// were measured against.
    pub fn render_compared(&self, job: &Job, reference: &Job, supervisor: &dyn Supervisor) -> JobResult<Rendered> {
        let started = Instant::now();
        let (frame, mut timings) = self.render_frame_reading(job, supervisor, crate::render::ExtraImages::for_encoding)?;
        // The frame is on the CPU: what follows runs outside the device lock.
        let quality = if job.compare {
            let start = Instant::now();
            let reference = self.reference_for(reference, supervisor)?;
            let start = timings.phase(PhaseName::Reference, start);
            let report = crate::quality::compare(&frame, &reference, job.output.exposure);
            timings.phase(PhaseName::Quality, start);
            Some(report)
        } else {
            None
        };
        let start = Instant::now();
        let bytes = crate::output::encode(&frame, job.output.format, job.output.exposure)?;
        timings.phase(PhaseName::Encode, start);
        timings.total_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok(Rendered {
            method: job.method.name.clone(),
            bytes,
            format: job.output.format,
            width: frame.width,
            height: frame.height,
            timings,
            counters: frame.counters,
            quality,
            warnings: frame.warnings,
            staging: frame.staging,
            digest: std::sync::OnceLock::new(),
            auto: None,
            progressive: None,
        })
    }

    /// A reference frame (`Job::reference_job`, or another reference method's) for a job's
    /// scene, view, light and size, rendered once and cached, so a sweep over methods renders
    /// it once.
    pub fn reference_for(&self, reference_job: &Job, supervisor: &dyn Supervisor) -> JobResult<Arc<FrameOutput>> {
        let key = format!(
            "{}|{}",
            self.scene_key(&reference_job.scene)?,
            serde_json::to_string(reference_job).map_err(|e| crate::error::JobError::internal(e.to_string()))?
        );
        if let Some(frame) = self.references.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
            return Ok(frame);
        }
        let (frame, _) = self.render_frame(reference_job, supervisor)?;
        let frame = Arc::new(frame);
        self.references.lock().unwrap_or_else(|p| p.into_inner()).insert(key, frame.clone());
        Ok(frame)
    }
}
