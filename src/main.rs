//! The `penumbra` command line: `serve` runs the daemon, `render` runs one job through the
//! same engine without HTTP.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use clap::{Parser, Subcommand};
use penumbra::config::{RenderOptions, ServeConfig};
use penumbra::engine::{Engine, PathPolicy};
use penumbra::gpu::GpuContext;
use penumbra::job::{Job, OutputFormat};
use penumbra::timing::Timings;

#[derive(Parser)]
#[command(name = "penumbra", version, about = "Soft shadows from coloured area lights, rendered on demand")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Log lines as text for people or as JSON objects for log collectors (each job's lines
    /// carry its span: id and method). The level filter is `PENUMBRA_LOG`.
    #[arg(long, global = true, env = "PENUMBRA_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    log_format: LogFormat,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum LogFormat {
    Text,
    Json,
}

#[derive(Subcommand)]
enum Command {
    /// Run the render daemon (HTTP/JSON).
    Serve(ServeConfig),
    /// Measure methods against `reference`: cost and quality tables, contact sheets, heat-maps.
    Eval {
        #[command(flatten)]
        suite: penumbra::eval::EvalOptions,
        #[command(flatten)]
        options: RenderOptions,
    },
    /// Measure what a 1080p frame costs, phase by phase, as users request it (warm, whole PNG
    /// requests, every method on the built-in scenes under four lights) with each method's
    /// penumbra error and the interpolated E0's error beside it: `bench.md`, `bench.json`.
    Bench {
        #[command(flatten)]
        bench: penumbra::eval::frame_bench::BenchOptions,
        #[command(flatten)]
        options: RenderOptions,
    },
    /// Measure the daemon around the render: HTTP overhead, throughput under concurrent
    /// clients, memory under uploads of ten times the cache budget (a real loopback server).
    BenchDaemon {
        #[command(flatten)]
        bench: penumbra::daemon_bench::BenchOptions,
        #[command(flatten)]
        options: RenderOptions,
    },
    /// Render a job on a remote penumbra: upload what it lacks, submit, follow the progress,
    /// download the image. Prints what it did as JSON.
    Submit(penumbra::client::SubmitOptions),
    /// The jobs of a remote penumbra: list, show, cancel, wait (a table, or `--json`).
    Jobs(penumbra::client::JobsCommand),
    /// Ask a local daemon one path (`/healthz` by default) and exit 0 on a 2xx answer: the
    /// container's health check, with no curl in the image.
    Probe {
        #[arg(default_value = "/healthz")]
        path: String,
        /// The daemon's address (an unspecified address such as 0.0.0.0 means this host).
        #[arg(long, env = "PENUMBRA_LISTEN", default_value = "127.0.0.1:8080")]
        listen: std::net::SocketAddr,
    },
    /// Render one job to a PNG or EXR file, without a server.
    Render {
        /// The job (JSON, see api/examples/), or a scene file (`.gltf`, `.glb`) to render on a
        /// floor with the fitted camera and light (contract §3). Without it: the built-in
        /// `torus` scene, `hard`.
        job: Option<PathBuf>,
        /// Output file; the extension (.png or .exr) picks the format.
        #[arg(short, long)]
        output: PathBuf,
        /// Also write the timing breakdown, counters, warnings and staging (the camera, light
        /// and floor used) as JSON to this file.
        #[arg(long)]
        timings_json: Option<PathBuf>,
        #[command(flatten)]
        options: RenderOptions,
    },
}

fn main() -> ExitCode {
    quiet_device_select();
    let cli = Cli::parse();
    // A one-shot render prints its own table; its log says only what went wrong. The daemon and
    // the measuring commands also log what they opened and did.
    let level = if matches!(cli.command, Command::Render { .. }) { "warn" } else { "info" };
    let filter = tracing_subscriber::EnvFilter::try_from_env("PENUMBRA_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("{level},wgpu_core=warn,wgpu_hal=warn,naga=warn")));
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()));
    match cli.log_format {
        LogFormat::Text => logs.init(),
        LogFormat::Json => logs.json().with_current_span(true).init(),
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("penumbra: {error:#}");
            // Interrupted by Ctrl-C: the shell's code for SIGINT.
            let interrupted = matches!(error.downcast_ref(), Some(penumbra::client::ClientError::Interrupted { .. }));
            ExitCode::from(if interrupted { 130 } else { 2 })
        }
    }
}

/// Turns off Mesa's implicit Vulkan layer `VK_LAYER_MESA_device_select` unless the user asked
/// for it (`MESA_VK_DEVICE_SELECT`) or already said (`NODEVICE_SELECT`). The layer orders the
/// devices by the display it finds, and to find one it connects to Wayland: on a headless
/// machine libwayland prints `error: XDG_RUNTIME_DIR is invalid or not set in the environment.`
/// at every device enumeration, though nothing is wrong. penumbra picks its adapter itself
/// (`--adapter`), so the layer has nothing to do here; real errors (no adapter, no driver)
/// still come from the loader and `GpuContext::new`. Set before any thread starts, as
/// `set_var` requires.
fn quiet_device_select() {
    if std::env::var_os("MESA_VK_DEVICE_SELECT").is_none() && std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}

fn open_gpu(options: &RenderOptions) -> anyhow::Result<Arc<GpuContext>> {
    let gpu = GpuContext::new(options.adapter)?;
    let a = &gpu.adapter;
    tracing::info!(name = %a.name, backend = %a.backend, kind = %a.device_type, driver = %a.driver, timestamps = a.timestamps, "GPU adapter");
    Ok(Arc::new(gpu))
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Serve(config) => {
            let gpu = open_gpu(&config.render)?;
            let paths = match &config.scene_dir {
                Some(dir) => PathPolicy::Under(dir.clone()),
                None => PathPolicy::Deny,
            };
            let engine = Arc::new(
                Engine::new(gpu, config.render.limits.limits(), paths)
                    .with_cache_budget(config.cache_bytes)
                    .with_pool_budget(config.pool_bytes),
            );
            let runtime = tokio::runtime::Runtime::new()?;
            runtime.block_on(penumbra::server::serve(config, engine))
        }
        Command::Eval { suite, options } => {
            let gpu = open_gpu(&options)?;
            let engine = Engine::new(gpu, options.limits.limits(), PathPolicy::Any);
            if suite.model {
                return measure_model(&engine, &suite.out);
            }
            if suite.budgets {
                penumbra::eval::budgets::run(&engine, &suite, suite.model_file.as_deref())?;
                return Ok(());
            }
            let report = penumbra::eval::run(&engine, &suite)?;
            eprintln!("wrote {} rows and {} pictures to {}", report.rows.len(), report.files.len(), suite.out.display());
            Ok(())
        }
        Command::Bench { bench, options } => {
            let gpu = open_gpu(&options)?;
            let engine = Engine::new(gpu, options.limits.limits(), PathPolicy::Any);
            let report = penumbra::eval::frame_bench::run(&engine, &bench)?;
            eprintln!("wrote {} rows to {}", report.rows.len(), bench.out.join("bench.md").display());
            Ok(())
        }
        Command::BenchDaemon { bench, options } => {
            let gpu = open_gpu(&options)?;
            penumbra::daemon_bench::run(gpu, &bench)?;
            Ok(())
        }
        Command::Submit(options) => submit(&options),
        Command::Jobs(command) => {
            let runtime = tokio::runtime::Runtime::new()?;
            println!("{}", runtime.block_on(penumbra::client::run_jobs(&command))?);
            Ok(())
        }
        Command::Probe { path, listen } => probe(&path, listen),
        Command::Render { job, output, timings_json, options } => render(job.as_deref(), &output, timings_json.as_deref(), &options),
    }
}

/// `penumbra submit`: one job through a running daemon, with a progress bar.
fn submit(options: &penumbra::client::SubmitOptions) -> anyhow::Result<()> {
    if options.estimate {
        let estimate = tokio::runtime::Runtime::new()?.block_on(penumbra::client::estimate(options))?;
        println!("{}", serde_json::to_string_pretty(&estimate)?);
        eprint!("{}", penumbra::client::estimate_table(&estimate));
        return Ok(());
    }
    let bar = if options.quiet { indicatif::ProgressBar::hidden() } else { indicatif::ProgressBar::new(0) };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {percent:>3}% {pos}/{len} {elapsed_precise}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let runtime = tokio::runtime::Runtime::new()?;
    let report = runtime.block_on(penumbra::client::submit(options, &|done, total| {
        // Methods without steps report 0 of 0: one step, done when the job is.
        bar.set_length(total.max(1));
        bar.set_position(if total == 0 { 0 } else { done });
    }))?;
    bar.set_position(bar.length().unwrap_or(1));
    bar.finish();
    println!("{}", serde_json::to_string(&report)?);
    match &options.output {
        Some(output) if !report.rounds.is_empty() => {
            let last = report.rounds.last().expect("not empty");
            let (rounds, error) = (report.rounds.len(), last["error_estimate"].as_f64().unwrap_or(f64::NAN));
            eprintln!(
                "wrote {} after {rounds} rounds ({}, estimated error {error:.4})",
                output.display(),
                last["method"].as_str().unwrap_or("?")
            );
        }
        Some(output) if !options.detach => eprintln!("wrote {} ({} bytes)", output.display(), report.output_bytes),
        _ => eprintln!("accepted as job {}: penumbra jobs wait {}", report.id, report.id),
    }
    Ok(())
}

/// `penumbra probe`: a container's health check — `path` on the daemon at `listen` answers 2xx.
fn probe(path: &str, mut listen: std::net::SocketAddr) -> anyhow::Result<()> {
    if listen.ip().is_unspecified() {
        listen.set_ip(std::net::Ipv4Addr::LOCALHOST.into());
    }
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let status = runtime.block_on(async {
        let client = reqwest::Client::builder().timeout(std::time::Duration::from_secs(3)).build()?;
        client.get(format!("http://{listen}{path}")).send().await.map(|r| r.status())
    })?;
    anyhow::ensure!(status.is_success(), "{path} answered {status}");
    Ok(())
}

/// `penumbra render`: one job (a JSON job, a scene file, or the embedded default) to a file.
fn render(job: Option<&Path>, output: &Path, timings_json: Option<&Path>, options: &RenderOptions) -> anyhow::Result<()> {
    let mut job = match job {
        Some(path) if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb")) => {
            // Soft shadows on a floor, camera and light fitted: what the file looks like.
            let mut job = Job::embedded_default();
            job.scene = penumbra::job::SceneRef {
                asset: penumbra::job::AssetRef::Path(path.to_path_buf()),
                floor: Some(penumbra::job::FloorSpec::default()),
            };
            job.method.name = "pcss".into();
            job
        }
        Some(path) => {
            let bytes = std::fs::read(path).map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
            Job::from_json(&bytes)?
        }
        None => Job::embedded_default(),
    };
    job.output.format = OutputFormat::from_extension(output)
        .ok_or_else(|| anyhow::anyhow!("the output file must end in .png or .exr: {}", output.display()))?;
    let gpu = open_gpu(options)?;
    let adapter = format!("{} ({})", gpu.adapter.name, gpu.adapter.device_type);
    let engine = Engine::new(gpu, options.limits.limits(), PathPolicy::Any);
    // Rounds are events of a submitted job; here there is one render.
    if job.progressive.is_some() {
        anyhow::bail!("a progressive job is submitted to a daemon, where its rounds are events: penumbra submit JOB -o OUT --progressive");
    }
    // `auto` here is chosen by the shipped model: a daemon measures its own device's.
    if let Some(budget) = penumbra::job::auto::AutoBudget::of(&job.method)? {
        let model = penumbra::model::Model::shipped();
        let features = penumbra::model::Features::of(&job, engine.scene_shape(&job.scene).as_ref());
        let (candidate, predicted) =
            model.choose(&budget, &features).map_err(|unmet| anyhow::anyhow!("{}: {}", unmet.field, unmet.message))?;
        eprintln!(
            "auto: {} (predicted {:.0} ms and a penumbra error of {:.4} by the shipped model, measured on {})",
            candidate.label, predicted.ms, predicted.error, model.key.adapter
        );
        job.method = candidate.method_for(&job);
    }
    // Long methods (the reference) report samples done; show them as a progress bar.
    let bar = indicatif::ProgressBar::hidden();
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} samples {elapsed_precise}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let cpu_before = penumbra::timing::process_cpu_ms();
    let rendered = engine.render(&job, &|done, total| {
        if bar.is_hidden() {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
        }
        bar.set_length(total);
        bar.set_position(done);
    })?;
    let cpu_ms = penumbra::timing::process_cpu_ms() - cpu_before;
    bar.finish_and_clear();
    for warning in &rendered.warnings {
        eprintln!("warning: {warning}");
    }
    std::fs::write(output, &rendered.bytes)?;
    print_timings(&adapter, &rendered.timings, cpu_ms);
    if let Some(path) = timings_json {
        let report = serde_json::json!({
            "timings": rendered.timings,
            "counters": rendered.counters,
            "process_cpu_ms": cpu_ms,
            "warnings": rendered.warnings,
            "staging": rendered.staging,
        });
        std::fs::write(path, serde_json::to_vec_pretty(&report)?)?;
    }
    eprintln!("wrote {} ({}×{}, {} bytes)", output.display(), rendered.width, rendered.height, rendered.bytes.len());
    Ok(())
}

/// The phase table: the adapter, each phase, and what the render cost the process in CPU time
/// (`cpu_ms`, every thread).
fn print_timings(adapter: &str, timings: &Timings, cpu_ms: f64) {
    eprintln!("{:<12} {adapter}", "adapter");
    eprintln!("{:<12} {:>10} {:>10}", "phase", "wall ms", "gpu ms");
    for phase in &timings.phases {
        let gpu = phase.gpu_ms.map(|g| format!("{g:.2}")).unwrap_or_else(|| "-".into());
        eprintln!("{:<12} {:>10.2} {:>10}", phase.name, phase.cpu_ms, gpu);
    }
    eprintln!("{:<12} {:>10.2}", "total", timings.total_ms);
    eprintln!("{:<12} {:>10.2}   ({:.2} cores)", "cpu", cpu_ms, cpu_ms / timings.total_ms);
}

/// `penumbra eval --model`: measures the model with a progress bar, prints its table and
/// writes it (`model.json` is what `src/model/default.json` ships).
fn measure_model(engine: &Engine, out: &std::path::Path) -> anyhow::Result<()> {
    struct Bar(indicatif::ProgressBar);
    impl penumbra::model::measure::Hooks for Bar {
        fn device(&self) -> Box<dyn std::any::Any> {
            Box::new(())
        }
        fn progress(&self, done: usize, total: usize, what: &str) {
            self.0.set_length(total as u64);
            self.0.set_position(done as u64);
            self.0.set_message(what.to_owned());
        }
        fn cancelled(&self) -> bool {
            false
        }
    }
    let bar = Bar(indicatif::ProgressBar::new(1)
        .with_style(indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} {msg}").expect("a valid template")));
    let key = penumbra::model::key_for(&engine.adapter());
    let model = penumbra::model::measure::measure(engine, &penumbra::model::measure::Suite::standard(), key, &bar)?.expect("not cancelled");
    bar.0.finish_and_clear();
    std::fs::create_dir_all(out)?;
    std::fs::write(out.join("model.json"), serde_json::to_vec_pretty(&model)?)?;
    let table = model.table();
    std::fs::write(out.join("model.md"), &table)?;
    println!("{table}");
    eprintln!("measured in {:.0} s; wrote {}", model.measure_seconds, out.join("model.json").display());
    Ok(())
}
