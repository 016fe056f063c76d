//! The daemon's Prometheus metrics (`GET /metrics`, text format 0.0.4) through the
//! `prometheus` crate, named by Prometheus's rules: one metric per quantity, its unit in its
//! name (`_bytes`, `_seconds`), counters as counters ending in `_total`, labels bounded (method
//! labels are registered method names only — a client's typo is `unknown` — routes are
//! templates, statuses numbers). Jobs by method and outcome, latency by method and by render
//! phase, HTTP requests by route and status, jobs in flight, the service's backlog (what an
//! autoscaler scales on), the process (CPU, memory, file descriptors), and — read at each
//! scrape — the engine's caches and pools, the job store and the connections.

use prometheus::{
    Encoder, GaugeVec, HistogramOpts, HistogramVec, IntCounter, IntCounterVec, IntGauge, IntGaugeVec, Opts, Registry, TextEncoder,
};

use super::connections::ConnectionStats;
use crate::engine::AdapterSummary;
use crate::engine::EngineStats;
use crate::methods::REGISTRY;
use crate::store::{Backlog, StoreStatus};
use crate::timing::Timings;

/// Latency buckets in seconds: 1 ms to 2 min, for a `hard` preview through a long `reference`.
const BUCKETS: &[f64] = &[0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 25.0, 60.0, 120.0];

pub struct Metrics {
    registry: Registry,
    jobs: IntCounterVec,
    latency: HistogramVec,
    phases: HistogramVec,
    in_flight: IntGauge,
    queued: IntGauge,
    http_requests: IntCounterVec,
    http_duration: HistogramVec,
    /// The service's backlog (no labels; absent while unknown).
    backlog_jobs: IntGaugeVec,
    backlog_oldest_age: GaugeVec,
    /// Read from `EngineStats` at each scrape.
    engine: EngineMetrics,
    device_resets: IntCounter,
    /// Read from the store's health at each scrape (absent without a store).
    store_available: IntGaugeVec,
    store_room: IntGaugeVec,
    store_free_bytes: IntGaugeVec,
    store_min_free_bytes: IntGaugeVec,
    store_reserved_bytes: IntGaugeVec,
    store_waiting_writes: IntGaugeVec,
    store_outages: IntCounter,
    /// Read from the connection tracker at each scrape.
    connections_open: IntGauge,
    connections_max: IntGauge,
    connections_closed: IntCounterVec,
}

/// The engine's caches and pools, one metric per quantity.
struct EngineMetrics {
    scene_cache_entries: IntGauge,
    scene_cache_lookups: IntCounterVec,
    pipelines: IntGauge,
    pipelines_compiled: IntCounter,
    pool_allocations: IntCounterVec,
    reference_cache_lookups: IntCounterVec,
    upload_cache_entries: IntGauge,
    upload_cache_bytes: IntGauge,
    upload_cache_budget_bytes: IntGauge,
    upload_cache_lookups: IntCounterVec,
    upload_cache_evictions: IntCounter,
}

/// Counts a job in a gauge (queued, or in flight) until dropped.
pub struct InFlight<'a>(&'a IntGauge);

impl Drop for InFlight<'_> {
    fn drop(&mut self) {
        self.0.dec();
    }
}

fn gauge(name: &str, help: &str) -> IntGauge {
    IntGauge::new(name, help).expect("valid metric")
}

/// A gauge with no labels that may be absent (`reset` removes its one series).
fn optional_gauge(name: &str, help: &str) -> IntGaugeVec {
    IntGaugeVec::new(Opts::new(name, help), &[]).expect("valid metric")
}

fn counter(name: &str, help: &str) -> IntCounter {
    IntCounter::new(name, help).expect("valid metric")
}

fn counter_vec(name: &str, help: &str, labels: &[&str]) -> IntCounterVec {
    IntCounterVec::new(Opts::new(name, help), labels).expect("valid metric")
}

/// Brings a counter up to a total read elsewhere (counters only go up; a total read lower, as
/// after a restart of what it counts, leaves it where it is).
fn catch_up(counter: &IntCounter, total: u64) {
    counter.inc_by(total.saturating_sub(counter.get()));
}

fn set(gauge: &IntGauge, value: u64) {
    gauge.set(i64::try_from(value).unwrap_or(i64::MAX));
}

fn set_optional(gauge: &IntGaugeVec, value: u64) {
    gauge.with_label_values(&[] as &[&str]).set(i64::try_from(value).unwrap_or(i64::MAX));
}

impl Metrics {
    pub fn new(adapter: &AdapterSummary) -> Self {
        let registry = Registry::new_custom(Some("penumbra".into()), None).expect("a valid prefix");
        let jobs = counter_vec("jobs_total", "Jobs finished, by method and outcome (ok or an error code)", &["method", "outcome"]);
        let latency = HistogramVec::new(
            HistogramOpts::new("job_duration_seconds", "Wall time of successful jobs, from the request to the encoded image")
                .buckets(BUCKETS.to_vec()),
            &["method"],
        )
        .expect("valid metric");
        let phases = HistogramVec::new(
            HistogramOpts::new("phase_duration_seconds", "Wall time of each render phase of successful jobs").buckets(BUCKETS.to_vec()),
            &["method", "phase"],
        )
        .expect("valid metric");
        let http_requests =
            counter_vec("http_requests_total", "HTTP requests answered, by route template and status", &["route", "status"]);
        let http_duration = HistogramVec::new(
            HistogramOpts::new("http_request_duration_seconds", "Time from a request's arrival to its answer's head, by route template")
                .buckets(BUCKETS.to_vec()),
            &["route"],
        )
        .expect("valid metric");
        let device =
            IntGaugeVec::new(Opts::new("device_info", "The adapter in use (value 1)"), &["name", "backend", "kind"]).expect("valid metric");
        device.with_label_values(&[adapter.name.as_str(), adapter.backend.as_str(), adapter.device_type.as_str()]).set(1);
        let lookups = |name: &str, what: &str| counter_vec(name, &format!("Look-ups in {what}, by result (hit or miss)"), &["result"]);
        let engine = EngineMetrics {
            scene_cache_entries: gauge("scene_cache_entries", "Scenes held on the device"),
            scene_cache_lookups: lookups("scene_cache_lookups_total", "the scene cache"),
            pipelines: gauge("pipelines", "Pipelines held, compiled"),
            pipelines_compiled: counter("pipelines_compiled_total", "Pipelines compiled"),
            pool_allocations: counter_vec(
                "pool_allocations_total",
                "GPU memory asked of the renderer's pools, by pool (targets, derived, readbacks) and result (created or reused)",
                &["pool", "result"],
            ),
            reference_cache_lookups: lookups("reference_cache_lookups_total", "the cache of reference frames for compare"),
            upload_cache_entries: gauge("upload_cache_entries", "Uploaded scenes and light images held"),
            upload_cache_bytes: gauge("upload_cache_bytes", "Bytes the held uploads take (a scene counts its CPU and GPU copies)"),
            upload_cache_budget_bytes: gauge("upload_cache_budget_bytes", "The upload cache's budget (--cache-bytes)"),
            upload_cache_lookups: lookups("upload_cache_lookups_total", "the upload cache"),
            upload_cache_evictions: counter("upload_cache_evictions_total", "Uploads evicted to keep the cache within its budget"),
        };
        let metrics = Self {
            jobs,
            latency,
            phases,
            in_flight: gauge("jobs_in_flight", "Jobs being rendered by this replica"),
            queued: gauge("jobs_queued", "Jobs admitted by this replica and waiting for its device"),
            http_requests,
            http_duration,
            backlog_jobs: optional_gauge(
                "backlog_jobs",
                "Jobs accepted and not yet started across the whole service (the same on every replica of a shared store); absent while the store cannot be read",
            ),
            backlog_oldest_age: GaugeVec::new(
                Opts::new("backlog_oldest_age_seconds", "Seconds the oldest job of the backlog has waited (0 when none waits); absent while the store cannot be read"),
                &[],
            )
            .expect("valid metric"),
            engine,
            device_resets: counter("device_resets_total", "Times the GPU device was lost and a new one opened"),
            store_available: optional_gauge("store_available", "Whether the job store answered its last call or probe (1 or 0)"),
            store_room: optional_gauge("store_room", "Whether the embedded store's disk is above its free-space margin (1 or 0)"),
            store_free_bytes: optional_gauge("store_free_bytes", "Bytes free on the embedded store's disk"),
            store_min_free_bytes: optional_gauge("store_min_free_bytes", "Bytes kept free on the embedded store's disk (--min-free-bytes)"),
            store_reserved_bytes: optional_gauge("store_reserved_bytes", "Bytes promised to admitted jobs' results"),
            store_waiting_writes: optional_gauge("store_waiting_writes", "Finished jobs whose outcome waits for the store"),
            store_outages: counter("store_outages_total", "Times the job store stopped answering"),
            connections_open: gauge("connections_open", "Client connections open"),
            connections_max: gauge("connections_max", "The cap on open client connections"),
            connections_closed: counter_vec(
                "connections_closed_total",
                "Client connections closed by the daemon, by reason (header_timeout, body_timeout, idle_timeout, shed at the cap)",
                &["reason"],
            ),
            registry,
        };
        let e = &metrics.engine;
        let collectors: Vec<Box<dyn prometheus::core::Collector>> = vec![
            Box::new(metrics.jobs.clone()),
            Box::new(metrics.latency.clone()),
            Box::new(metrics.phases.clone()),
            Box::new(metrics.in_flight.clone()),
            Box::new(metrics.queued.clone()),
            Box::new(metrics.http_requests.clone()),
            Box::new(metrics.http_duration.clone()),
            Box::new(metrics.backlog_jobs.clone()),
            Box::new(metrics.backlog_oldest_age.clone()),
            Box::new(e.scene_cache_entries.clone()),
            Box::new(e.scene_cache_lookups.clone()),
            Box::new(e.pipelines.clone()),
            Box::new(e.pipelines_compiled.clone()),
            Box::new(e.pool_allocations.clone()),
            Box::new(e.reference_cache_lookups.clone()),
            Box::new(e.upload_cache_entries.clone()),
            Box::new(e.upload_cache_bytes.clone()),
            Box::new(e.upload_cache_budget_bytes.clone()),
            Box::new(e.upload_cache_lookups.clone()),
            Box::new(e.upload_cache_evictions.clone()),
            Box::new(metrics.device_resets.clone()),
            Box::new(device),
            Box::new(metrics.store_available.clone()),
            Box::new(metrics.store_room.clone()),
            Box::new(metrics.store_free_bytes.clone()),
            Box::new(metrics.store_min_free_bytes.clone()),
            Box::new(metrics.store_reserved_bytes.clone()),
            Box::new(metrics.store_waiting_writes.clone()),
            Box::new(metrics.store_outages.clone()),
            Box::new(metrics.connections_open.clone()),
            Box::new(metrics.connections_max.clone()),
            Box::new(metrics.connections_closed.clone()),
        ];
        for collector in collectors {
            metrics.registry.register(collector).expect("metric names are unique");
        }
        // The process's CPU seconds, memory, open files and start time, unprefixed
        // (`process_*`), as every Prometheus client library names them.
        #[cfg(target_os = "linux")]
        prometheus::default_registry().register(Box::new(prometheus::process_collector::ProcessCollector::for_self())).ok();
        metrics
    }

    /// Counts a job as waiting for the device until the guard drops.
    pub fn job_queued(&self) -> InFlight<'_> {
        self.queued.inc();
        InFlight(&self.queued)
    }

    /// Counts a job as rendering until the guard drops.
    pub fn job_running(&self) -> InFlight<'_> {
        self.in_flight.inc();
        InFlight(&self.in_flight)
    }

    /// Records a finished job: its outcome, and for a success its latency and phases.
    pub fn job_finished(&self, method: &str, outcome: &str, seconds: f64, timings: Option<&Timings>) {
        let method = label(method);
        self.jobs.with_label_values(&[method, outcome]).inc();
        if let Some(timings) = timings {
            self.latency.with_label_values(&[method]).observe(seconds);
            for phase in &timings.phases {
                self.phases.with_label_values(&[method, phase.name.as_str()]).observe(phase.cpu_ms / 1e3);
            }
        }
    }

    /// Records an answered request: `route` a template (or `(no route)`), `status` its code.
    pub fn request_answered(&self, route: &str, status: u16, seconds: f64) {
        self.http_requests.with_label_values(&[route, &status.to_string()]).inc();
        self.http_duration.with_label_values(&[route]).observe(seconds);
    }

    /// Sets the backlog gauges: absent while unknown; the age 0 without a waiting job, so
    /// that an alert on it (`> 60`) and a panel of it read the same whether or not jobs wait.
    pub fn observe_backlog(&self, backlog: Option<Backlog>, now_unix_ms: u64) {
        self.backlog_jobs.reset();
        self.backlog_oldest_age.reset();
        let Some(backlog) = backlog else { return };
        set_optional(&self.backlog_jobs, backlog.jobs);
        self.backlog_oldest_age.with_label_values(&[] as &[&str]).set(backlog.oldest_age_seconds(now_unix_ms).unwrap_or(0.0));
    }

    /// Sets the store and connection metrics from their state now (absent: not shown).
    pub fn observe_service(&self, store: Option<StoreStatus>, connections: Option<ConnectionStats>) {
        if let Some(s) = store {
            set_optional(&self.store_available, u64::from(s.available));
            set_optional(&self.store_room, u64::from(s.room));
            set_optional(&self.store_min_free_bytes, s.min_free_bytes);
            set_optional(&self.store_reserved_bytes, s.reserved_bytes);
            set_optional(&self.store_waiting_writes, s.waiting_writes);
            if let Some(free) = s.free_bytes {
                set_optional(&self.store_free_bytes, free);
            }
            catch_up(&self.store_outages, s.outages);
        }
        if let Some(c) = connections {
            set(&self.connections_open, c.open);
            set(&self.connections_max, c.max);
            for (reason, total) in [
                ("header_timeout", c.header_timeouts),
                ("body_timeout", c.body_timeouts),
                ("idle_timeout", c.idle_timeouts),
                ("shed", c.shed),
            ] {
                catch_up(&self.connections_closed.with_label_values(&[reason]), total);
            }
        }
    }

    /// The text exposition, with the engine's state read now, and the process's.
    pub fn encode(&self, stats: &EngineStats) -> String {
        let (e, u) = (&self.engine, &stats.uploads);
        set(&e.scene_cache_entries, stats.scenes_cached as u64);
        set(&e.pipelines, stats.pipelines as u64);
        set(&e.upload_cache_entries, u.entries as u64);
        set(&e.upload_cache_bytes, u.bytes);
        set(&e.upload_cache_budget_bytes, u.budget_bytes);
        catch_up(&e.pipelines_compiled, stats.pipelines_compiled);
        catch_up(&e.upload_cache_evictions, u.evictions);
        for (vec, hits, misses) in [
            (&e.scene_cache_lookups, stats.scene_cache_hits, stats.scene_cache_misses),
            (&e.reference_cache_lookups, stats.reference_cache_hits, stats.reference_cache_misses),
            (&e.upload_cache_lookups, u.hits, u.misses),
        ] {
            catch_up(&vec.with_label_values(&["hit"]), hits);
            catch_up(&vec.with_label_values(&["miss"]), misses);
        }
        for (pool, created, reused) in [
            ("targets", stats.targets_created, stats.targets_reused),
            ("derived", stats.derived_created, stats.derived_reused),
            ("readbacks", stats.readbacks_created, stats.readbacks_reused),
        ] {
            catch_up(&e.pool_allocations.with_label_values(&[pool, "created"]), created);
            catch_up(&e.pool_allocations.with_label_values(&[pool, "reused"]), reused);
        }
        catch_up(&self.device_resets, stats.device_resets);
        let mut families = self.registry.gather();
        families.extend(prometheus::default_registry().gather());
        let mut text = Vec::new();
        TextEncoder::new().encode(&families, &mut text).expect("text encoding into memory");
        String::from_utf8(text).expect("the text format is UTF-8")
    }

    pub fn in_flight(&self) -> i64 {
        self.in_flight.get()
    }

    pub fn queued(&self) -> i64 {
        self.queued.get()
    }
}

/// A method name fit for a label: a registered method, else `unknown`.
fn label(method: &str) -> &'static str {
    REGISTRY.iter().map(|m| m.name()).find(|name| *name == method).unwrap_or("unknown")
}
