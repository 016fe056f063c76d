//! `penumbra serve`: opens the store, binds the listener with its connection limits, warms
//! the engine up, serves until SIGINT or SIGTERM, then finishes the work it accepted.

use super::*;
use crate::config::{JobStoreKind, ModelMode};

/// Binds, warms up, serves until SIGINT or SIGTERM, then finishes requests in flight.
pub async fn serve(config: ServeConfig, engine: Arc<Engine>) -> anyhow::Result<()> {
    let queue = QueueConfig {
        capacity: config.queue,
        concurrency: config.concurrency,
        deadline: std::time::Duration::from_secs_f64(config.deadline_secs.max(0.0)),
    };
    let ttl = std::time::Duration::from_secs_f64(config.results_ttl_secs.max(0.0));
    let mut state = AppState::new(engine.clone(), config.results_kept)
        .with_queue(queue)
        .with_results_ttl(ttl)
        .with_idempotency(Idempotency::new(
            std::time::Duration::from_secs_f64(config.idempotency_ttl_secs.max(1.0)),
            config.idempotency_keys,
        ))
        .with_cors_origins(&config.cors_origins)?
        .with_replica(Replica::new(replica_name(&config), std::time::Duration::from_secs_f64(config.heartbeat_secs)));
    if let Some(path) = &config.auth_token_file {
        let auth = auth::Auth::from_file(path, config.metrics_open)?;
        tracing::info!(metrics_open = auth.metrics_open, "bearer tokens required on /v1");
        state = state.with_auth(auth);
    }
    state = with_job_store(state, &config, ttl)?;
    let tracker = connections::Tracker::new(connections::ConnectionLimits::from_config(&config).within_fd_limit());
    let state = Arc::new(
        state.with_store_retry(std::time::Duration::from_secs_f64(config.store_retry_secs.max(0.0))).with_connections(tracker.clone()),
    );
    if let Some(store) = &state.store {
        store.probe().await;
        store.spawn_probe();
    }
    let resumed = state.resume_unfinished().await?;
    if resumed > 0 {
        tracing::info!(resumed, "resumed jobs accepted before the last stop");
    }
    state.spawn_expiry(ttl, config.results_bytes);
    let listener = tokio::net::TcpListener::bind(config.listen).await?;
    let lavapipe_threads = std::env::var("LP_NUM_THREADS").unwrap_or_else(|_| "unset".into());
    tracing::info!(address = %listener.local_addr()?, lavapipe_threads, max_connections = tracker.stats().max, "listening");
    tracker.spawn_sweeper();
    let listener = connections::TrackedListener::new(listener, tracker);
    spawn_warm_up(state.clone(), !config.no_warm_up, (config.model, config.data_dir.clone()));
    let stopping = state.clone();
    let signal = async move {
        shutdown_signal().await;
        stopping.begin_shutdown();
    };
    let service = app(state.clone())
        .layer(axum::middleware::from_fn(connections::track))
        .into_make_service_with_connect_info::<connections::ConnRef>();
    axum::serve(listener, service).with_graceful_shutdown(signal).await?;
    // Requests in flight have finished; jobs submitted with POST /v1/jobs may still run.
    if !state.drain(state.queue.deadline + std::time::Duration::from_secs(600)).await {
        tracing::warn!("shut down with submitted jobs unfinished");
    }
    tracing::info!("shut down");
    Ok(())
}

/// `state` with the job store `--job-store` names: none (in memory), the embedded one under
/// `--data-dir`, or a Redis queue shared with other replicas.
fn with_job_store(state: AppState, config: &ServeConfig, ttl: std::time::Duration) -> anyhow::Result<AppState> {
    Ok(match &config.job_store {
        JobStoreKind::Memory => {
            tracing::warn!("job store in memory: submitted jobs are lost when the daemon stops");
            state
        }
        JobStoreKind::Embedded => {
            let store = crate::store::EmbeddedStore::open(&config.data_dir)?.with_max_keys(config.idempotency_keys);
            tracing::info!(data_dir = %config.data_dir.display(), min_free_bytes = config.min_free_bytes, "job store: embedded");
            state.with_store(Store::new(Arc::new(store), "embedded", config.min_free_bytes))
        }
        JobStoreKind::Redis(url) => {
            let claim_idle = std::time::Duration::from_secs_f64(config.claim_idle_secs.max(0.5));
            let store = crate::store::RedisStore::open(url, config.redis_ca_cert.as_deref(), ttl, claim_idle)?;
            tracing::info!("job store: redis (shared queue; this replica takes jobs from it)");
            state.with_store(Store::new(Arc::new(store), "redis", 0))
        }
    })
}

/// This replica's name: `--replica-name`, else `$HOSTNAME` (the pod's name under Kubernetes),
/// else the listen address.
fn replica_name(config: &ServeConfig) -> String {
    [config.replica_name.clone(), std::env::var("HOSTNAME").ok()]
        .into_iter()
        .flatten()
        .find(|name| !name.trim().is_empty())
        .unwrap_or_else(|| config.listen.to_string())
}

/// Compiles the pipelines and uploads the default scene (unless `warm_up` is false) in the
/// background, then marks the daemon ready, starts its workers and its heartbeat, and reads or
/// measures the device's model (`auto.rs`).
fn spawn_warm_up(state: Arc<AppState>, warm_up: bool, (model, data_dir): (ModelMode, std::path::PathBuf)) {
    tokio::spawn(async move {
        let started = std::time::Instant::now();
        if warm_up {
            let engine = state.engine.clone();
            if let Err(error) =
                tokio::task::spawn_blocking(move || engine.warm_up()).await.unwrap_or_else(|e| Err(JobError::internal(e.to_string())))
            {
                tracing::error!(%error, "warm-up failed");
                return;
            }
        }
        state.set_ready();
        tracing::info!(duration_ms = started.elapsed().as_millis() as u64, "ready: pipelines compiled, default scene uploaded");
        // A replica of a shared store takes jobs, and joins the cluster view, once it is warm.
        state.spawn_workers();
        state.spawn_heartbeat();
        // After readiness: `auto` answers with the shipped model until this one is in.
        super::auto::spawn_model(state, model, data_dir);
    });
}

async fn shutdown_signal() {
    let interrupt = tokio::signal::ctrl_c();
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = interrupt => {},
        _ = terminate => {},
    }
    tracing::info!("shutdown signal received; finishing requests in flight");
}
