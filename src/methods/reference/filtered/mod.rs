//! Method `filtered`: `reference`'s estimate where it matters and a few samples elsewhere,
//! then filtered over the penumbra — the ratio estimator of Heitz, Hill & McGuire 2018 (the
//! unshadowed irradiance E0 stays exact; only V = Σ L·G·V / Σ L·G is estimated) with Mehta,
//! Wang & Ramamoorthi 2012's two halves of "axis-aligned filtering": samples where the filter
//! cannot gather enough (§5, adaptive sampling) and a filter sized by the penumbra (§4),
//! guided by the G-buffer as in SVGF (Schied et al. 2017).
//!
//! The samples are `reference`'s (the same sequence, maps, crops and bias): the first
//! `samples × refine²` of its sequence, whose first `samples` — themselves stratified over the
//! whole light, as every prefix of the sequence is — probe every pixel. A pixel whose tile or a
//! neighbour tile has a pixel its probes see partly lit, or both fully lit and fully shadowed
//! pixels, is in or near a penumbra: it is tested against the rest too, and there it is
//! `reference` with `samples × refine²` samples. The rest keep their probes' verdict (0 or 1,
//! which more samples would only confirm). Every map is drawn once. On a frame of few pixels
//! for its triangles every pixel is tested against every sample: there the maps cost far more
//! than the tests the probes would save (`REFINE_EVERYWHERE_PIXELS_PER_TRIANGLE`). Either of
//! the reference's engines draws the maps and makes the tests (`engine`): the CPU's cores, or
//! the device (`gpu.rs`); the classification and the filter are the CPU's either way.
//!
//! Why not a few samples a pixel everywhere, rotated per pixel, as the papers do with rays: a
//! sample is a depth map here, and a map costs what its triangles cost, whatever the pixels,
//! so the distinct samples, not the tests, set the price; and at small sizes a penumbra is a
//! few pixels wide, too narrow for a filter to make a few samples a pixel good (measured in
//! docs/methods.md#filtered). The probes cut the tests; the filter then smooths what the
//! strata leave where a penumbra spans pixels enough.

mod filter;
mod gpu;

use rayon::prelude::*;

use super::bands::{self, Band};
use super::cpu::{self, BlockerBlock, CpuSample, Receivers, Sums};
use super::estimate::{PenumbraMean, Texels};
use super::gpu::SEGMENT;
use super::samples::{half_of_index, SamplePlan};
use super::{
    write_visibility_rows, Counters, Engine, MethodContext, Param, ParamSpec, Params, Progress, ShadowMethod, BIAS_TEXELS, CROP, ENGINE,
    RESOLUTION, SEED, SLOPE_BIAS_TEXELS,
};
use crate::error::JobResult;
use crate::gpu::scene::Runs;
use crate::params::Cap;
use crate::render::method::{CounterKey, ERROR_ESTIMATE};
use crate::timing::PhaseName;
use filter::FilterInputs;

pub struct Filtered;

// At most 64 × 4² = 1,024 samples in a penumbra, a quarter of what `reference` may take.
const SAMPLES: Param<u32> =
    Param::integer("samples", 16, 1, 64, "light samples that probe every pixel: one stratified set over the whole light")
        .capped(Cap::Samples);
const REFINE: Param<u32> = Param::integer(
    "refine",
    4,
    1,
    4,
    "a pixel in or near a penumbra (every pixel on a frame of at most ten pixels a scene triangle) is tested against samples × refine² samples (each probe's stratum cut refine × refine)",
);
const FILTER: Param<bool> = Param::boolean("filter", true, "filter the visibility over the penumbra (off: each pixel's own samples)");
const FILTER_SCALE: Param<f32> = Param::float(
    "filter_scale",
    0.5,
    0.0,
    8.0,
    "the filter's width in steps of the samples' banding (the penumbra's width over the strata across the light)",
);

const PARAMS: &[ParamSpec] = &[
    SAMPLES.spec,
    REFINE.spec,
    FILTER.spec,
    FILTER_SCALE.spec,
    RESOLUTION.spec,
    BIAS_TEXELS.spec,
    SLOPE_BIAS_TEXELS.spec,
    SEED.spec,
    CROP.spec,
    ENGINE.spec,
];

/// Pixels tested against every sample, not the probes alone.
pub const PIXELS_REFINED: CounterKey = CounterKey("pixels_refined");

impl ShadowMethod for Filtered {
    fn name(&self) -> &'static str {
        "filtered"
    }

    fn summary(&self) -> &'static str {
        "reference's samples where a penumbra is, a few probes elsewhere, filtered by the penumbra's width (Heitz 2018, Mehta 2012)"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    /// As `reference`: maps of the samples' own.
    fn reads_shadow_map(&self) -> bool {
        false
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let started = std::time::Instant::now();
        let spec = ctx.spec;
        let (probes, refine) = (params.get(&SAMPLES), params.get(&REFINE));
        let strata = probes * refine * refine;
        // The reference's plan of as many samples: the same maps.
        let plan = SamplePlan::first(ctx, params, strata);
        let constants = plan.test_constants(params, spec.light.center);
        // The samples by round (the probes, the rest) and half (the sequence's two), by their
        // place in the plan.
        let mut order: [[Vec<usize>; 2]; 2] = Default::default();
        for (k, &index) in plan.indices.iter().enumerate() {
            order[usize::from(index >= probes)][usize::from(half_of_index(index))].push(k);
        }
        let cpu_samples = plan.cpu_samples();
        let [probe_samples, other_samples]: [[Vec<CpuSample>; 2]; 2] =
            order.clone().map(|halves| halves.map(|ks| ks.iter().map(|&k| cpu_samples[k].clone()).collect()));
        let on_cpu = match params.get(&ENGINE) {
            Engine::Cpu => true,
            Engine::Gpu => false,
            Engine::Auto => ctx.gpu.software,
        };
        let device = (!on_cpu).then(|| gpu::DeviceTests::new(ctx, &plan, params, &order));
        let pixels = u64::from(ctx.width) * u64::from(ctx.height);
        let everywhere = pixels <= REFINE_EVERYWHERE_PIXELS_PER_TRIANGLE * ctx.scene.triangles;
        let lit_tiles = !everywhere && pixels > LIT_TILES_PIXELS_PER_TRIANGLE * ctx.scene.triangles;
        let shared = Shared {
            everywhere,
            lit_tiles,
            runs: ctx.scene.casting_runs(&spec.light),
            probes: probe_samples.concat(),
            // The probes with no map: each test lit, as it is in a tile they all see lit.
            lit_probes: probe_samples.clone().map(|half| half.into_iter().map(|s| CpuSample { crop_origin: None, ..s }).collect()),
            probe_samples,
            other_samples,
            constants,
            channels: plan.channels() as usize,
            crop_size: plan.crop.size,
            filter: FilterShape {
                light_extent: spec.light.size_m.x.max(1e-6).sqrt() * spec.light.size_m.y.max(1e-6).sqrt(),
                samples_across: (strata as f32).sqrt(),
                scale: if params.get(&FILTER) { params.get(&FILTER_SCALE) } else { 0.0 },
                samples_effective: plan.effective_samples(),
            },
        };
        let mut done = Done { read_ms: started.elapsed().as_secs_f64() * 1e3, ..Done::default() };
        let (per_pixel, budget) = match &device {
            None => (cpu_bytes_per_pixel(shared.channels), ctx.cpu_working_bytes),
            Some(device) => {
                // A band's records are one storage binding on the device too: at most a row of
                // segments' lanes (the width rounded up to a segment) a row of the reach.
                let per_pixel = gpu_bytes_per_pixel(shared.channels, device.record_floats());
                let row_bytes = u64::from(ctx.width.next_multiple_of(SEGMENT)) * 4 * device.record_floats() as u64;
                let rows = ctx.gpu.device.limits().max_storage_buffer_binding_size / row_bytes;
                (per_pixel, ctx.cpu_working_bytes.min(rows * u64::from(ctx.width) * per_pixel))
            }
        };
        let bands = bands::bands(ctx.width, ctx.height, per_pixel, budget, HALO_ROWS, filter::TILE);
        let supervisor = ctx.supervisor;
        let mut progress = Progress::new(supervisor, shared.samples() * bands.len() as u64);
        for (b, band) in bands.iter().enumerate() {
            render_band(ctx, &shared, device.as_ref(), band, (b as u64 * shared.samples(), &mut progress), &mut done)?;
            if supervisor.cancelled() {
                break;
            }
        }
        ctx.timer.cpu_pass(PhaseName::Method, "filtered_receivers", done.read_ms);
        if on_cpu {
            ctx.timer.cpu_pass(PhaseName::Method, "filtered_maps", done.spent.maps_ms);
            ctx.timer.cpu_pass(PhaseName::Method, "filtered_tests", done.spent.tests_ms);
        } else {
            ctx.timer.cpu_pass(PhaseName::Method, "filtered_gather", done.gather_ms);
        }
        ctx.timer.cpu_pass(PhaseName::Method, "filtered_filter", done.filter_ms);

        let mut counters = plan.counters(done.segments, ctx);
        counters.extend([
            ("probes".to_owned(), f64::from(probes)),
            ("samples_effective".to_owned(), f64::from(shared.filter.samples_effective)),
            ("refine".to_owned(), f64::from(refine)),
            ("refined_everywhere".to_owned(), f64::from(u8::from(shared.everywhere))),
            ("engine_cpu".to_owned(), f64::from(u8::from(on_cpu))),
            ("cpu_threads".to_owned(), done.spent.round as f64),
            ("cpu_bands".to_owned(), bands.len() as f64),
            ("pixels_filtered".to_owned(), done.pixels_filtered as f64),
            ("tiles_found_lit".to_owned(), done.tiles_found_lit as f64),
            ("penumbra_pixels_estimated".to_owned(), done.penumbra.pixels()),
        ]);
        PIXELS_REFINED.set(&mut counters, done.pixels_refined as f64);
        ERROR_ESTIMATE.set(&mut counters, done.penumbra.mean());
        Ok(counters)
    }
}

/// The most pixels a frame has, per triangle of its scene, for every covered pixel to be
/// tested against every sample, not only those the probes find near a penumbra. The
/// refinement saves tests, and every map is drawn anyway: a triangle set up and drawn into a
/// map costs as much as a few dozen tests of a pixel against one, so on a frame of at most ten
/// pixels a triangle testing every pixel adds at most a fraction of the maps' time (measured
/// in docs/methods.md), and no small penumbra that all the probes happened to miss is left
/// out. Counted on the frame, not a band, so that bands give the frame's pixels.
const REFINE_EVERYWHERE_PIXELS_PER_TRIANGLE: u64 = 10;

/// The fewest pixels a frame has, per triangle of its scene, for the CPU engine to look for the
/// tiles every probe sees lit (`cpu::lit_tiles`): that draws the probes' maps once more, and a
/// triangle drawn into a map costs about as much as 25 tests (docs/methods.md), so the 16 maps
/// pay where the tests they spare — 16 a pixel, in the half or so of a frame found lit, and
/// only their map reads where the filter still wants the pixels' sums — outnumber about 50 a
/// triangle. Measured at 1080p: five in six tiles found lit on `crowd` (224 pixels a
/// triangle) and 12 % off its request; even on 100k-triangle `terrain` (21), whose tiles found
/// lit all lie within the filter's reach (docs/performance-log.md).
const LIT_TILES_PIXELS_PER_TRIANGLE: u64 = 50;

/// The rows a band reads beyond those it writes, either side: what a written pixel depends on —
/// the column pass's reach (`MAX_RADIUS`, 24), the fallback σ of the tiles around the pixels it
/// reads (up to 15 rows further) and the refinement of those pixels, decided by the tiles
/// around theirs (15 more) — rounded to whole tiles, so that the band's tiles are the frame's.
const HALO_ROWS: u32 = 56;

/// What `filtered` holds a pixel of a band at most, in bytes, under a light of `channels`
/// channels (1 or 3): its surface (24), texel (16 a channel: `Texels`) and blockers met (8),
/// the probes' receiver (32), a half's sums (8 a channel) and its blockers met (8), and its
/// refined flag and filter slot (5) — 101 under a gray light, 149 under a coloured one; the
/// filter's copies of the refined pixels and the visibility written come after the receivers
/// are let go.
fn cpu_bytes_per_pixel(channels: usize) -> u64 {
    24 + 16 * channels as u64 + 8 + 32 + 8 * channels as u64 + 8 + 5
}

/// What the GPU engine's bands hold a pixel at most, in bytes, with records of `record_floats`
/// floats under a light of `channels` channels: its surface (24), texel (16 a channel),
/// blockers met (8), refined flag and filter slot (5), and a round's record read back
/// (`gpu::DeviceTests::test`), mapped and as the device left it.
fn gpu_bytes_per_pixel(channels: usize, record_floats: usize) -> u64 {
    24 + 16 * channels as u64 + 8 + 5 + 2 * 4 * record_floats as u64
}

/// What every band shares: the samples, split into the probes and the rest, each in the
/// reference's two halves, and the filter's shape.
struct Shared {
    /// Whether every covered pixel is tested against every sample
    /// (`REFINE_EVERYWHERE_PIXELS_PER_TRIANGLE`).
    everywhere: bool,
    /// Whether the CPU engine looks for the tiles every probe sees lit
    /// (`LIT_TILES_PIXELS_PER_TRIANGLE`).
    lit_tiles: bool,
    /// The triangles the CPU engine's maps draw (`GpuScene::casting_runs`).
    runs: Runs,
    probe_samples: [Vec<CpuSample>; 2],
    other_samples: [Vec<CpuSample>; 2],
    /// The probes of both halves, in order.
    probes: Vec<CpuSample>,
    /// The probes without their maps (`CpuSample::crop_origin` none): their sums in the tiles
    /// they all see lit (`cpu::lit_tiles`), where every test is lit.
    lit_probes: [Vec<CpuSample>; 2],
    constants: cpu::TestConstants,
    channels: usize,
    crop_size: glam::UVec2,
    filter: FilterShape,
}

impl Shared {
    /// How many samples, the probes and the rest.
    fn samples(&self) -> u64 {
        count(&self.probe_samples) + count(&self.other_samples)
    }
}

/// The samples a round of tests takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tested {
    /// The first `samples` of the frame's sequence, over every pixel not found lit without them.
    Probes,
    /// The rest, over the pixels where the probes vary.
    Others,
    /// The probes with no map, every test lit: the sums of the tiles found lit that the filter
    /// reads. The CPU engine's alone, since only it looks for such tiles.
    ProbesUnmapped,
}

/// The samples of a round's two halves.
fn count(halves: &[Vec<CpuSample>; 2]) -> u64 {
    (halves[0].len() + halves[1].len()) as u64
}

/// The filter's parameters from the light and the samples (`FilterInputs`).
struct FilterShape {
    light_extent: f32,
    samples_across: f32,
    scale: f32,
    samples_effective: f32,
}

/// What the bands did, summed.
#[derive(Default)]
struct Done {
    read_ms: f64,
    spent: cpu::Spent,
    /// The GPU engine's records added to the texels.
    gather_ms: f64,
    filter_ms: f64,
    segments: u32,
    pixels_refined: usize,
    pixels_filtered: usize,
    /// Tiles every probe sees lit, found without a test (`cpu::lit_tiles`).
    tiles_found_lit: usize,
    penumbra: PenumbraMean,
}

/// A band of the frame, whose samples follow the frame's `before` others: the probes over its
/// reach, every sample where they vary (on the device where `device` is given, else on the
/// CPU's cores), the filter, and the visibility of its rows written to the frame.
fn render_band(
    ctx: &mut MethodContext<'_>,
    shared: &Shared,
    device: Option<&gpu::DeviceTests>,
    band: &Band,
    (before, progress): (u64, &mut Progress<'_>),
    done: &mut Done,
) -> JobResult<()> {
    let width = ctx.width;
    let height = band.reach.len() as u32;
    // The CPU engine's maps, kept from round to round and let go before the filter.
    let mut maps = cpu::Maps::new(shared.crop_size);
    // The probes' maps as their cells' largest depths (for `cpu::lit_tiles`), drawn on the
    // CPU's cores while this thread waits for the G-buffer to come back.
    let mut maxima = None;
    let scene = ctx.scene;
    let surfaces = rayon::in_place_scope(|scope| {
        if device.is_none() && shared.lit_tiles {
            scope.spawn(|_| {
                let geometry = cpu::Geometry { positions: scene.positions(), indices: scene.indices(), runs: &shared.runs };
                maxima = Some(cpu::cell_maxima(&shared.probes, geometry, &mut maps));
            });
        }
        let started = std::time::Instant::now();
        let surfaces = ctx.read_surfaces(band.reach.clone());
        done.read_ms += started.elapsed().as_secs_f64() * 1e3;
        surfaces
    })?;

    let (probe_count, other_count) = (count(&shared.probe_samples), count(&shared.other_samples));
    let mut texels = Texels::new((width * height) as usize, shared.channels);
    let mut blockers = vec![[0.0f32; 2]; (width * height) as usize];
    let mut round = Round { ctx, shared, device, band, surfaces: &surfaces, progress, done, maps };

    // The probes, everywhere but in the tiles they all see lit as a whole (on the CPU's cores;
    // every pixel where every pixel is refined): those pixels are lit, as their tests would say.
    let tiles = filter::Tiles::new(width, height);
    let tile = |x: u32, y: u32| tiles.of((y * width + x) as usize);
    let lit = maxima.map(|maxima| round.lit_tiles(maxima));
    let settled = |x: u32, y: u32| lit.as_ref().is_some_and(|lit| lit[tile(x, y)]);
    round.test(Tested::Probes, before, |x, y| !settled(x, y), &mut texels, &mut blockers)?;
    // With one set there is nothing more to test; its varying pixels are still filtered.
    let refined = if shared.everywhere { filter::covered(&surfaces) } else { filter::refined(&surfaces, &texels, lit.as_deref()) };
    // The lit tiles the filter reads get their probes' sums after all (it weighs a pixel's
    // neighbours by them): the sums of tests that are all lit, with no map to read. The rest
    // keep none, which the visibility writes as lit too.
    if let Some(lit) = &lit {
        let read = filter::read_tiles(&refined, width, height);
        let late: Vec<bool> = lit.iter().zip(&read).map(|(&lit, &read)| lit && read).collect();
        if late.contains(&true) {
            round.test(Tested::ProbesUnmapped, before, |x, y| late[tile(x, y)], &mut texels, &mut blockers)?;
        }
    }
    let written = band.written();
    if other_count > 0 {
        let pixels = written.start as usize * width as usize..written.end as usize * width as usize;
        round.done.pixels_refined += refined[pixels].iter().filter(|&&r| r).count();
    }
    // The other strata, where a penumbra is.
    if !round.ctx.supervisor.cancelled() && other_count > 0 && refined.contains(&true) {
        round.test(Tested::Others, before + probe_count, |x, y| refined[(y * width + x) as usize], &mut texels, &mut blockers)?;
    }
    let Round { ctx, done, maps, .. } = round;
    drop(maps);

    // The filter, and the visibility of the band's rows with its error estimate written to the frame.
    let filtering = std::time::Instant::now();
    let shape = &shared.filter;
    let inputs = FilterInputs {
        width,
        height,
        written,
        frame_height: ctx.height,
        light_extent: shape.light_extent,
        samples_across: shape.samples_across,
        scale: shape.scale,
        samples_effective: shape.samples_effective,
        camera: &ctx.spec.camera,
        depth_of: &|position| shared.constants.depth_of(position),
    };
    let filtered = filter::filter(&inputs, &surfaces, texels, &blockers, &refined);
    let row = width as usize;
    let mut penumbra = PenumbraMean::default();
    write_visibility_rows(ctx, band.rows.clone(), width, |rows, out| {
        filtered.write_visibility(rows.start as usize * row..rows.end as usize * row, row, out, &mut penumbra);
    });
    done.filter_ms += filtering.elapsed().as_secs_f64() * 1e3;
    done.pixels_filtered += filtered.pixels_filtered;
    done.penumbra.merge(penumbra);
    Ok(())
}

/// One band's rounds of tests, on the engine the frame runs on.
struct Round<'r, 'c, 'p> {
    ctx: &'r mut MethodContext<'c>,
    shared: &'r Shared,
    device: Option<&'r gpu::DeviceTests>,
    band: &'r Band,
    surfaces: &'r filter::Surfaces,
    progress: &'r mut Progress<'p>,
    done: &'r mut Done,
    maps: cpu::Maps,
}

impl Round<'_, '_, '_> {
    /// The tiles (`filter::TILE`², by rows of them) whose every covered pixel the probes all
    /// see lit (`cpu::lit_tiles`), from their maps' `maxima` and what drawing them took.
    fn lit_tiles(&mut self, (maxima, mut spent): (Vec<cpu::CellMaxima>, cpu::Spent)) -> Vec<bool> {
        let shared = self.shared;
        let testing = std::time::Instant::now();
        let lit = cpu::lit_tiles(self.surfaces, filter::TILE, &shared.probes, &maxima, &shared.constants, shared.channels);
        // The band's own tiles, not its halo's (a band's tiles are the frame's).
        let own = filter::Tiles::new(self.surfaces.width, self.surfaces.height).of_rows(self.band.written());
        self.done.tiles_found_lit += lit[own].iter().filter(|&&l| l).count();
        spent.tests_ms += testing.elapsed().as_secs_f64() * 1e3;
        self.done.spent.add(spent);
        lit
    }

    /// Tests the band's covered pixels (x, y) that `keep` keeps against the `tested` samples,
    /// both halves, the first of them the frame's `first`-th sample, and adds their sums and
    /// blockers to `texels` and `blockers`.
    fn test(
        &mut self,
        tested: Tested,
        first: u64,
        keep: impl Fn(u32, u32) -> bool + Sync,
        texels: &mut Texels,
        blockers: &mut [[f32; 2]],
    ) -> JobResult<()> {
        let (shared, surfaces, width) = (self.shared, self.surfaces, self.ctx.width);
        let constants = &shared.constants;
        let started = std::time::Instant::now();
        let Some(device) = self.device else {
            let (pixels, segments) = cpu::covered_pixels(surfaces, SEGMENT, keep);
            let halves = match tested {
                Tested::Probes => &shared.probe_samples,
                Tested::Others => &shared.other_samples,
                Tested::ProbesUnmapped => &shared.lit_probes,
            };
            let geometry = cpu::Geometry { positions: self.ctx.scene.positions(), indices: self.ctx.scene.indices(), runs: &shared.runs };
            let (channels, crop_size) = (shared.channels, shared.crop_size);
            // A half's maps held at once where they take fewer bytes than the frame-sized
            // receivers and sums would (the probes over a large frame): the same sums.
            let map_bytes = u64::from(crop_size.x) * u64::from(crop_size.y) * 4;
            let most = halves.iter().map(Vec::len).max().unwrap_or(0) as u64;
            let tiled = most * map_bytes < pixels.len() as u64 * cpu::receiver_bytes(channels);
            let (receivers, pixels) =
                if tiled { (None, pixels) } else { (Some(Receivers::of_list(surfaces, pixels, segments, constants)), Vec::new()) };
            self.done.read_ms += started.elapsed().as_secs_f64() * 1e3;
            let mut first = first;
            for (half, samples) in halves.iter().enumerate() {
                let progress = &mut *self.progress;
                let second_half = half == 1;
                let spent = match &receivers {
                    None => {
                        let spent = cpu::estimate_tiled(
                            surfaces,
                            &pixels,
                            samples,
                            constants,
                            geometry,
                            channels,
                            &mut self.maps,
                            |p, sums, met| gather(p, sums, met, second_half, texels, blockers),
                        );
                        progress.at(first + samples.len() as u64);
                        spent
                    }
                    Some(receivers) => {
                        let (sums, met, spent) =
                            cpu::estimate_with::<true>(receivers, samples, constants, geometry, channels, &mut self.maps, |n| {
                                progress.at(first + n as u64)
                            });
                        gather(receivers.pixels(), &sums, &met, second_half, texels, blockers);
                        spent
                    }
                };
                first += samples.len() as u64;
                self.done.spent.add(spent);
                if self.ctx.supervisor.cancelled() {
                    break;
                }
            }
            // The receivers' segments, once a round (as `reference` counts them once a frame).
            self.done.segments += segments;
            return Ok(());
        };
        // The row segments that hold a pixel to test, each by its first pixel in the frame.
        let band_start = self.band.reach.start * width;
        let kept = |x: u32, y: u32| keep(x, y) && surfaces.normal(x, y).is_some();
        let segments: Vec<u32> = (0..self.band.reach.len() as u32)
            .into_par_iter()
            .flat_map_iter(|y| {
                (0..width.div_ceil(SEGMENT))
                    .filter(move |s| (s * SEGMENT..((s + 1) * SEGMENT).min(width)).any(|x| kept(x, y)))
                    .map(move |s| band_start + y * width + s * SEGMENT)
            })
            .collect();
        self.done.read_ms += started.elapsed().as_secs_f64() * 1e3;
        let (floats, channels) = (device.record_floats(), shared.channels);
        let mut gather_ms = 0.0;
        device.test(self.ctx, tested, &segments, (first, self.progress), |records| {
            let gathering = std::time::Instant::now();
            // Each half's sums as `Texel::add` takes them (the gray one standing for all three).
            let sums = |at: &[f32]| {
                if channels == 1 {
                    ([at[0]; 3], [at[1]; 3])
                } else {
                    ([at[0], at[1], at[2]], [at[3], at[4], at[5]])
                }
            };
            for (s, &start) in segments.iter().enumerate() {
                for lane in 0..SEGMENT.min(width - start % width) {
                    let (x, y) = ((start - band_start + lane) % width, (start - band_start + lane) / width);
                    if !kept(x, y) {
                        continue;
                    }
                    let record = &records[(s * SEGMENT as usize + lane as usize) * floats..][..floats];
                    let pixel = (y * width + x) as usize;
                    for half in 0..2 {
                        let (shadowed, unshadowed) = sums(&record[2 * channels * half..]);
                        texels.add(pixel, shadowed, unshadowed, half == 1);
                    }
                    let (met, blocker) = (&record[4 * channels..], &mut blockers[pixel]);
                    *blocker = [blocker[0] + met[0], blocker[1] + met[1]];
                }
            }
            gather_ms = gathering.elapsed().as_secs_f64() * 1e3;
        })?;
        self.done.gather_ms += gather_ms;
        self.done.segments += segments.len() as u32;
        Ok(())
    }
}

/// Adds a round of tests of the receivers of `pixels` to the frame's pixels: per pixel its
/// sums (the gray one standing for all three under a gray light), to its second half's too
/// where `second_half`, and the count and summed depth of the blockers its tests met. On one
/// core: the first round touches the frame's texels first, and the kernel's faults of their
/// pages, most of its time, took longer from two threads at once (docs/performance-log.md).
fn gather(pixels: &[u32], sums: &Sums, met: &[BlockerBlock], second_half: bool, texels: &mut Texels, blockers: &mut [[f32; 2]]) {
    for (k, &pixel) in pixels.iter().enumerate() {
        let (block, lane) = (k / cpu::LANES, k % cpu::LANES);
        let (shadowed, unshadowed) = sums.lane(block, lane);
        texels.add(pixel as usize, shadowed, unshadowed, second_half);
        let blocker = &mut blockers[pixel as usize];
        *blocker = [blocker[0] + met[block].count[lane], blocker[1] + met[block].depth_sum[lane]];
    }
}

#[cfg(test)]
mod tests;
