//! The engine: the warm state behind every interface. It owns the renderer (device,
//! pipelines, target pool) and the caches of uploaded scenes and decoded light images, turns
//! a `Job` into an encoded image with its timing breakdown, and is shared by the CLI
//! (`penumbra render`) and the HTTP server alike, so both take exactly the same path.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde::Serialize;

use crate::error::{ErrorCode, JobError, JobResult};
use crate::gpu::scene::GpuScene;
use crate::gpu::GpuContext;
use crate::job::{AssetRef, Job, Limits, OutputFormat};
use crate::light::LightImage;
use crate::methods::Counters;
use crate::quality::QualityReport;
use crate::render::{FrameOutput, FrameSpec, Observer, Renderer};
use crate::scene::{self, builtin};
use crate::timing::Timings;
use crate::uploads::{content_id, Asset, Kind, UploadStats, UploadStore};

/// Where `{"path": ...}` assets may be read from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PathPolicy {
    /// Any path (the CLI: the user reads their own files).
    Any,
    /// Only files inside this directory, after resolving symlinks (`serve --scene-dir`).
    Under(PathBuf),
    /// No paths at all (`serve` without `--scene-dir`).
    Deny,
}

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
}

/// Counts for `/v1/stats` and logs.
#[derive(Debug, Clone, Default, Serialize)]
pub struct EngineStats {
    pub scenes_cached: usize,
    pub scene_cache_hits: u64,
    pub scene_cache_misses: u64,
    pub pipelines: usize,
    pub pipelines_compiled: u64,
    pub targets_created: u64,
    pub targets_reused: u64,
    /// Look-up tables and other resources derived from a job's light, built or reused.
    pub derived_created: u64,
    pub derived_reused: u64,
    /// Readback buffers allocated or taken from the pool.
    pub readbacks_created: u64,
    pub readbacks_reused: u64,
    pub reference_cache_hits: u64,
    pub reference_cache_misses: u64,
    pub uploads: UploadStats,
    /// Times the GPU device was lost and replaced.
    pub device_resets: u64,
}

/// Reference frames kept for `compare` (each is a few MB of floats).
const REFERENCE_CACHE_ENTRIES: usize = 8;

/// Most scenes kept on the GPU at once (least recently used ones are dropped first).
const SCENE_CACHE_ENTRIES: usize = 16;

struct CachedScene {
    scene: Arc<GpuScene>,
    last_used: u64,
}

struct State {
    renderer: Renderer,
    scenes: HashMap<String, CachedScene>,
    lights: HashMap<String, Arc<LightImage>>,
    clock: u64,
    hits: u64,
    misses: u64,
}

/// What an upload answers: the asset's id, whether this upload stored it (false: the same
/// bytes were already there), and what it costs the cache.
#[derive(Debug, Clone, Serialize)]
pub struct UploadReceipt {
    pub id: String,
    pub created: bool,
    pub cache_bytes: u64,
}

/// Default byte budget of the upload cache.
pub const DEFAULT_CACHE_BYTES: u64 = 1 << 30;

pub struct Engine {
    /// The device in use; replaced (under the state lock) when the device is lost.
    gpu: std::sync::RwLock<Arc<GpuContext>>,
    device_resets: std::sync::atomic::AtomicU64,
    limits: Limits,
    paths: PathPolicy,
    uploads: Mutex<UploadStore>,
    /// `stats()` as of the last time the renderer was free.
    last_stats: Mutex<EngineStats>,
    // One frame at a time on the device: the renderer's targets and timer are per frame.
    state: Mutex<State>,
    references: Mutex<HashMap<String, Arc<FrameOutput>>>,
    reference_hits: std::sync::atomic::AtomicU64,
    reference_misses: std::sync::atomic::AtomicU64,
}

impl Engine {
    pub fn new(gpu: Arc<GpuContext>, limits: Limits, paths: PathPolicy) -> Self {
        // Honoured as configured (a scene over the device's limit then fails its own job at
        // upload), but said once, since it is almost certainly not what the operator meant.
        let device_max = gpu.limits.max_texture_dimension_2d;
        if limits.max_texture_dim > device_max {
            tracing::warn!(max_texture_dim = limits.max_texture_dim, device_max, "textures above the device's limit will fail their jobs");
        }
        let renderer = Renderer::new(gpu.clone());
        let state = State { renderer, scenes: HashMap::new(), lights: HashMap::new(), clock: 0, hits: 0, misses: 0 };
        Self {
            gpu: std::sync::RwLock::new(gpu),
            device_resets: Default::default(),
            limits,
            paths,
            state: Mutex::new(state),
            references: Mutex::new(HashMap::new()),
            reference_hits: Default::default(),
            reference_misses: Default::default(),
            uploads: Mutex::new(UploadStore::new(DEFAULT_CACHE_BYTES)),
            last_stats: Mutex::new(EngineStats::default()),
        }
    }

    /// Sets the upload cache's byte budget (scenes count their CPU and GPU copies).
    pub fn with_cache_budget(self, bytes: u64) -> Self {
        Self { uploads: Mutex::new(UploadStore::new(bytes)), ..self }
    }

    /// Stores a glTF (JSON with `data:` buffers) or GLB scene; validated now, so a bad file
    /// is refused at upload, not at its first render.
    pub fn upload_scene(&self, bytes: &[u8]) -> JobResult<UploadReceipt> {
        self.upload(Kind::Scene, bytes)
    }

    /// Stores a PNG or EXR light image.
    pub fn upload_light(&self, bytes: &[u8]) -> JobResult<UploadReceipt> {
        self.upload(Kind::Light, bytes)
    }

    /// Stores an upload of either kind under its content id (`content_id(bytes)`).
    pub fn upload(&self, kind: Kind, bytes: &[u8]) -> JobResult<UploadReceipt> {
        let id = content_id(bytes);
        if self.lock_uploads().touch(kind, &id) {
            return Ok(UploadReceipt { id, created: false, cache_bytes: 0 });
        }
        let asset = match kind {
            Kind::Scene => Asset::Scene(Arc::new(scene::gltf::load(bytes, &self.limits, "body")?)),
            Kind::Light => Asset::Light(Arc::new(LightImage::decode(bytes, self.limits.max_light_image_dim, "body")?)),
        };
        self.store_upload(id, asset)
    }

    /// Whether the server holds the upload `id` of this kind (`HEAD /v1/scenes/{id}`).
    /// Checks a job before it is accepted to run later: its fields and limits, and that the
    /// files it names may be read (a 202 must not turn into `path_not_allowed` later). With
    /// `uploads_here`, also that the uploads it names are held (a shared store may hold them
    /// for another replica instead). An upload can still be evicted before the job runs.
    pub fn check(&self, job: &Job, uploads_here: bool) -> JobResult<()> {
        job.validate(&self.limits)?;
        let light = job.light.image.as_ref();
        for (kind, asset, field) in [(Kind::Scene, Some(&job.scene), "scene"), (Kind::Light, light, "light.image")] {
            match asset {
                Some(AssetRef::Path(path)) => drop(self.resolve_path(path, &format!("{field}.path"))?),
                Some(AssetRef::Id(id)) if uploads_here && !self.holds_upload(kind, id) => {
                    return Err(not_uploaded(id, &format!("{field}.id")));
                }
                _ => {}
            }
        }
        Ok(())
    }

    pub fn holds_upload(&self, kind: Kind, id: &str) -> bool {
        self.lock_uploads().contains(kind, id)
    }

    fn store_upload(&self, id: String, asset: Asset) -> JobResult<UploadReceipt> {
        if self.lock_uploads().touch(asset.kind(), &id) {
            return Ok(UploadReceipt { id, created: false, cache_bytes: 0 });
        }
        let cache_bytes = asset.cost();
        self.lock_uploads().insert(id.clone(), asset)?;
        self.prune_if_free();
        Ok(UploadReceipt { id, created: true, cache_bytes })
    }

    /// Removes an upload; false when there was none under `id`.
    pub fn delete_upload(&self, kind: Kind, id: &str) -> bool {
        let removed = self.lock_uploads().remove(kind, id);
        self.prune_if_free();
        removed
    }

    pub fn upload_stats(&self) -> UploadStats {
        self.lock_uploads().stats()
    }

    fn lock_uploads(&self) -> std::sync::MutexGuard<'_, UploadStore> {
        self.uploads.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Drops the GPU copies of evicted or deleted uploads now when the renderer is free; while
    /// it renders, the next job's `prune_gone_uploads` does (an upload never waits for a render).
    fn prune_if_free(&self) {
        let mut state = match self.state.try_lock() {
            Ok(state) => state,
            Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => return,
        };
        self.prune_gone_uploads(&mut state);
    }

    /// The uploaded asset under `id`, or `not_uploaded` naming `field`.
    fn uploaded(&self, kind: Kind, id: &str, field: &str) -> JobResult<Asset> {
        self.lock_uploads().get(kind, id).ok_or_else(|| not_uploaded(id, field))
    }

    /// The device in use now (another engine may share it: tests, several configurations).
    pub fn gpu(&self) -> Arc<GpuContext> {
        self.gpu.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Times the device was lost and replaced.
    pub fn device_resets(&self) -> u64 {
        self.device_resets.load(std::sync::atomic::Ordering::Relaxed)
    }

    pub fn limits(&self) -> &Limits {
        &self.limits
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
                if let crate::methods::ParamKind::Integer { min, .. } = spec.kind {
                    job.method.params.insert(spec.name.into(), min.into());
                }
            }
            job.output.width = 8;
            job.output.height = 8;
            job.shadow_map.resolution = 64;
            self.render(&job)?;
        }
        Ok(())
    }

    /// Validates, renders and encodes one job.
    pub fn render(&self, job: &Job) -> JobResult<Rendered> {
        self.render_observed(job, &|_, _| {})
    }

    /// `render`, reporting the progress of long methods to `observer` (steps done, steps in
    /// all), which may also cancel it.
    pub fn render_observed(&self, job: &Job, observer: &dyn Observer) -> JobResult<Rendered> {
        let started = Instant::now();
        let (frame, mut timings) = self.render_raw_observed(job, observer)?;
        let quality = if job.compare {
            let start = Instant::now();
            let reference = self.reference_for(job, observer)?;
            let start = timings.phase("reference", start);
            let report = crate::quality::compare(&frame, &reference, job.output.exposure);
            timings.phase("quality", start);
            Some(report)
        } else {
            None
        };
        let start = Instant::now();
        let bytes = crate::output::encode(&frame, job.output.format, job.output.exposure)?;
        timings.phase("encode", start);
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
        })
    }

    /// The reference frame for a job's scene, view, light and size, rendered once and
    /// cached, so a sweep over methods renders it once.
    pub fn reference_for(&self, job: &Job, observer: &dyn Observer) -> JobResult<Arc<FrameOutput>> {
        let reference_job = job.reference_job();
        let key = format!(
            "{}|{}",
            self.asset_key(&job.scene, Kind::Scene, "scene")?,
            serde_json::to_string(&reference_job).map_err(|e| JobError::internal(e.to_string()))?
        );
        if let Some(frame) = self.references.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
            self.reference_hits.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            return Ok(frame.clone());
        }
        self.reference_misses.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let (frame, _) = self.render_raw_observed(&reference_job, observer)?;
        let frame = Arc::new(frame);
        let mut references = self.references.lock().unwrap_or_else(|p| p.into_inner());
        if references.len() >= REFERENCE_CACHE_ENTRIES {
            references.clear();
        }
        references.insert(key, frame.clone());
        Ok(frame)
    }

    /// Validates and renders one job, returning the linear float frame (what `encode`
    /// turns into PNG or EXR, and what quality measurements compare).
    pub fn render_raw(&self, job: &Job) -> JobResult<(FrameOutput, Timings)> {
        self.render_raw_observed(job, &|_, _| {})
    }

    /// Renders on the device; when the device is lost (before or during the job) it opens a
    /// new one and retries the job once, so a driver reset costs one slow job, not the daemon.
    pub fn render_raw_observed(&self, job: &Job, observer: &dyn Observer) -> JobResult<(FrameOutput, Timings)> {
        job.validate(&self.limits)?;
        let mut state = self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        // Cancelled while it waited for the device: nothing to render.
        if observer.cancelled() {
            return Err(crate::render::cancelled_error());
        }
        if state.renderer.gpu().is_lost() {
            self.recover_device(&mut state)?;
        }
        match self.render_on_device(&mut state, job, observer) {
            Err(_) if state.renderer.gpu().is_lost() => {
                self.recover_device(&mut state)?;
                tracing::warn!("retrying the job once on the new device");
                self.render_on_device(&mut state, job, observer)
            }
            outcome => outcome,
        }
    }

    fn render_on_device(&self, state: &mut State, job: &Job, observer: &dyn Observer) -> JobResult<(FrameOutput, Timings)> {
        let mut timings = Timings::default();
        let start = Instant::now();
        let scene = self.scene(state, &job.scene, &mut timings)?;
        timings.scene_triangles = scene.triangles;
        let image_ref = job.light.image.clone().unwrap_or_else(|| scene.defaults.light_image.clone());
        let light_image = self.light_image(state, &image_ref)?;
        let spec = FrameSpec::resolve(job, &scene, light_image)?;
        timings.phase("scene", start);
        // A lost device makes readbacks fail deep inside the renderer, which treats mapping
        // as infallible; the panic is caught here and becomes this job's error (or a retry).
        let frame =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.render_frame(state, &scene, &spec, &mut timings, observer)))
                .unwrap_or_else(|_| Err(JobError::internal("the renderer failed on the GPU")))?;
        Ok((frame, timings))
    }

    /// Replaces a lost device: a new device on the same kind of adapter, a new renderer (its
    /// pipelines and pools belonged to the old device) and no GPU scenes; CPU caches stay.
    fn recover_device(&self, state: &mut State) -> JobResult<()> {
        let choice = state.renderer.gpu().choice;
        let gpu = GpuContext::new(choice).map_err(|error| {
            tracing::error!(%error, "GPU device lost and no new device could be opened");
            JobError::internal("the GPU device was lost and could not be reopened")
        })?;
        let gpu = Arc::new(gpu);
        state.renderer = Renderer::new(gpu.clone());
        state.scenes.clear();
        *self.gpu.write().unwrap_or_else(|p| p.into_inner()) = gpu.clone();
        let resets = self.device_resets.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        tracing::warn!(adapter = %gpu.adapter.name, resets, "GPU device lost: opened a new device; pipelines and scenes are rebuilt on demand");
        Ok(())
    }

    fn render_frame(
        &self,
        state: &mut State,
        scene: &GpuScene,
        spec: &FrameSpec,
        timings: &mut Timings,
        observer: &dyn Observer,
    ) -> JobResult<FrameOutput> {
        // Validation errors inside wgpu are bugs in penumbra, never the client's fault; they
        // fail this job alone with a generic message and are logged in full.
        let gpu = state.renderer.gpu().clone();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let frame = state.renderer.render(scene, spec, timings, observer);
        if let Some(error) = pollster::block_on(scope.pop()) {
            tracing::error!(%error, "GPU validation error while rendering");
            return Err(JobError::internal("the renderer failed on the GPU"));
        }
        frame
    }

    /// The engine's counts. Never waits for a render in progress (a scrape must not block on
    /// a ten-second reference): while the device is busy it answers the counts as of the last
    /// time it was free, with fresh upload figures.
    pub fn stats(&self) -> EngineStats {
        let state = match self.state.try_lock() {
            Ok(state) => state,
            Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => {
                let last = self.last_stats.lock().unwrap_or_else(|p| p.into_inner()).clone();
                return EngineStats { uploads: self.upload_stats(), ..last };
            }
        };
        let stats = self.stats_of(&state);
        *self.last_stats.lock().unwrap_or_else(|p| p.into_inner()) = stats.clone();
        stats
    }

    fn stats_of(&self, state: &State) -> EngineStats {
        let r = &state.renderer;
        EngineStats {
            scenes_cached: state.scenes.len(),
            scene_cache_hits: state.hits,
            scene_cache_misses: state.misses,
            pipelines: r.pipelines.len(),
            pipelines_compiled: r.pipelines.stats.created,
            targets_created: r.textures.stats.created,
            targets_reused: r.textures.stats.reused,
            derived_created: r.derived.stats.created,
            derived_reused: r.derived.stats.reused,
            readbacks_created: r.readbacks.stats.created,
            readbacks_reused: r.readbacks.stats.reused,
            reference_cache_hits: self.reference_hits.load(std::sync::atomic::Ordering::Relaxed),
            reference_cache_misses: self.reference_misses.load(std::sync::atomic::Ordering::Relaxed),
            uploads: self.upload_stats(),
            device_resets: self.device_resets(),
        }
    }

    /// Drops cached copies of uploads that were evicted or deleted: the upload budget counts
    /// them, so they must not outlive their upload.
    fn prune_gone_uploads(&self, state: &mut State) {
        let uploads = self.lock_uploads();
        state.scenes.retain(|key, _| key.strip_prefix("id:").is_none_or(|id| uploads.contains(Kind::Scene, id)));
        state.lights.retain(|key, _| key.strip_prefix("id:").is_none_or(|id| uploads.contains(Kind::Light, id)));
    }

    /// Finds a scene in the cache or loads and uploads it.
    fn scene(&self, state: &mut State, asset: &AssetRef, timings: &mut Timings) -> JobResult<Arc<GpuScene>> {
        let key = self.asset_key(asset, Kind::Scene, "scene")?;
        self.prune_gone_uploads(state);
        state.clock += 1;
        let clock = state.clock;
        if let Some(cached) = state.scenes.get_mut(&key) {
            cached.last_used = clock;
            state.hits += 1;
            timings.scene_cached = true;
            return Ok(cached.scene.clone());
        }
        state.misses += 1;
        let loaded = match asset {
            AssetRef::Builtin { name, params } => Arc::new(builtin::build(name, params, "scene", &self.limits)?),
            AssetRef::Path(path) => {
                let bytes = self.read_path(path, "scene.path")?;
                Arc::new(scene::gltf::load(&bytes, &self.limits, "scene")?)
            }
            AssetRef::Id(id) => match self.uploaded(Kind::Scene, id, "scene.id")? {
                Asset::Scene(scene) => scene,
                Asset::Light(_) => return Err(not_uploaded(id, "scene.id")),
            },
        };
        let gpu = state.renderer.gpu().clone();
        let uploaded = GpuScene::upload(&gpu, &loaded, state.renderer.material_layout()).map_err(|error| {
            tracing::warn!(%error, "a scene failed to upload to the GPU");
            let first_line = error.to_string().lines().find(|l| !l.trim().is_empty()).unwrap_or("").trim().to_owned();
            JobError::field(
                ErrorCode::LimitExceeded,
                "scene",
                format!("the scene does not fit on this GPU ({}): {first_line}", gpu.adapter.name),
            )
        })?;
        let uploaded = Arc::new(uploaded);
        timings.scene_upload_bytes = uploaded.bytes;
        if state.scenes.len() >= SCENE_CACHE_ENTRIES {
            if let Some(oldest) = state.scenes.iter().min_by_key(|(_, c)| c.last_used).map(|(k, _)| k.clone()) {
                state.scenes.remove(&oldest);
            }
        }
        state.scenes.insert(key, CachedScene { scene: uploaded.clone(), last_used: clock });
        Ok(uploaded)
    }

    fn light_image(&self, state: &mut State, asset: &AssetRef) -> JobResult<Arc<LightImage>> {
        let key = self.asset_key(asset, Kind::Light, "light.image")?;
        if let Some(image) = state.lights.get(&key) {
            return Ok(image.clone());
        }
        let image = match asset {
            AssetRef::Builtin { name, params } => Arc::new(LightImage::builtin(name, params, "light.image")?),
            AssetRef::Path(path) => {
                let bytes = self.read_path(path, "light.image.path")?;
                Arc::new(LightImage::decode(&bytes, self.limits.max_light_image_dim, "light.image")?)
            }
            AssetRef::Id(id) => match self.uploaded(Kind::Light, id, "light.image.id")? {
                Asset::Light(image) => image,
                Asset::Scene(_) => return Err(not_uploaded(id, "light.image.id")),
            },
        };
        if state.lights.len() >= SCENE_CACHE_ENTRIES {
            state.lights.clear();
        }
        state.lights.insert(key, image.clone());
        Ok(image)
    }

    /// A cache key that changes whenever the asset's content may have changed.
    fn asset_key(&self, asset: &AssetRef, kind: Kind, field: &str) -> JobResult<String> {
        match asset {
            AssetRef::Builtin { name, params } => Ok(format!("builtin:{name}:{}", serde_json::Value::Object(params.clone()))),
            AssetRef::Id(id) if self.lock_uploads().contains(kind, id) => Ok(format!("id:{id}")),
            AssetRef::Id(id) => Err(not_uploaded(id, &format!("{field}.id"))),
            AssetRef::Path(path) => {
                let resolved = self.resolve_path(path, &format!("{field}.path"))?;
                let meta = std::fs::metadata(&resolved).map_err(|_| not_readable(&format!("{field}.path")))?;
                let modified =
                    meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).map(|d| d.as_nanos()).unwrap_or(0);
                Ok(format!("path:{}:{}:{}", resolved.display(), meta.len(), modified))
            }
        }
    }

    /// Applies the path policy: canonical path inside the allowed directory, or an error
    /// that does not reveal whether the file exists.
    fn resolve_path(&self, path: &Path, field: &str) -> JobResult<PathBuf> {
        match &self.paths {
            PathPolicy::Deny => {
                Err(JobError::field(ErrorCode::PathNotAllowed, field, "this server reads no paths (start it with --scene-dir)"))
            }
            PathPolicy::Any => std::fs::canonicalize(path).map_err(|_| not_readable(field)),
            PathPolicy::Under(dir) => {
                let dir = std::fs::canonicalize(dir).map_err(|_| not_readable(field))?;
                let joined = if path.is_absolute() { path.to_path_buf() } else { dir.join(path) };
                match std::fs::canonicalize(&joined) {
                    Ok(resolved) if resolved.starts_with(&dir) && resolved.is_file() => Ok(resolved),
                    _ => Err(not_readable(field)),
                }
            }
        }
    }

    fn read_path(&self, path: &Path, field: &str) -> JobResult<Vec<u8>> {
        let resolved = self.resolve_path(path, field)?;
        let meta = std::fs::metadata(&resolved).map_err(|_| not_readable(field))?;
        if meta.len() > self.limits.max_body_bytes as u64 {
            return Err(JobError::field(ErrorCode::LimitExceeded, field, format!("the file exceeds {} bytes", self.limits.max_body_bytes)));
        }
        std::fs::read(&resolved).map_err(|_| not_readable(field))
    }
}

fn not_readable(field: &str) -> JobError {
    JobError::field(ErrorCode::PathNotAllowed, field, "no readable file at this path in the allowed directory")
}

/// The error for an id this server does not hold (never uploaded, evicted or deleted).
fn not_uploaded(id: &str, field: &str) -> JobError {
    JobError::field(
        ErrorCode::NotUploaded,
        field,
        format!("no uploaded asset with id `{id}` of this kind on this server (never uploaded, evicted or deleted); upload it again"),
    )
}
