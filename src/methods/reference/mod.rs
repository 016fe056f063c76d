//! Method `reference`: the physically based visibility of contract §1, `Vref = E/E0` per
//! channel, estimated from many point samples on the light. The ground truth every other
//! method is measured against.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#reference.

mod bands;
mod cpu;
mod crop;
mod estimate;
mod filtered;
mod gpu;
mod samples;

use cpu::CpuSample;
pub use filtered::Filtered;
use gpu::{batch_layers, Accumulation, DepthMaps, BATCH, BATCH_MAP_BYTES, SEGMENT};
use samples::SamplePlan;
pub use samples::{half_of_index, light_samples, predicted_map_share, LightSample};

use super::{Cap, Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;
use crate::params::choice;
use crate::render::method::ERROR_ESTIMATE;
use crate::supervise::Supervisor;
use crate::timing::PhaseName;

pub struct Reference;

/// The most light samples a reference takes.
pub const MAX_SAMPLES: u32 = 4096;

const SAMPLES: Param<u32> = Param::integer(
    "samples",
    256,
    1,
    MAX_SAMPLES as i64,
    "light samples, the first of one nested, stratified sequence per seed; noise falls as 1/√samples or faster",
)
.capped(Cap::Samples);
const RESOLUTION: Param<u32> = Param::integer("resolution", 1024, 64, 4096, "side of each sample's depth map, texels");
const BIAS_TEXELS: Param<f32> =
    Param::float("bias_texels", 1.0, 0.0, 64.0, "constant bias of the visibility test, in texels of the sample's map");
const SLOPE_BIAS_TEXELS: Param<f32> =
    Param::float("slope_bias_texels", 1.0, 0.0, 64.0, "slope-scaled bias, texels × tanθ at the receiver (θ to the light's centre)");
const SEED: Param<u32> = Param::integer("seed", 1, 0, 4_294_967_295, "seed of the jitter within strata");
const CROP: Param<bool> = Param::boolean(
    "crop",
    true,
    "draw each sample's map only over the texels where the frame's receivers can fall (the same maps there: less to clear and draw)",
);

choice! {
    /// Where the maps are drawn and tested.
    enum Engine { Auto = "auto", Gpu = "gpu", Cpu = "cpu" }
}
const ENGINE: Param<Engine> = Param::choice(
    "engine",
    "where the maps are drawn and tested: the device (gpu), the CPU's cores (cpu: the same maps and tests, ~2.5× as fast on a software adapter), or cpu on a software adapter and gpu on a GPU (auto)",
);

const PARAMS: &[ParamSpec] = &[SAMPLES.spec, RESOLUTION.spec, BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec, SEED.spec, CROP.spec, ENGINE.spec];

impl ShadowMethod for Reference {
    fn name(&self) -> &'static str {
        "reference"
    }

    fn summary(&self) -> &'static str {
        "ground truth: many stratified light samples, a depth map each, per-channel ratio E/E0"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    /// A depth map of its own from every sample, none from the light's centre.
    fn reads_shadow_map(&self) -> bool {
        false
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let plan = SamplePlan::new(ctx, params);
        let on_cpu = match params.get(&ENGINE) {
            Engine::Cpu => true,
            Engine::Gpu => false,
            Engine::Auto => ctx.gpu.software,
        };
        if on_cpu {
            return record_on_cpu(ctx, params, &plan);
        }
        let (view_projs, slots) = plan.slots();
        let layers = batch_layers(plan.resolution).min(slots.len().max(1) as u32);
        let batches = plan.batches(&slots, layers, params);
        let maps = DepthMaps::new(ctx, plan.crop.size, layers, &view_projs);
        let accumulation = Accumulation::new(ctx, &plan, &batches);
        let total = plan.samples.len() as u64;
        let mut progress = Progress::new(ctx.supervisor, total);
        let mut before = 0;
        for (b, &(count, _)) in batches.iter().enumerate() {
            let first = before as usize;
            maps.draw(ctx, "reference_maps", first, &plan.crop.origins[first..first + count as usize]);
            accumulation.record(ctx, &maps, b, count, b + 1 == batches.len());
            let done = before + u64::from(count);
            before = done;
            if progress.reaches(done) {
                ctx.flush()?;
                ctx.supervisor.progress(done, total);
                // Cancelled: the renderer discards this frame, so the remaining batches
                // would only keep the device from the next job.
                if ctx.supervisor.cancelled() {
                    break;
                }
            }
        }
        let segments_tested = ctx.read_counters(&accumulation.segments_count)?[0];
        let mut counters = plan.counters(segments_tested, ctx);
        counters.insert("engine_cpu".to_owned(), 0.0);
        Ok(counters)
    }
}

/// Engine `cpu` (`cpu.rs`): the G-buffer read back, the same maps and tests on the CPU's
/// cores, and the visibility written to the frame's buffer — in bands of rows where the frame
/// needs more than `cpu_working_bytes` (`bands.rs`; the same pixels). The two halves of the
/// samples (`samples::half_of_index`) are summed apart, for the error estimate written beside
/// the visibility (`estimate.rs`). In a progressive job's rounds the sums of the samples
/// taken before come from the last round (`Carried`) and only the new samples are tested:
/// each pixel's sums get the same samples in the same order as in one render of them all.
fn record_on_cpu(ctx: &mut MethodContext<'_>, params: &Params, plan: &SamplePlan) -> JobResult<Counters> {
    let constants = plan.test_constants(params, ctx.spec.light.center);
    let samples = plan.cpu_samples();
    let channels = plan.channels() as usize;
    let width = ctx.width;
    let bands = bands::bands(width, ctx.height, cpu_bytes_per_pixel(channels), ctx.cpu_working_bytes, 0, 1);
    let supervisor = ctx.supervisor;
    let rounds = supervisor.rounds();
    let shape = (width, ctx.height, bands.len(), channels);
    let mut carried = rounds
        .and_then(|r| r.take::<Carried>())
        .filter(|c| c.shape == shape && c.samples <= samples.len())
        .map_or_else(|| Carried { shape, samples: 0, bands: vec![[0, 1].map(|_| cpu::Sums::new(0, channels)); bands.len()] }, |c| *c);
    let carried_samples = carried.samples;
    // The new samples, by half, in order.
    let mut halves: [Vec<CpuSample>; 2] = Default::default();
    for (sample, &index) in samples.iter().zip(&plan.indices).skip(carried_samples) {
        halves[usize::from(half_of_index(index))].push(sample.clone());
    }
    let new_samples = (samples.len() - carried_samples) as u64;
    let mut progress = Progress::new(supervisor, new_samples * bands.len() as u64);
    let (mut read_ms, mut write_ms, mut spent, mut segments) = (0.0, 0.0, cpu::Spent::default(), 0);
    let effective = plan.effective_samples();
    let mut penumbra = estimate::PenumbraMean::default();
    let runs = ctx.scene.casting_runs(&ctx.spec.light);
    let mut maps = cpu::Maps::new(plan.crop.size);
    for (b, band) in bands.iter().enumerate() {
        let started = std::time::Instant::now();
        let receivers = cpu::Receivers::new(&ctx.read_surfaces(band.rows.clone())?, SEGMENT, &constants);
        read_ms += started.elapsed().as_secs_f64() * 1e3;
        let geometry = cpu::Geometry { positions: ctx.scene.positions(), indices: ctx.scene.indices(), runs: &runs };
        let sums = &mut carried.bands[b];
        for half in sums.iter_mut() {
            half.resize(receivers.blocks());
        }
        let mut first = b as u64 * new_samples;
        for (half, samples) in halves.iter().enumerate() {
            // Cancelled: the renderer discards this frame.
            if supervisor.cancelled() {
                break;
            }
            let (_, half_spent) =
                cpu::estimate_into::<false>(&receivers, samples, &constants, geometry, &mut maps, &mut sums[half], |done| {
                    progress.at(first + done as u64)
                });
            first += samples.len() as u64;
            spent.add(half_spent);
        }
        let written = std::time::Instant::now();
        write_visibility_rows(ctx, band.rows.clone(), width, |rows, out| {
            penumbra.merge(cpu::write_visibility(&receivers, [&sums[0], &sums[1]], effective, (width, rows.start), out));
        });
        write_ms += written.elapsed().as_secs_f64() * 1e3;
        segments += receivers.segments;
        if supervisor.cancelled() {
            break;
        }
    }
    ctx.timer.cpu_pass(PhaseName::Method, "reference_cpu_receivers", read_ms);
    ctx.timer.cpu_pass(PhaseName::Method, "reference_cpu_maps", spent.maps_ms);
    ctx.timer.cpu_pass(PhaseName::Method, "reference_cpu_tests", spent.tests_ms);
    ctx.timer.cpu_pass(PhaseName::Method, "reference_cpu_visibility", write_ms);
    let mut counters = plan.counters(segments, ctx);
    counters.extend([
        ("engine_cpu".to_owned(), 1.0),
        ("cpu_threads".to_owned(), spent.round as f64),
        ("cpu_bands".to_owned(), bands.len() as f64),
        ("samples_carried".to_owned(), carried_samples as f64),
    ]);
    counters.insert("samples_effective".to_owned(), f64::from(effective));
    counters.insert("penumbra_pixels_estimated".to_owned(), penumbra.pixels());
    ERROR_ESTIMATE.set(&mut counters, penumbra.mean());
    if let Some(rounds) = rounds {
        carried.samples = samples.len();
        rounds.put(carried);
    }
    Ok(counters)
}

/// What the CPU engine carries between a progressive job's rounds: per band of the frame, the
/// two halves' sums of its receivers over the first `samples` of the plan. The frame is drawn
/// again each round, the same (`shape`: size, bands and channels, checked), so its receivers
/// come in the same order.
struct Carried {
    shape: (u32, u32, usize, usize),
    samples: usize,
    bands: Vec<[cpu::Sums; 2]>,
}

/// A frame's progress through its samples, reported as the GPU engine reports it: each time
/// another `BATCH` samples are done, and when all of them are.
struct Progress<'a> {
    supervisor: &'a dyn Supervisor,
    total: u64,
    done: u64,
}

impl<'a> Progress<'a> {
    fn new(supervisor: &'a dyn Supervisor, total: u64) -> Self {
        Self { supervisor, total, done: 0 }
    }

    /// Notes `done` samples done; whether that is a point to report (and flush) at. Samples
    /// done again (`filtered`'s probes of the pixels it tests late) report nothing: progress
    /// never goes back.
    fn reaches(&mut self, done: u64) -> bool {
        let report = done / BATCH > self.done / BATCH || (done == self.total && self.done < done);
        self.done = self.done.max(done);
        report
    }

    /// Notes `done` samples done, reports them where `reaches` says, and says whether to go on
    /// (the job is not cancelled).
    fn at(&mut self, done: u64) -> bool {
        if self.reaches(done) {
            self.supervisor.progress(done, self.total);
        }
        !self.supervisor.cancelled()
    }
}

/// What the CPU engine holds a pixel at most, in bytes, under a light of `channels` channels:
/// its receiver (28: `cpu::ReceiverBlock`) and listing (4), its two halves' sums (16 a channel:
/// `cpu::Sums`), and its visibility as queued for the device (16; written `VISIBILITY_ROWS` at
/// a time) — the G-buffer's copy (24) is let go before the sums are made. 96 under a coloured
/// light, 64 under a gray one.
fn cpu_bytes_per_pixel(channels: usize) -> u64 {
    28 + 4 + 16 * channels as u64 + 16
}

/// Rows of visibility written to the device at a time.
const VISIBILITY_ROWS: u32 = 64;

/// Writes the visibility of a band (the frame's rows `band_rows`, `width` pixels each) to the
/// frame's buffer `VISIBILITY_ROWS` rows at a time, so that it is never held whole beside the
/// device's copy: `fill(rows, out)` writes the band's rows `rows` (counted from its first) into
/// `out` as `vec4<f32>` texels, 16 bytes a pixel.
fn write_visibility_rows(
    ctx: &MethodContext<'_>,
    band_rows: std::ops::Range<u32>,
    width: u32,
    mut fill: impl FnMut(std::ops::Range<u32>, &mut [u8]),
) {
    let mut visibility = Vec::new();
    for first in band_rows.clone().step_by(VISIBILITY_ROWS as usize) {
        let rows = VISIBILITY_ROWS.min(band_rows.end - first);
        visibility.resize(width as usize * rows as usize * 16, 0);
        let relative = first - band_rows.start;
        fill(relative..relative + rows, &mut visibility);
        ctx.gpu.queue.write_buffer(ctx.visibility, u64::from(first) * u64::from(width) * 16, &visibility);
    }
}

#[cfg(test)]
mod tests;
