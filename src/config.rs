//! Configuration: command-line flags, each with an environment variable, parsed once by
//! clap at start-up and passed down. No globals.

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::Args;

use crate::gpu::AdapterChoice;
use crate::job::Limits;

/// Options shared by every command that renders.
#[derive(Debug, Clone, Args)]
pub struct RenderOptions {
    /// Which Vulkan adapter to use: a hardware GPU when present (auto), or force one kind.
    #[arg(long, env = "PENUMBRA_ADAPTER", default_value_t = AdapterChoice::Auto)]
    pub adapter: AdapterChoice,

    #[command(flatten)]
    pub limits: LimitArgs,
}

/// Limits on what one job may ask for (see `job::Limits`).
#[derive(Debug, Clone, Args)]
pub struct LimitArgs {
    /// Largest output width or height, pixels.
    #[arg(long, env = "PENUMBRA_MAX_OUTPUT_DIM", default_value_t = Limits::default().max_output_dim)]
    pub max_output_dim: u32,
    /// Largest output image, pixels (width × height).
    #[arg(long, env = "PENUMBRA_MAX_OUTPUT_PIXELS", default_value_t = Limits::default().max_output_pixels)]
    pub max_output_pixels: u64,
    /// Largest shadow-map resolution, texels per side.
    #[arg(long, env = "PENUMBRA_MAX_SHADOW_MAP", default_value_t = Limits::default().max_shadow_map_resolution)]
    pub max_shadow_map: u32,
    /// Most triangles per scene.
    #[arg(long, env = "PENUMBRA_MAX_TRIANGLES", default_value_t = Limits::default().max_triangles)]
    pub max_triangles: u64,
    /// Largest light image, texels per side.
    #[arg(long, env = "PENUMBRA_MAX_LIGHT_IMAGE_DIM", default_value_t = Limits::default().max_light_image_dim)]
    pub max_light_image_dim: u32,
    /// Largest scene texture, texels per side.
    #[arg(long, env = "PENUMBRA_MAX_TEXTURE_DIM", default_value_t = Limits::default().max_texture_dim)]
    pub max_texture_dim: u32,
    /// Most bytes a scene's textures may take decoded, together (4 a texel).
    #[arg(long, env = "PENUMBRA_MAX_TEXTURE_BYTES", default_value_t = Limits::default().max_texture_bytes)]
    pub max_texture_bytes: u64,
    /// Largest request body (and scene or image file), bytes.
    #[arg(long, env = "PENUMBRA_MAX_BODY_BYTES", default_value_t = Limits::default().max_body_bytes)]
    pub max_body_bytes: usize,
    /// Deepest nesting of arrays and objects in a job's JSON.
    #[arg(long, env = "PENUMBRA_MAX_JSON_DEPTH", default_value_t = Limits::default().max_json_depth)]
    pub max_json_depth: usize,
    /// Most vertices per loaded scene (summed over mesh instances).
    #[arg(long, env = "PENUMBRA_MAX_VERTICES", default_value_t = Limits::default().max_vertices)]
    pub max_vertices: u64,
    /// Most samples per pixel a method may take (`reference`'s `samples`).
    #[arg(long, env = "PENUMBRA_MAX_SAMPLES", default_value_t = Limits::default().max_samples)]
    pub max_samples: u32,
    /// Most rounds an iterative method may run (JFA's `rounds`).
    #[arg(long, env = "PENUMBRA_MAX_ROUNDS", default_value_t = Limits::default().max_rounds)]
    pub max_rounds: u32,
    /// Most bytes `reference`'s CPU engine and `filtered` hold for their per-pixel work at
    /// once: a larger frame is worked on in bands of rows (the same pixels; each band draws the
    /// samples' maps again).
    #[arg(long, env = "PENUMBRA_MAX_CPU_WORKING_BYTES", default_value_t = Limits::default().max_cpu_working_bytes, value_parser = clap::value_parser!(u64).range(1 << 20..))]
    pub max_cpu_working_bytes: u64,
}

impl LimitArgs {
    pub fn limits(&self) -> Limits {
        Limits {
            max_output_dim: self.max_output_dim,
            max_output_pixels: self.max_output_pixels,
            max_shadow_map_resolution: self.max_shadow_map,
            max_triangles: self.max_triangles,
            max_light_image_dim: self.max_light_image_dim,
            max_texture_dim: self.max_texture_dim,
            max_texture_bytes: self.max_texture_bytes,
            max_body_bytes: self.max_body_bytes,
            max_json_depth: self.max_json_depth,
            max_vertices: self.max_vertices,
            max_samples: self.max_samples,
            max_rounds: self.max_rounds,
            max_cpu_working_bytes: self.max_cpu_working_bytes,
        }
    }
}

/// `penumbra serve`.
#[derive(Debug, Clone, Args)]
pub struct ServeConfig {
    /// Address and port to listen on.
    #[arg(long, env = "PENUMBRA_LISTEN", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,

    /// The only directory from which `{"path": ...}` scenes and light images are read.
    /// Without it the server reads no paths at all.
    #[arg(long, env = "PENUMBRA_SCENE_DIR")]
    pub scene_dir: Option<PathBuf>,

    /// Finished renders kept in memory for `GET /v1/jobs/{id}/image`.
    #[arg(long, env = "PENUMBRA_RESULTS_KEPT", default_value_t = 64)]
    pub results_kept: usize,

    /// Where submitted jobs and their results are kept: `embedded` (a file under --data-dir;
    /// accepted jobs survive a crash and finish after a restart), `memory`, or
    /// `redis://[:PASSWORD@]HOST:PORT/DB` (shared by several replicas acting as one service;
    /// `rediss://` for TLS).
    #[arg(long, env = "PENUMBRA_JOB_STORE", default_value = "embedded", value_parser = JobStoreKind::parse)]
    pub job_store: JobStoreKind,

    /// With a Redis store: seconds a job taken by a replica may go without its heartbeat
    /// before another replica claims it (the first is presumed dead).
    #[arg(long, env = "PENUMBRA_CLAIM_IDLE_SECS", default_value_t = 15.0, value_parser = seconds)]
    pub claim_idle_secs: f64,

    /// With a Redis store: seconds between this replica's heartbeats, which tell the others
    /// (and the cluster's dashboard) that it is alive and what it is doing; a replica missing
    /// three in a row leaves the cluster view.
    #[arg(long, env = "PENUMBRA_HEARTBEAT_SECS", default_value_t = 5.0, value_parser = seconds)]
    pub heartbeat_secs: f64,

    /// With a `rediss://` store: a PEM file of the certificate authorities that signed Redis's
    /// certificate, trusted beside the system's roots.
    #[arg(long, env = "PENUMBRA_REDIS_CA_CERT")]
    pub redis_ca_cert: Option<PathBuf>,

    /// This replica's name in job records, the cluster view and `/v1/stats`. Default:
    /// `$HOSTNAME` (the pod's name under Kubernetes), else the listen address.
    #[arg(long, env = "PENUMBRA_REPLICA_NAME")]
    pub replica_name: Option<String>,

    /// Directory of the embedded job store.
    #[arg(long, env = "PENUMBRA_DATA_DIR", default_value = "penumbra-data")]
    pub data_dir: PathBuf,

    /// Byte budget of stored result images; the oldest go first (their records stay until
    /// they expire by age).
    #[arg(long, env = "PENUMBRA_RESULTS_BYTES", default_value_t = 1 << 30)]
    pub results_bytes: u64,

    /// Bytes kept free on the embedded store's disk: the oldest stored results are dropped to
    /// keep them, and submitted jobs whose result would not fit are refused with 507.
    #[arg(long, env = "PENUMBRA_MIN_FREE_BYTES", default_value_t = 128 << 20)]
    pub min_free_bytes: u64,

    /// Seconds a finished job's outcome is retried while the store cannot take it (down, or
    /// its disk full); then a shared store's job is left for another replica to claim, and an
    /// embedded store's result is served from memory until a restart renders it again.
    #[arg(long, env = "PENUMBRA_STORE_RETRY_SECS", default_value_t = 600.0, value_parser = seconds)]
    pub store_retry_secs: f64,

    /// Seconds an `Idempotency-Key` names the job it created: the same key and body within
    /// it answers that job and creates nothing.
    #[arg(long, env = "PENUMBRA_IDEMPOTENCY_TTL_SECS", default_value_t = 86400.0, value_parser = seconds)]
    pub idempotency_ttl_secs: f64,

    /// Most idempotency keys kept by the embedded store or in memory (past it, the expired
    /// go, then the oldest); on Redis they are bounded by their TTL.
    #[arg(long, env = "PENUMBRA_IDEMPOTENCY_KEYS", default_value_t = crate::job::submission::DEFAULT_MAX_KEYS)]
    pub idempotency_keys: usize,

    /// Seconds a finished job's record, events and image stay readable.
    #[arg(long, env = "PENUMBRA_RESULTS_TTL_SECS", default_value_t = 3600.0, value_parser = seconds)]
    pub results_ttl_secs: f64,

    /// Byte budget of the cache of uploaded scenes and light images (a scene counts its CPU
    /// and GPU copies); the least recently used go first.
    #[arg(long, env = "PENUMBRA_CACHE_BYTES", default_value_t = crate::engine::DEFAULT_CACHE_BYTES)]
    pub cache_bytes: u64,

    /// Bytes of idle GPU memory the renderer keeps for later frames, in each of its pools
    /// (render targets, methods' scratch buffers, readback buffers); the longest idle go first.
    #[arg(long, env = "PENUMBRA_POOL_BYTES", default_value_t = crate::gpu::pool::DEFAULT_POOL_BYTES)]
    pub pool_bytes: u64,

    /// Render jobs admitted at once, waiting or running; one more answers 429 with Retry-After.
    #[arg(long, env = "PENUMBRA_QUEUE", default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..))]
    pub queue: u32,

    /// Jobs rendering at once. Frames go through the device one at a time (the renderer's
    /// targets and timer are per frame); each further slot lets one job's CPU work — asset
    /// look-up, encoding, comparing with the reference — overlap another's frame, and a job in
    /// a slot may wait for the frames of the others (at most concurrency − 1).
    #[arg(long, env = "PENUMBRA_CONCURRENCY", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub concurrency: u32,

    /// Seconds a job may wait in the queue before it fails with 503 `deadline_exceeded`.
    #[arg(long, env = "PENUMBRA_DEADLINE_SECS", default_value_t = 120.0, value_parser = seconds)]
    pub deadline_secs: f64,

    /// A file of bearer tokens (one per line, at least 16 characters; `#` comments): every
    /// `/v1` request must carry one (`Authorization: Bearer TOKEN`). None: the API is open.
    #[arg(long, env = "PENUMBRA_AUTH_TOKEN_FILE")]
    pub auth_token_file: Option<PathBuf>,

    /// With tokens: leave `/metrics` open to scrapers without one.
    #[arg(long, env = "PENUMBRA_METRICS_OPEN")]
    pub metrics_open: bool,

    /// Origins allowed to call the API from a browser (CORS), comma-separated, e.g.
    /// `https://tools.example`. None: CORS closed.
    #[arg(long, env = "PENUMBRA_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,

    /// Open client connections at most (like nginx's `worker_connections`); lowered, with a
    /// warning, to the open-files limit (`ulimit -n`) less 128. At the cap, a new connection
    /// still gets in and the one that has waited longest on its client is closed.
    #[arg(long, env = "PENUMBRA_MAX_CONNECTIONS", default_value_t = 4096, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_connections: u64,

    /// Seconds a client may take to send a request's head, from its first byte (and a new
    /// connection to start its first request): nginx's `client_header_timeout`.
    #[arg(long, env = "PENUMBRA_HEADER_TIMEOUT_SECS", default_value_t = 30.0, value_parser = seconds)]
    pub header_timeout_secs: f64,

    /// Seconds a client may go without sending more of a request body: nginx's
    /// `client_body_timeout`. The connection is closed.
    #[arg(long, env = "PENUMBRA_BODY_TIMEOUT_SECS", default_value_t = 30.0, value_parser = seconds)]
    pub body_timeout_secs: f64,

    /// Seconds an idle keep-alive connection stays open: nginx's `keepalive_timeout`.
    #[arg(long, env = "PENUMBRA_KEEP_ALIVE_SECS", default_value_t = 75.0, value_parser = seconds)]
    pub keep_alive_secs: f64,

    /// Skip compiling pipelines and uploading the default scene before accepting jobs.
    #[arg(long, env = "PENUMBRA_NO_WARM_UP")]
    pub no_warm_up: bool,

    /// The cost and quality model `auto` jobs and estimates use: `measure` reads the one kept
    /// under `--data-dir` for this adapter and build, or measures it in the background after
    /// warm-up (about three minutes on two cores; the shipped model answers meanwhile); `quick`
    /// the same on a suite of a tenth of the time; `default` keeps the shipped model.
    #[arg(long, env = "PENUMBRA_MODEL", value_enum, default_value = "measure")]
    pub model: ModelMode,

    #[command(flatten)]
    pub render: RenderOptions,
}

/// A duration flag in seconds: a finite number ≥ 0 (a duration that overflows, or is not a
/// number, is refused when the flags are read rather than later).
fn seconds(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if s.is_finite() && (0.0..=1e9).contains(&s) => Ok(s),
        _ => Err(format!("`{text}` is not a number of seconds in [0, 1e9]")),
    }
}

/// Where submitted jobs are kept (`--job-store`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum JobStoreKind {
    /// `embedded`: a file under `--data-dir`; accepted jobs survive a crash.
    Embedded,
    /// `memory`: nothing survives the process.
    Memory,
    /// `redis://HOST:PORT/DB` (or `rediss://` over TLS): a queue and records shared by
    /// several replicas.
    Redis(String),
}

impl JobStoreKind {
    fn parse(text: &str) -> Result<Self, String> {
        match text {
            "embedded" => Ok(Self::Embedded),
            "memory" => Ok(Self::Memory),
            url if url.starts_with("redis://") || url.starts_with("rediss://") => Ok(Self::Redis(url.to_owned())),
            other => Err(format!("`{other}` is not embedded, memory, redis://HOST:PORT/DB or rediss://HOST:PORT/DB")),
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn durations_are_finite_and_not_negative() {
        assert_eq!(super::seconds("2.5"), Ok(2.5));
        for bad in ["inf", "NaN", "-1", "1e300", "soon"] {
            assert!(super::seconds(bad).is_err(), "{bad}");
        }
    }
}

/// What `--model` asks of the daemon's start (contract §5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModelMode {
    /// The model stored for this adapter and build, else measure it in the background.
    Measure,
    /// As `measure`, on the quick suite (a tenth of the time; errors of small frames).
    Quick,
    /// The shipped model only (tests; a fleet that should not spend its first minutes measuring).
    Default,
}
