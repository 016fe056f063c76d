//! The daemon's Prometheus metrics (`GET /metrics`, text format 0.0.4) through the
//! `prometheus` crate: jobs by method and outcome, latency by method and by render phase, jobs
//! in flight, the service's backlog (what an autoscaler scales on), and — read from the engine
//! at each scrape — the upload cache, the GPU pools and the device. Method labels are registered method names only (a client's typo is `unknown`),
//! so label sets stay bounded.

use prometheus::{Encoder, HistogramOpts, HistogramVec, IntCounter, IntCounterVec, IntGauge, IntGaugeVec, Opts, Registry, TextEncoder};

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
    /// Set from `EngineStats` at each scrape.
    engine: IntGaugeVec,
    /// Brought up to `EngineStats::device_resets` at each scrape.
    device_resets: IntCounter,
    /// Set from the store's health at each scrape.
    store: IntGaugeVec,
    /// Set from the connection tracker at each scrape.
    connections: IntGaugeVec,
    /// The service's backlog (no labels; absent while unknown).
    backlog_jobs: IntGaugeVec,
    backlog_oldest_age: prometheus::GaugeVec,
}

/// Counts a job in a gauge (queued, or in flight) until dropped.
pub struct InFlight<'a>(&'a IntGauge);

impl Drop for InFlight<'_> {
    fn drop(&mut self) {
        self.0.dec();
    }
}

impl Metrics {
    pub fn new(adapter: &AdapterSummary) -> Self {
        let registry = Registry::new_custom(Some("penumbra".into()), None).expect("a valid prefix");
        let jobs = IntCounterVec::new(
            Opts::new("jobs_total", "Jobs finished, by method and outcome (ok or an error code)"),
            &["method", "outcome"],
        )
        .expect("valid metric");
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
        let in_flight = IntGauge::new("jobs_in_flight", "Jobs being rendered").expect("valid metric");
        let queued = IntGauge::new("jobs_queued", "Jobs admitted and waiting for the device").expect("valid metric");
        let engine = IntGaugeVec::new(Opts::new("engine", "Engine state: caches, pools, uploads (see the `what` label)"), &["what"])
            .expect("valid metric");
        let device =
            IntGaugeVec::new(Opts::new("device_info", "The adapter in use (value 1)"), &["name", "backend", "kind"]).expect("valid metric");
        device.with_label_values(&[adapter.name.as_str(), adapter.backend.as_str(), adapter.device_type.as_str()]).set(1);
        let device_resets =
            IntCounter::new("device_resets_total", "Times the GPU device was lost and a new one opened").expect("valid metric");
        let store = IntGaugeVec::new(
            Opts::new(
                "store",
                "Job store: available (1/0), room (1/0: its disk above the margin), free_bytes, min_free_bytes, reserved_bytes, outages, waiting_writes (finished jobs whose outcome waits for it)",
            ),
            &["what"],
        )
        .expect("valid metric");
        let connections = IntGaugeVec::new(
            Opts::new(
                "connections",
                "Client connections: open, max, and closed for header_timeouts, body_timeouts, idle_timeouts, shed (at the cap)",
            ),
            &["what"],
        )
        .expect("valid metric");
        let backlog_jobs = IntGaugeVec::new(
            Opts::new("backlog_jobs", "Jobs accepted and not yet started across the whole service (the same on every replica of a shared store); absent while the store cannot be read"),
            &[],
        )
        .expect("valid metric");
        let backlog_oldest_age = prometheus::GaugeVec::new(
            Opts::new(
                "backlog_oldest_age_seconds",
                "Seconds the oldest job of the backlog has waited; absent when there is none or it is unknown",
            ),
            &[],
        )
        .expect("valid metric");
        for collector in [
            Box::new(device_resets.clone()) as Box<dyn prometheus::core::Collector>,
            Box::new(backlog_jobs.clone()),
            Box::new(backlog_oldest_age.clone()),
            Box::new(jobs.clone()),
            Box::new(latency.clone()),
            Box::new(phases.clone()),
            Box::new(in_flight.clone()),
            Box::new(queued.clone()),
            Box::new(engine.clone()),
            Box::new(store.clone()),
            Box::new(connections.clone()),
            Box::new(device),
        ] {
            registry.register(collector).expect("metric names are unique");
        }
        Self {
            registry,
            jobs,
            latency,
            phases,
            in_flight,
            queued,
            engine,
            device_resets,
            store,
            connections,
            backlog_jobs,
            backlog_oldest_age,
        }
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

    /// Sets the backlog gauges: absent while unknown, the age absent without a waiting job.
    pub fn observe_backlog(&self, backlog: Option<Backlog>, now_unix_ms: u64) {
        self.backlog_jobs.reset();
        self.backlog_oldest_age.reset();
        let Some(backlog) = backlog else { return };
        self.backlog_jobs.with_label_values(&[] as &[&str]).set(i64::try_from(backlog.jobs).unwrap_or(i64::MAX));
        if let Some(oldest) = backlog.oldest_unix_ms {
            self.backlog_oldest_age.with_label_values(&[] as &[&str]).set(now_unix_ms.saturating_sub(oldest) as f64 / 1e3);
        }
    }

    /// Sets the store and connection gauges from their state now (absent: not shown).
    pub fn observe_service(&self, store: Option<StoreStatus>, connections: Option<ConnectionStats>) {
        let gauge =
            |vec: &IntGaugeVec, what: &str, value: u64| vec.with_label_values(&[what]).set(i64::try_from(value).unwrap_or(i64::MAX));
        if let Some(s) = store {
            for (what, value) in [
                ("available", u64::from(s.available)),
                ("room", u64::from(s.room)),
                ("min_free_bytes", s.min_free_bytes),
                ("reserved_bytes", s.reserved_bytes),
                ("outages", s.outages),
                ("waiting_writes", s.waiting_writes),
            ] {
                gauge(&self.store, what, value);
            }
            if let Some(free) = s.free_bytes {
                gauge(&self.store, "free_bytes", free);
            }
        }
        if let Some(c) = connections {
            for (what, value) in [
                ("open", c.open),
                ("max", c.max),
                ("header_timeouts", c.header_timeouts),
                ("body_timeouts", c.body_timeouts),
                ("idle_timeouts", c.idle_timeouts),
                ("shed", c.shed),
            ] {
                gauge(&self.connections, what, value);
            }
        }
    }

    /// The text exposition, with the engine's state read now.
    pub fn encode(&self, stats: &EngineStats) -> String {
        let u = &stats.uploads;
        for (what, value) in [
            ("scenes_cached", stats.scenes_cached as u64),
            ("scene_cache_hits", stats.scene_cache_hits),
            ("scene_cache_misses", stats.scene_cache_misses),
            ("pipelines", stats.pipelines as u64),
            ("pipelines_compiled", stats.pipelines_compiled),
            ("targets_created", stats.targets_created),
            ("targets_reused", stats.targets_reused),
            ("derived_created", stats.derived_created),
            ("derived_reused", stats.derived_reused),
            ("readbacks_created", stats.readbacks_created),
            ("readbacks_reused", stats.readbacks_reused),
            ("reference_cache_hits", stats.reference_cache_hits),
            ("reference_cache_misses", stats.reference_cache_misses),
            ("upload_entries", u.entries as u64),
            ("upload_bytes", u.bytes),
            ("upload_budget_bytes", u.budget_bytes),
            ("upload_hits", u.hits),
            ("upload_misses", u.misses),
            ("upload_evictions", u.evictions),
        ] {
            self.engine.with_label_values(&[what]).set(i64::try_from(value).unwrap_or(i64::MAX));
        }
        self.device_resets.inc_by(stats.device_resets.saturating_sub(self.device_resets.get()));
        let mut text = Vec::new();
        TextEncoder::new().encode(&self.registry.gather(), &mut text).expect("text encoding into memory");
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
