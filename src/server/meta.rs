//! What the server says about itself: methods and limits, readiness, Prometheus metrics and
//! the JSON stats the dashboard draws.

use super::*;

/// `GET /v1/limits`: every limit the server enforces, with its value (all configurable).
pub(super) async fn limits(State(state): State<Arc<AppState>>) -> Json<Value> {
    let limits = state.engine.limits();
    Json(json!({
        "max_body_bytes": limits.max_body_bytes,
        "max_output_dim": limits.max_output_dim,
        "max_output_pixels": limits.max_output_pixels,
        "max_shadow_map_resolution": limits.max_shadow_map_resolution,
        "max_triangles": limits.max_triangles,
        "max_light_image_dim": limits.max_light_image_dim,
        "max_texture_dim": limits.max_texture_dim,
        "max_texture_bytes": limits.max_texture_bytes,
        "max_json_depth": limits.max_json_depth,
        "max_vertices": limits.max_vertices,
        "max_samples": limits.max_samples,
        "max_rounds": limits.max_rounds,
        "max_cpu_working_bytes": limits.max_cpu_working_bytes,
        "queue": state.queue_config.capacity,
        "concurrency": state.queue_config.concurrency,
        "deadline_secs": state.queue_config.deadline.as_secs_f64(),
        "upload_cache_bytes": state.engine.upload_stats().budget_bytes,
        "method_params": REGISTRY.iter().map(|m| (m.name().to_owned(), capped_params(m.params(), limits))).collect::<serde_json::Map<_, _>>(),
    }))
}

/// A method's parameters as `/v1/limits` lists them: ranges ending at the operator's caps.
fn capped_params(specs: &[crate::methods::ParamSpec], limits: &crate::job::Limits) -> Value {
    let mut listed = json!(specs);
    for (spec, listed) in specs.iter().zip(listed.as_array_mut().into_iter().flatten()) {
        if let (Some((cap, _)), Some(max)) = (spec.cap.map(|c| limits.cap(c)), listed["max"].as_i64()) {
            listed["max"] = json!(max.min(cap));
        }
    }
    listed
}

/// `GET /readyz`: 200 once warm, 503 while warming up, stopping, or unable to take submitted
/// jobs (the store does not answer, or its disk is at the margin) — so a load balancer sends
/// work elsewhere while `/healthz` stays 200 and nothing restarts a healthy process.
pub(super) async fn readyz(State(state): State<Arc<AppState>>) -> Response {
    let unavailable = |status: &str| (StatusCode::SERVICE_UNAVAILABLE, Json(json!({"status": status}))).into_response();
    if *state.stopping.borrow() {
        unavailable("stopping")
    } else if !state.ready.load(Ordering::SeqCst) {
        unavailable("warming up")
    } else if let Some(trouble) = state.store_trouble() {
        let mut response = unavailable(trouble);
        response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from_static("2"));
        response
    } else {
        let mut ready = json!({"status": "ready", "adapter": state.engine.adapter(), "replica": state.replica.name});
        if state.shared_store().is_some() {
            ready["heartbeat"] = state.replica.heartbeat_detail();
        }
        Json(ready).into_response()
    }
}

/// `GET /v1/methods`: the registry, the built-ins, and the device's cost and quality model
/// (`auto` chooses by it; its `status` says whether it is this device's yet).
pub(super) async fn methods(State(state): State<Arc<AppState>>) -> Json<Value> {
    let methods: Vec<Value> = REGISTRY.iter().map(|m| json!({"name": m.name(), "summary": m.summary(), "params": m.params()})).collect();
    let mut model = state.model.get().summary();
    model["status"] = state.model.status().into();
    model["pace"] = json!({"factor": state.model.pace(), "renders": state.model.pace_renders(), "window": crate::model::PACE_WINDOW});
    Json(json!({
        "methods": methods,
        "scenes": BUILTIN_SCENES,
        "light_images": BUILTIN_LIGHT_IMAGES,
        "model": model,
    }))
}

/// `GET /metrics`: Prometheus text format.
pub(super) async fn metrics(State(state): State<Arc<AppState>>) -> Response {
    state.metrics.observe_service(state.store.as_ref().map(|s| s.health().status()), state.connections.as_ref().map(|c| c.stats()));
    state.metrics.observe_backlog(state.backlog().await, unix_ms());
    let text = state.metrics.encode(&state.engine.stats());
    ([(header::CONTENT_TYPE, HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"))], text).into_response()
}

/// Jobs listed in `/v1/stats` (newest first).
const STATS_RECENT: usize = 40;

/// `GET /v1/stats`: what the dashboard draws — the replica that answered (its engine's
/// caches, pools and uploads, its queue), and the service: the backlog, the live replicas and
/// the recent jobs of all of them with throughput, latency per method and phase breakdowns.
pub(super) async fn stats(State(state): State<Arc<AppState>>) -> Json<Value> {
    let uptime_s = state.started.elapsed().map(|d| d.as_secs_f64()).unwrap_or(0.0);
    let (cluster, jobs) = state.cluster_view(STATS_RECENT).await;
    Json(json!({
        "replica": state.replica.name,
        "cluster": cluster,
        "adapter": state.engine.adapter(),
        "uptime_s": uptime_s,
        "jobs_in_flight": state.metrics.in_flight(),
        "jobs_queued": state.metrics.queued(),
        "backlog": state.backlog().await.map(|b| json!({
            "jobs": b.jobs,
            "oldest_age_seconds": b.oldest_age_seconds(unix_ms()),
        })),
        "queue": {"capacity": state.queue_config.capacity, "concurrency": state.queue_config.concurrency},
        "store": state.store.as_ref().map(|s| s.health().status()),
        "connections": state.connections.as_ref().map(|c| c.stats()),
        "engine": state.engine.stats(),
        "jobs": jobs,
    }))
}
