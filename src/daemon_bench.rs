//! `penumbra bench-daemon`: what the daemon costs around a render, measured in one run on a
//! real server over loopback (no timed test asserts any of it):
//!
//! - **overhead**: the same warm 512×512 `hard` job through the library and through HTTP,
//!   interleaved, medians — what HTTP, queueing and the response add to the render;
//! - **throughput**: 1, 2, 4 and 16 concurrent clients, jobs per second, p50/p99 latency and
//!   every status that was not 200 (only documented 429s are allowed);
//! - **memory**: distinct uploaded scenes adding up to ten times the cache budget, each
//!   rendered (so its GPU copy exists too), the process's resident memory sampled after each.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;
use serde_json::{json, Value};

use crate::engine::{Engine, PathPolicy};
use crate::gpu::GpuContext;
use crate::job::{Job, Limits};
use crate::server::{app, AppState, QueueConfig};

#[derive(Debug, Clone, clap::Args)]
pub struct BenchOptions {
    /// Directory for the JSON report.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Library/HTTP pairs for the overhead measurement.
    #[arg(long, default_value_t = 15)]
    pub repeat: usize,
    /// Concurrent client counts for the throughput measurement.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,16")]
    pub clients: Vec<usize>,
    /// Jobs per throughput level (split between the clients).
    #[arg(long, default_value_t = 48)]
    pub jobs: usize,
    /// Upload cache budget for the memory measurement, MiB (ten times this is uploaded).
    #[arg(long, default_value_t = 64)]
    pub cache_mib: u64,
    /// Vertices per side of each uploaded height-field scene.
    #[arg(long, default_value_t = 256)]
    pub scene_side: u32,
    /// Device slots (`serve --concurrency`) to compare, each with 4 clients sending the same
    /// jobs: frames take the device one at a time, so more slots overlap one job's CPU work
    /// (scene look-up, encoding) with another's frame.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    pub concurrency: Vec<u32>,
}

#[derive(Debug, Serialize)]
pub struct BenchReport {
    pub adapter: String,
    pub overhead: Overhead,
    pub throughput: Vec<Throughput>,
    /// Throughput with 4 clients for each `--concurrency` compared.
    pub by_concurrency: Vec<(u32, Throughput)>,
    pub memory: Memory,
}

#[derive(Debug, Serialize)]
pub struct Overhead {
    pub pairs: usize,
    pub library_median_ms: f64,
    pub http_median_ms: f64,
    /// (HTTP − library) / library.
    pub overhead_fraction: f64,
}

#[derive(Debug, Serialize)]
pub struct Throughput {
    pub clients: usize,
    pub jobs: usize,
    pub seconds: f64,
    pub jobs_per_second: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    /// Statuses other than 200, with counts.
    pub other_statuses: std::collections::BTreeMap<u16, usize>,
}

#[derive(Debug, Serialize)]
pub struct Memory {
    pub budget_bytes: u64,
    pub uploaded_bytes: u64,
    pub scenes: usize,
    pub scene_cost_bytes: u64,
    pub evictions: u64,
    pub rss_before_bytes: u64,
    pub rss_max_bytes: u64,
    pub rss_after_bytes: u64,
    /// Highest resident memory above the budget, over the resident memory before uploads.
    pub rss_growth_over_budget_bytes: i64,
}

/// The resident set size of this process (Linux `/proc/self/statm`), bytes; 0 elsewhere.
pub fn resident_bytes() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
    let pages: u64 = statm.split_whitespace().nth(1).and_then(|p| p.parse().ok()).unwrap_or(0);
    pages * 4096
}

/// The job the overhead and throughput measurements send: warm, small enough to run many.
fn bench_job() -> Value {
    json!({"scene": {"builtin": "torus"}, "method": {"name": "hard"}, "output": {"width": 512, "height": 512}})
}

fn median(values: &mut [f64]) -> f64 {
    percentile(values, 0.5)
}

fn percentile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

/// Starts a real server on an ephemeral loopback port for `engine`; returns its base URL.
async fn start_server(engine: Arc<Engine>, queue: QueueConfig) -> anyhow::Result<String> {
    let state = Arc::new(AppState::new(engine, 64).with_queue(queue));
    state.set_ready();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let base = format!("http://{}", listener.local_addr()?);
    tokio::spawn(async move { axum::serve(listener, app(state)).await });
    Ok(base)
}

pub fn run(gpu: Arc<GpuContext>, options: &BenchOptions) -> anyhow::Result<BenchReport> {
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(run_async(gpu, options))
}

async fn run_async(gpu: Arc<GpuContext>, options: &BenchOptions) -> anyhow::Result<BenchReport> {
    std::fs::create_dir_all(&options.out)?;
    let engine = Arc::new(Engine::new(gpu.clone(), Limits::default(), PathPolicy::Deny));
    let warm = engine.clone();
    tokio::task::spawn_blocking(move || warm.warm_up()).await??;
    let base = start_server(engine.clone(), QueueConfig::default()).await?;
    let client = reqwest::Client::new();

    let overhead = measure_overhead(&engine, &client, &base, options.repeat).await?;
    eprintln!(
        "overhead: library {:.1} ms, HTTP {:.1} ms (medians of {}): +{:.1} %",
        overhead.library_median_ms,
        overhead.http_median_ms,
        overhead.pairs,
        overhead.overhead_fraction * 100.0
    );

    let mut throughput = Vec::new();
    for &clients in &options.clients {
        let level = measure_throughput(&client, &base, clients.max(1), options.jobs).await?;
        eprintln!(
            "{:>2} clients: {:.2} jobs/s, p50 {:.0} ms, p99 {:.0} ms, other statuses {:?}",
            level.clients, level.jobs_per_second, level.p50_ms, level.p99_ms, level.other_statuses
        );
        throughput.push(level);
    }

    let mut by_concurrency = Vec::new();
    for &slots in &options.concurrency {
        let queue = QueueConfig { concurrency: slots.max(1), ..QueueConfig::default() };
        let base = start_server(engine.clone(), queue).await?;
        let level = measure_throughput(&client, &base, 4, options.jobs).await?;
        eprintln!(
            "concurrency {slots}, 4 clients: {:.2} jobs/s, p50 {:.0} ms, p99 {:.0} ms",
            level.jobs_per_second, level.p50_ms, level.p99_ms
        );
        by_concurrency.push((slots, level));
    }

    let memory = measure_memory(gpu.clone(), &client, options).await?;
    eprintln!(
        "memory: {} scenes of {:.1} MiB ({:.0} MiB uploaded, budget {:.0} MiB): RSS {:.0} → max {:.0} MiB; growth − budget = {:.0} MiB",
        memory.scenes,
        memory.scene_cost_bytes as f64 / 1048576.0,
        memory.uploaded_bytes as f64 / 1048576.0,
        memory.budget_bytes as f64 / 1048576.0,
        memory.rss_before_bytes as f64 / 1048576.0,
        memory.rss_max_bytes as f64 / 1048576.0,
        memory.rss_growth_over_budget_bytes as f64 / 1048576.0
    );

    let report = BenchReport { adapter: gpu.adapter.name.clone(), overhead, throughput, by_concurrency, memory };
    let path = options.out.join("daemon.json");
    std::fs::write(&path, serde_json::to_vec_pretty(&report)?)?;
    eprintln!("wrote {}", path.display());
    Ok(report)
}

async fn measure_overhead(engine: &Arc<Engine>, client: &reqwest::Client, base: &str, pairs: usize) -> anyhow::Result<Overhead> {
    let job = Job::from_json(bench_job().to_string().as_bytes())?;
    let (mut library, mut http) = (Vec::new(), Vec::new());
    // Two unmeasured rounds warm both paths (connection, pools at this size).
    for round in 0..pairs + 2 {
        let engine = engine.clone();
        let job = job.clone();
        let start = Instant::now();
        tokio::task::spawn_blocking(move || engine.render(&job, &())).await??;
        let library_ms = start.elapsed().as_secs_f64() * 1e3;
        let start = Instant::now();
        let response = client.post(format!("{base}/v1/render")).json(&bench_job()).send().await?;
        anyhow::ensure!(response.status().is_success(), "the bench job failed over HTTP: {}", response.status());
        response.bytes().await?;
        let http_ms = start.elapsed().as_secs_f64() * 1e3;
        if round >= 2 {
            library.push(library_ms);
            http.push(http_ms);
        }
    }
    let (library_median_ms, http_median_ms) = (median(&mut library), median(&mut http));
    Ok(Overhead { pairs, library_median_ms, http_median_ms, overhead_fraction: (http_median_ms - library_median_ms) / library_median_ms })
}

async fn measure_throughput(client: &reqwest::Client, base: &str, clients: usize, jobs: usize) -> anyhow::Result<Throughput> {
    let per_client = jobs.div_ceil(clients);
    let started = Instant::now();
    let mut tasks = Vec::new();
    for _ in 0..clients {
        let client = client.clone();
        let url = format!("{base}/v1/render");
        tasks.push(tokio::spawn(async move {
            let mut results = Vec::new();
            for _ in 0..per_client {
                let start = Instant::now();
                let status = match client.post(&url).json(&bench_job()).send().await {
                    Ok(response) => {
                        let status = response.status().as_u16();
                        let _ = response.bytes().await;
                        status
                    }
                    Err(_) => 0,
                };
                results.push((status, start.elapsed().as_secs_f64() * 1e3));
            }
            results
        }));
    }
    let mut latencies = Vec::new();
    let mut other_statuses = std::collections::BTreeMap::new();
    for task in tasks {
        for (status, ms) in task.await? {
            if status == 200 {
                latencies.push(ms);
            } else {
                *other_statuses.entry(status).or_insert(0) += 1;
            }
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    Ok(Throughput {
        clients,
        jobs: per_client * clients,
        seconds,
        jobs_per_second: latencies.len() as f64 / seconds,
        p50_ms: percentile(&mut latencies, 0.5),
        p99_ms: percentile(&mut latencies, 0.99),
        other_statuses,
    })
}

async fn measure_memory(gpu: Arc<GpuContext>, client: &reqwest::Client, options: &BenchOptions) -> anyhow::Result<Memory> {
    let budget = options.cache_mib << 20;
    let limits = Limits { max_body_bytes: 256 << 20, ..Limits::default() };
    let engine = Arc::new(Engine::new(gpu, limits, PathPolicy::Deny).with_cache_budget(budget));
    let base = start_server(engine.clone(), QueueConfig::default()).await?;
    let first = crate::scene::gltf::height_field_glb(options.scene_side, 0);
    // One upload and render unmeasured: pools and pipelines at this size exist before the baseline.
    let receipt: Value = client.post(format!("{base}/v1/scenes")).body(first).send().await?.json().await?;
    let scene_cost = receipt["cache_bytes"].as_u64().unwrap_or(0);
    anyhow::ensure!(scene_cost > 0, "the warm-up upload failed: {receipt}");
    render_uploaded(client, &base, &receipt).await?;
    let rss_before = resident_bytes();
    let scenes = ((10 * budget).div_ceil(scene_cost)) as usize;
    let mut rss_max = rss_before;
    for seed in 1..=scenes as u32 {
        let bytes = crate::scene::gltf::height_field_glb(options.scene_side, seed);
        let receipt: Value = client.post(format!("{base}/v1/scenes")).body(bytes).send().await?.json().await?;
        render_uploaded(client, &base, &receipt).await?;
        rss_max = rss_max.max(resident_bytes());
    }
    let rss_after = resident_bytes();
    Ok(Memory {
        budget_bytes: budget,
        uploaded_bytes: scene_cost * scenes as u64,
        scenes,
        scene_cost_bytes: scene_cost,
        evictions: engine.upload_stats().evictions,
        rss_before_bytes: rss_before,
        rss_max_bytes: rss_max,
        rss_after_bytes: rss_after,
        rss_growth_over_budget_bytes: rss_max as i64 - rss_before as i64 - budget as i64,
    })
}

async fn render_uploaded(client: &reqwest::Client, base: &str, receipt: &Value) -> anyhow::Result<()> {
    let id = receipt["id"].as_str().ok_or_else(|| anyhow::anyhow!("no id in the upload receipt: {receipt}"))?;
    let job = json!({"scene": {"id": id}, "method": {"name": "hard"}, "output": {"width": 64, "height": 64},
                     "shadow_map": {"resolution": 256}});
    let response = client.post(format!("{base}/v1/render")).json(&job).send().await?;
    anyhow::ensure!(response.status().is_success(), "rendering uploaded scene {id} failed: {}", response.status());
    response.bytes().await?;
    Ok(())
}
