//! The timing breakdown of one job: wall-clock time per phase always, GPU time per phase
//! where the adapter has timestamp queries, and the warm-state facts (pipelines compiled,
//! scene uploaded) that show whether a job paid for set-up. Sent as JSON and as a
//! `Server-Timing` header.

use std::time::Instant;

use serde::Serialize;

/// The phases of a job, in the order they run; each is timed on its own (contract §3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PhaseName {
    Scene,
    ShadowMap,
    Gbuffer,
    E0,
    Method,
    Composite,
    Readback,
    Reference,
    Quality,
    Encode,
}

impl PhaseName {
    /// The name in JSON, `Server-Timing`, metrics and tables.
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Scene => "scene",
            Self::ShadowMap => "shadow_map",
            Self::Gbuffer => "gbuffer",
            Self::E0 => "e0",
            Self::Method => "method",
            Self::Composite => "composite",
            Self::Readback => "readback",
            Self::Reference => "reference",
            Self::Quality => "quality",
            Self::Encode => "encode",
        }
    }
}

impl std::fmt::Display for PhaseName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Phase {
    pub name: PhaseName,
    /// Wall-clock milliseconds on the host, GPU work included (each phase waits for it).
    pub cpu_ms: f64,
    /// GPU milliseconds between the phase's first and last timestamp, where supported.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_ms: Option<f64>,
    /// GPU time of each of the phase's passes — of each dispatch, where the adapter writes
    /// timestamps inside passes — summed over repeats of the same pass (batches, chunks).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub passes: Vec<PassTiming>,
}

/// The GPU time of one pass (or dispatch) of a phase.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PassTiming {
    pub name: &'static str,
    pub gpu_ms: f64,
}

#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Timings {
    pub phases: Vec<Phase>,
    pub total_ms: f64,
    /// Pipelines compiled for this job; 0 once the daemon is warm.
    pub pipelines_compiled: u64,
    /// Whether the scene came from the cache (no load, no upload).
    pub scene_cached: bool,
    /// Bytes uploaded to the GPU for the scene by this job; 0 when cached.
    pub scene_upload_bytes: u64,
    /// Triangles in the job's scene (object-space methods' cost follows them).
    pub scene_triangles: u64,
    /// Textures in the job's scene (base colours read from its file).
    pub scene_textures: u64,
}

impl Timings {
    /// Records that phase `name` ran from `start` until now and returns now.
    pub fn phase(&mut self, name: PhaseName, start: Instant) -> Instant {
        let now = Instant::now();
        self.phases.push(Phase { name, cpu_ms: (now - start).as_secs_f64() * 1e3, gpu_ms: None, passes: Vec::new() });
        now
    }

    /// Adds GPU time measured for pass `pass` of phase `name` to the phase's total and to
    /// the pass's own entry.
    pub fn add_gpu(&mut self, name: PhaseName, pass: &'static str, ms: f64) {
        if let Some(phase) = self.phases.iter_mut().find(|p| p.name == name) {
            *phase.gpu_ms.get_or_insert(0.0) += ms;
            match phase.passes.iter_mut().find(|p| p.name == pass) {
                Some(entry) => entry.gpu_ms += ms,
                None => phase.passes.push(PassTiming { name: pass, gpu_ms: ms }),
            }
        }
    }

    pub fn get(&self, name: PhaseName) -> Option<&Phase> {
        self.phases.iter().find(|p| p.name == name)
    }

    /// The render's own wall time: the total less a comparison's reference and metrics (what
    /// an `auto` job's prediction is of).
    pub fn render_ms(&self) -> f64 {
        let compared: f64 =
            self.phases.iter().filter(|p| matches!(p.name, PhaseName::Reference | PhaseName::Quality)).map(|p| p.cpu_ms).sum();
        self.total_ms - compared
    }

    /// The `Server-Timing` header value (W3C Server Timing): one entry per phase with its
    /// wall time, a `gpu_<phase>` entry where GPU time was measured, and `total`.
    pub fn server_timing(&self) -> String {
        let mut parts: Vec<String> = Vec::new();
        for phase in &self.phases {
            parts.push(format!("{};dur={:.3}", phase.name, phase.cpu_ms));
        }
        for phase in &self.phases {
            if let Some(gpu) = phase.gpu_ms {
                parts.push(format!("gpu_{};dur={:.3}", phase.name, gpu));
            }
        }
        parts.push(format!("total;dur={:.3}", self.total_ms));
        parts.join(", ")
    }
}

/// CPU time this process has used so far, user and system, all threads, in ms: on a software
/// adapter the device's work runs on the process's threads, so the difference over a render
/// is what it cost in cores (where nothing else runs beside it: `penumbra render`, `bench`).
pub fn process_cpu_ms() -> f64 {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::uninit();
    // SAFETY: `getrusage` fills the struct when it returns 0, and only then is it read.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) } != 0 {
        return f64::NAN;
    }
    let usage = unsafe { usage.assume_init() };
    let ms = |t: libc::timeval| t.tv_sec as f64 * 1e3 + t.tv_usec as f64 * 1e-3;
    ms(usage.ru_utime) + ms(usage.ru_stime)
}
