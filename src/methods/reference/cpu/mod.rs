//! Engine `cpu` of method `reference`: the GPU engine's estimate — the same samples, the same
//! maps (frusta, crops, and Vulkan's rules for which texels a triangle covers and at what
//! depth) and the same test per receiver and sample (`accumulate.wgsl`) — computed by plain
//! code on the CPU's cores. On a software adapter the GPU *is* those cores, and this code
//! pays less than lavapipe does per triangle of a map and per test (the figures:
//! `docs/performance-log.md`). On a GPU the GPU engine is the fast one.
//!
//! The work goes in rounds of as many samples as there are threads: each thread draws one
//! sample's map, then each takes a share of the receivers and tests them against the round's
//! maps in sample order. Every receiver's sums are so added in the same order whatever the
//! number of threads, and the image is the same on every machine.

use std::ops::Range;

use glam::{Mat4, UVec2, Vec3};
use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
mod avx2;
mod raster;
mod settled;

use raster::Map;
pub(super) use settled::{cell_maxima, lit_tiles, CellMaxima};

use super::estimate::{PenumbraMean, Texel};
use crate::render::method::Surfaces;

/// Receivers a block: one AVX2 vector of f32 (and the unit the threads share the frame by).
pub(super) const LANES: usize = 8;

/// Blocks of receivers a thread takes at a time when the receivers are shared out.
const BLOCKS_PER_TASK: usize = 256;

/// Eight receivers, structure of arrays: what the test of `accumulate.wgsl` takes once per
/// pixel, in every sample's view coordinates (`Receiver` there). Only what the receiver is
/// (28 bytes a receiver): its depth's reciprocal, square and clamp, and the bias scaled by its
/// square, are taken again in each test (the same operations: the same bits), since streaming
/// them from memory cost more than computing them and they were most of the engine's
/// per-pixel bytes.
#[derive(Clone, Copy, Default)]
pub(super) struct ReceiverBlock {
    x: [f32; LANES],
    y: [f32; LANES],
    nx: [f32; LANES],
    ny: [f32; LANES],
    /// Depth along the light normal from the light's plane (0 for the padding past the last
    /// receiver: no weight, whatever its test says).
    depth: [f32; LANES],
    /// n·v's part along the normal, the same from every sample: `n.z · (−depth)`.
    n_dot_z: [f32; LANES],
    /// The test's bias in texels.
    bias: [f32; LANES],
}

/// Every block's sums per channel (one or three): a block's Σ L·G·V of each channel, then its
/// Σ L·G of each, `LANES` receivers a row. Sized by the channels: a gray light (one channel)
/// holds a third of a coloured one's bytes (16 a receiver for the two sums of two halves,
/// against 48).
#[derive(Clone)]
pub(super) struct Sums {
    channels: usize,
    rows: Vec<[f32; LANES]>,
}

impl Sums {
    /// `blocks` blocks' sums of `channels` channels (1 or 3), all 0.
    pub(super) fn new(blocks: usize, channels: usize) -> Self {
        assert!(channels == 1 || channels == 3, "{channels} channels");
        Self { channels, rows: vec![[0.0; LANES]; blocks * 2 * channels] }
    }

    /// Rows a block takes.
    fn stride(&self) -> usize {
        2 * self.channels
    }

    /// How many blocks.
    pub(super) fn blocks(&self) -> usize {
        self.rows.len() / self.stride()
    }

    /// Makes room for `blocks` blocks, the new ones 0.
    pub(super) fn resize(&mut self, blocks: usize) {
        let rows = blocks * self.stride();
        self.rows.resize(rows, [0.0; LANES]);
    }

    /// Block `block`'s lane `lane`, three channels (the first standing for all where there is
    /// one).
    #[inline]
    pub(super) fn lane(&self, block: usize, lane: usize) -> ([f32; 3], [f32; 3]) {
        if self.channels == 1 {
            let rows = &self.rows[2 * block..2 * block + 2];
            ([rows[0][lane]; 3], [rows[1][lane]; 3])
        } else {
            let rows = &self.rows[6 * block..6 * block + 6];
            ([rows[0][lane], rows[1][lane], rows[2][lane]], [rows[3][lane], rows[4][lane], rows[5][lane]])
        }
    }
}

/// The blockers eight receivers' tests met (method `filtered`, which sizes its filter by
/// them): how many tests were blocked, and the sum of the blockers' depths from the light's
/// plane.
#[derive(Clone, Copy, Default)]
pub(super) struct BlockerBlock {
    pub(super) count: [f32; LANES],
    pub(super) depth_sum: [f32; LANES],
}

/// What the frame's covered pixels are, for the test: built from the G-buffer as the
/// accumulate pass builds its `Receiver`.
pub(super) struct Receivers {
    blocks: Vec<ReceiverBlock>,
    /// The pixel of each receiver, in block order.
    pixels: Vec<u32>,
    /// Row segments of `SEGMENT` pixels that hold one (the GPU engine's `segments_tested`).
    pub segments: u32,
}

/// What every test of a frame shares (`Batch` in `accumulate.wgsl`).
pub(super) struct TestConstants {
    /// Rows of the rotation into the samples' view coordinates.
    pub rotation: Mat4,
    pub plane: f32,
    pub near: f32,
    pub resolution: u32,
    pub bias_texels: f32,
    pub slope_bias_texels: f32,
    pub light_center: Vec3,
}

impl TestConstants {
    /// A receiver's depth along the light normal from the light's plane (every sample's
    /// depth of it: they all lie on that plane).
    pub fn depth_of(&self, world: Vec3) -> f32 {
        self.plane - self.rotation.row(2).truncate().dot(world)
    }
}

/// The triangles a sample's map is drawn from: the scene's vertices, its indices (three a
/// triangle), and the runs of those that can shadow (`GpuScene::casting_runs`: the bounding
/// triangles the light lies beyond are left out, by both engines).
#[derive(Clone, Copy)]
pub(super) struct Geometry<'a> {
    pub positions: &'a [Vec3],
    pub indices: &'a [u32],
    pub runs: &'a [Range<u32>],
}

impl<'a> Geometry<'a> {
    /// The triangles of the runs, in order.
    pub(super) fn triangles(&self) -> impl Iterator<Item = &'a [u32]> + 'a {
        let indices = self.indices;
        self.runs.iter().flat_map(move |run| indices[run.start as usize..run.end as usize].chunks_exact(3))
    }
}

/// The maps a job's calls draw into, `size` texels each, kept from call to call: a map's
/// buffer (16 MB at 2,048²) is faulted in by the kernel once a job, not once a call (four calls
/// a band for `filtered`, two for `reference`).
pub(super) struct Maps {
    size: UVec2,
    maps: Vec<Map>,
}

impl Maps {
    /// None yet, of `size` texels.
    pub(super) fn new(size: UVec2) -> Self {
        Self { size, maps: Vec::new() }
    }

    /// The first `count`, made where there are fewer.
    fn first(&mut self, count: usize) -> &mut [Map] {
        while self.maps.len() < count {
            self.maps.push(Map::new(self.size));
        }
        &mut self.maps[..count]
    }
}

/// One sample as its map is drawn and read.
#[derive(Clone)]
pub(super) struct CpuSample {
    /// Its crop's projection (`MapCrop::layer_view_proj`).
    pub view_proj: Mat4,
    /// The sample point in view coordinates (x, y; its z is the plane's).
    pub origin: [f32; 2],
    /// Texels per unit of tan from the map's centre.
    pub texels_per_tan: f32,
    /// Where its crop begins in the whole map; `None` where no receiver falls in its map (an
    /// empty map: every test lit).
    pub crop_origin: Option<UVec2>,
    pub weight: Vec3,
}

impl Receivers {
    /// The covered pixels of the frame's surfaces, `segment` pixels a listed segment.
    pub fn new(surfaces: &Surfaces, segment: u32, c: &TestConstants) -> Self {
        let (pixels, segments) = covered_pixels(surfaces, segment, |_, _| true);
        Self::of_list(surfaces, pixels, segments, c)
    }

    /// The receivers of `pixels` (covered pixels, in row order; `covered_pixels`), which lie
    /// in `segments` row segments.
    pub fn of_list(surfaces: &Surfaces, pixels: Vec<u32>, segments: u32, c: &TestConstants) -> Self {
        let rotation = rotation_rows(c);
        let mut blocks = vec![ReceiverBlock::default(); pixels.len().div_ceil(LANES)];
        blocks
            .par_iter_mut()
            .zip(pixels.par_chunks(LANES))
            .for_each(|(b, block_pixels)| *b = receiver_block(surfaces, block_pixels, c, &rotation));
        Self { blocks, pixels, segments }
    }

    /// How many blocks of `LANES` receivers there are (the length of their sums).
    pub(super) fn blocks(&self) -> usize {
        self.blocks.len()
    }

    /// The pixel (index into the frame's rows) of each receiver, in block order.
    pub(super) fn pixels(&self) -> &[u32] {
        &self.pixels
    }
}

/// The covered pixels (x, y) of `surfaces` that `keep` keeps, as indices in row order, and
/// how many row segments of `segment` pixels hold one (the GPU engine's `segments_tested`).
/// Row by row on every core.
pub(super) fn covered_pixels(surfaces: &Surfaces, segment: u32, keep: impl Fn(u32, u32) -> bool + Sync) -> (Vec<u32>, u32) {
    let (width, height) = (surfaces.width, surfaces.height);
    let rows: Vec<(Vec<u32>, u32)> = (0..height)
        .into_par_iter()
        .map(|y| {
            let covered: Vec<u32> = (0..width).filter(|&x| keep(x, y) && surfaces.normal(x, y).is_some()).collect();
            let mut segments = 0;
            let mut last = u32::MAX;
            for &x in &covered {
                if x / segment != last {
                    segments += 1;
                    last = x / segment;
                }
            }
            (covered.into_iter().map(|x| y * width + x).collect(), segments)
        })
        .collect();
    let segments = rows.iter().map(|(_, count)| count).sum();
    (rows.into_iter().flat_map(|(pixels, _)| pixels).collect(), segments)
}

/// The rows of the rotation into the samples' view coordinates.
fn rotation_rows(c: &TestConstants) -> [Vec3; 3] {
    [0, 1, 2].map(|i| c.rotation.row(i).truncate())
}

/// The block of the receivers of `pixels` (at most `LANES`, indices into the rows of
/// `surfaces`) as the accumulate pass builds its `Receiver`; the padding lanes keep depth 0:
/// no weight, whatever their test says.
fn receiver_block(surfaces: &Surfaces, pixels: &[u32], c: &TestConstants, rotation: &[Vec3; 3]) -> ReceiverBlock {
    let mut b = ReceiverBlock::default();
    for (l, &pixel) in pixels.iter().enumerate() {
        let (px, py) = (pixel % surfaces.width, pixel / surfaces.width);
        let (world, normal) = (surfaces.position(px, py), surfaces.normal(px, py).unwrap_or_default());
        let n = Vec3::new(rotation[0].dot(normal), rotation[1].dot(normal), rotation[2].dot(normal));
        // The bias in texels, constant plus slope-scaled by tanθ to the light's centre.
        let cos_c = normal.dot((c.light_center - world).normalize()).clamp(0.0, 1.0);
        let tan_c = ((1.0 - cos_c * cos_c).sqrt() / cos_c.max(0.05)).min(10.0);
        let bias = c.bias_texels + c.slope_bias_texels * tan_c;
        let depth = c.depth_of(world);
        b.x[l] = rotation[0].dot(world);
        b.y[l] = rotation[1].dot(world);
        b.nx[l] = n.x;
        b.ny[l] = n.y;
        b.depth[l] = depth;
        b.n_dot_z[l] = -n.z * depth;
        b.bias[l] = bias;
    }
    b
}

/// Wall time of the two kinds of work, summed over the rounds (ms), and the maps a round drew
/// at once (the threads that drew them).
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Spent {
    pub maps_ms: f64,
    pub tests_ms: f64,
    pub round: usize,
}

impl Spent {
    /// Adds a later call's times (its round is the same machine's).
    pub(super) fn add(&mut self, later: Spent) {
        self.maps_ms += later.maps_ms;
        self.tests_ms += later.tests_ms;
        self.round = later.round;
    }
}

/// Estimates every receiver's sums over `samples` (their maps drawn from `geometry` into
/// `maps`), `channels` of them (1: every weight gray, the red one stands for all), and with
/// `BLOCKERS` the blockers its tests met (else none are kept). `after` hears how many samples
/// are done after each round and says whether to go on.
pub(super) fn estimate_with<const BLOCKERS: bool>(
    receivers: &Receivers,
    samples: &[CpuSample],
    constants: &TestConstants,
    geometry: Geometry<'_>,
    channels: usize,
    maps: &mut Maps,
    after: impl FnMut(usize) -> bool,
) -> (Sums, Vec<BlockerBlock>, Spent) {
    let mut sums = Sums::new(receivers.blocks.len(), channels);
    let (blockers, spent) = estimate_into::<BLOCKERS>(receivers, samples, constants, geometry, maps, &mut sums, after);
    (sums, blockers, spent)
}

/// `estimate_with`, adding to `sums` (one block per block of `receivers`, of its channels):
/// the sums of samples tested before, which the new ones follow in order — as if they had all
/// been tested in one call (a progressive job's rounds).
pub(super) fn estimate_into<const BLOCKERS: bool>(
    receivers: &Receivers,
    samples: &[CpuSample],
    constants: &TestConstants,
    geometry: Geometry<'_>,
    maps: &mut Maps,
    sums: &mut Sums,
    mut after: impl FnMut(usize) -> bool,
) -> (Vec<BlockerBlock>, Spent) {
    debug_assert_eq!(sums.blocks(), receivers.blocks.len());
    let (channels, stride) = (sums.channels, sums.stride());
    let mut blockers = vec![BlockerBlock::default(); if BLOCKERS { receivers.blocks.len() } else { 0 }];
    let mut spent = Spent::default();
    let threads = rayon::current_num_threads().max(1);
    // One map per thread in flight, within the GPU engine's budget for a batch's maps.
    let map_bytes = maps.size.x as usize * maps.size.y as usize * 4;
    let round = threads.min((super::BATCH_MAP_BYTES as usize / map_bytes.max(1)).max(1));
    spent.round = round;
    let maps = maps.first(round);
    let avx2 = has_avx2();
    let mut done = 0;
    for chunk in samples.chunks(round) {
        let start = std::time::Instant::now();
        maps.par_iter_mut().zip(chunk).for_each(|(map, sample)| map.draw(sample, geometry));
        let drawn = std::time::Instant::now();
        let maps = &maps[..chunk.len()];
        // Each task's share of the blockers: empty without `BLOCKERS`.
        let tasks = receivers.blocks.len().div_ceil(BLOCKS_PER_TASK);
        let mut shares: Vec<&mut [BlockerBlock]> = if BLOCKERS {
            blockers.chunks_mut(BLOCKS_PER_TASK).collect()
        } else {
            std::iter::repeat_with(|| &mut [][..]).take(tasks).collect()
        };
        let work = sums.rows.par_chunks_mut(BLOCKS_PER_TASK * stride).zip(receivers.blocks.par_chunks(BLOCKS_PER_TASK));
        work.zip(shares.par_iter_mut()).for_each(|((sums, blocks), share)| {
            for (map, sample) in maps.iter().zip(chunk) {
                test_blocks::<BLOCKERS>(blocks, sums, share, map, sample, constants, channels, avx2);
            }
        });
        spent.maps_ms += (drawn - start).as_secs_f64() * 1e3;
        spent.tests_ms += drawn.elapsed().as_secs_f64() * 1e3;
        done += chunk.len();
        if !after(done) {
            break;
        }
    }
    (blockers, spent)
}

/// What `estimate_with` holds a receiver for the whole frame, in bytes, beyond its pixel's
/// index: its block's share (`ReceiverBlock`), a call's sums of `channels` channels and the
/// blockers it met.
pub(super) fn receiver_bytes(channels: usize) -> u64 {
    (std::mem::size_of::<ReceiverBlock>() / LANES + 8 * channels + std::mem::size_of::<BlockerBlock>() / LANES) as u64
}

/// `estimate_with::<true>` over the receivers of `pixels` (`covered_pixels` of `surfaces`)
/// with none of its frame-sized parts: every map of `samples` is drawn first and held, then
/// each task makes its `BLOCKS_PER_TASK` blocks of receivers, tests them against every map in
/// order and hands their pixels, sums and blockers met to `gather`, a few tasks' worth at a
/// time. The same sums and blockers to the bit (each receiver's samples are added in the same
/// order, its block the same), for the bytes of the maps instead of `receiver_bytes` a
/// receiver: method `filtered`'s few probes over a whole frame hold less so.
#[allow(clippy::too_many_arguments)]
pub(super) fn estimate_tiled(
    surfaces: &Surfaces,
    pixels: &[u32],
    samples: &[CpuSample],
    constants: &TestConstants,
    geometry: Geometry<'_>,
    channels: usize,
    maps: &mut Maps,
    mut gather: impl FnMut(&[u32], &Sums, &[BlockerBlock]),
) -> Spent {
    let started = std::time::Instant::now();
    let maps = maps.first(samples.len());
    maps.par_iter_mut().zip(samples).for_each(|(map, sample)| map.draw(sample, geometry));
    let threads = rayon::current_num_threads().max(1);
    let mut spent = Spent { maps_ms: started.elapsed().as_secs_f64() * 1e3, tests_ms: 0.0, round: threads.min(samples.len()) };
    let (rotation, avx2) = (rotation_rows(constants), has_avx2());
    let task = BLOCKS_PER_TASK * LANES;
    // A few tasks a thread at a time: their sums are gathered before the next ones are made.
    for wave in pixels.chunks(task * 8 * threads) {
        let testing = std::time::Instant::now();
        let results: Vec<(Sums, Vec<BlockerBlock>)> = wave
            .par_chunks(task)
            .map(|task_pixels| {
                let blocks: Vec<ReceiverBlock> =
                    task_pixels.chunks(LANES).map(|block| receiver_block(surfaces, block, constants, &rotation)).collect();
                let mut sums = Sums::new(blocks.len(), channels);
                let mut met = vec![BlockerBlock::default(); blocks.len()];
                for (map, sample) in maps.iter().zip(samples) {
                    test_blocks::<true>(&blocks, &mut sums.rows, &mut met, map, sample, constants, channels, avx2);
                }
                (sums, met)
            })
            .collect();
        spent.tests_ms += testing.elapsed().as_secs_f64() * 1e3;
        for (task_pixels, (sums, met)) in wave.chunks(task).zip(&results) {
            gather(task_pixels, sums, met);
        }
    }
    spent
}

/// Writes every pixel's visibility into `out`, a `vec4<f32>` of bytes each (rgb; w the error
/// estimate), rows of `width` pixels: the ratio of its receiver's sums per channel, both halves
/// together (`ratio` in `accumulate.wgsl`), and half the halves' difference (`Texel::error`);
/// 1 (and 0) where no receiver is; `out` holds the rows from `first_row` on. Row by row on
/// every core. Returns the estimate's mean over the penumbra, `samples` the samples' effective
/// count.
pub(super) fn write_visibility(
    receivers: &Receivers,
    halves: [&Sums; 2],
    samples: f32,
    (width, first_row): (u32, u32),
    out: &mut [u8],
) -> PenumbraMean {
    let texel = |k: usize| {
        let (b, l) = (k / LANES, k % LANES);
        let mut texel = Texel::UNCOVERED;
        for (half, sums) in halves.iter().enumerate() {
            let (shadowed, unshadowed) = sums.lane(b, l);
            texel.add(shadowed, unshadowed, half == 1);
        }
        texel
    };
    let row_bytes = width as usize * 16;
    out.par_chunks_mut(row_bytes)
        .enumerate()
        .map(|(y, row)| {
            let y = first_row + y as u32;
            for texel in row.chunks_exact_mut(16) {
                texel.copy_from_slice(bytemuck::bytes_of(&[1.0f32, 1.0, 1.0, 0.0]));
            }
            // The receivers are listed row by row: this row's lie between these two.
            let first = receivers.pixels.partition_point(|&p| p < y * width);
            let end = receivers.pixels.partition_point(|&p| p < (y + 1) * width);
            let mut penumbra = PenumbraMean::default();
            for k in first..end {
                let x = (receivers.pixels[k] % width) as usize;
                let t = texel(k);
                let [r, g, b] = t.visibility();
                let error = t.error();
                row[16 * x..16 * x + 16].copy_from_slice(bytemuck::bytes_of(&[r, g, b, error]));
                penumbra.add(&t, error, samples);
            }
            penumbra
        })
        .collect::<Vec<_>>()
        // Summed in row order: the same mean on every machine.
        .into_iter()
        .fold(PenumbraMean::default(), |mut all, row| {
            all.merge(row);
            all
        })
}

/// Tests `blocks` against one sample's map and adds to their sums (`add_sample` in
/// `accumulate.wgsl`): `sums` holds `2 · channels` rows a block (`Sums`).
/// With `BLOCKERS`, `blockers` (one per block; empty without) hears the blockers met.
#[allow(clippy::too_many_arguments)]
fn test_blocks<const BLOCKERS: bool>(
    blocks: &[ReceiverBlock],
    sums: &mut [[f32; LANES]],
    blockers: &mut [BlockerBlock],
    map: &Map,
    sample: &CpuSample,
    c: &TestConstants,
    channels: usize,
    avx2: bool,
) {
    let test = SampleTest::new(map, sample, c);
    let mut spare = BlockerBlock::default();
    for (k, (block, sum)) in blocks.iter().zip(sums.chunks_exact_mut(2 * channels)).enumerate() {
        let met = if BLOCKERS { &mut blockers[k] } else { &mut spare };
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // Safety: `has_avx2` found AVX2 and FMA on this CPU.
            unsafe { avx2::add_sample::<BLOCKERS>(block, sum, met, &test, channels) };
            continue;
        }
        let _ = avx2;
        scalar_add_sample::<BLOCKERS>(block, sum, met, &test, channels);
    }
}

/// What one sample's tests read, taken once per sample and map.
struct SampleTest<'a> {
    depths: &'a [f32],
    /// Texels a row of the map.
    width: u32,
    /// The map's last texel (x, y), to clamp to.
    last: [f32; 2],
    origin: [f32; 2],
    k: f32,
    half: f32,
    crop: [f32; 2],
    near_k: f32,
    weight: [f32; 3],
    /// The map is empty: every test is lit.
    empty: bool,
}

impl<'a> SampleTest<'a> {
    fn new(map: &'a Map, sample: &CpuSample, c: &TestConstants) -> Self {
        let crop = sample.crop_origin.unwrap_or(UVec2::ZERO).as_vec2();
        Self {
            depths: &map.depths,
            width: map.size.x,
            last: [map.size.x as f32 - 1.0, map.size.y as f32 - 1.0],
            origin: sample.origin,
            k: sample.texels_per_tan,
            half: 0.5 * c.resolution as f32,
            crop: crop.to_array(),
            near_k: c.near * sample.texels_per_tan,
            weight: sample.weight.to_array(),
            empty: map.empty,
        }
    }
}

/// The test of eight receivers against one sample, one lane at a time: the reference for the
/// AVX2 path (the same operations in the same order, fused where it fuses them: the same
/// bits) and the path on CPUs without it.
// A lane indexes every array of the block and its sums alike.
#[allow(clippy::needless_range_loop)]
fn scalar_add_sample<const BLOCKERS: bool>(
    b: &ReceiverBlock,
    sums: &mut [[f32; LANES]],
    blockers: &mut BlockerBlock,
    t: &SampleTest<'_>,
    channels: usize,
) {
    for l in 0..LANES {
        let depth = b.depth[l];
        let depth2 = depth * depth;
        let dx = b.x[l] - t.origin[0];
        let dy = b.y[l] - t.origin[1];
        let inv_dist = 1.0 / dx.mul_add(dx, dy.mul_add(dy, depth2)).sqrt();
        let inv_dist2 = inv_dist * inv_dist;
        // `cosθy·|v|`: 0 behind the light's plane and for the padding.
        let g_depth = depth.max(0.0);
        let g = (-b.nx[l].mul_add(dx, b.ny[l].mul_add(dy, b.n_dot_z[l]))).max(0.0) * g_depth * inv_dist2 * inv_dist2;
        let ki = t.k * (1.0 / depth);
        let (fx, fy) = (dx * ki, dy * ki);
        let visible = t.empty || {
            let tx = (t.half + fx - t.crop[0]).clamp(0.0, t.last[0]);
            let ty = (t.half - fy - t.crop[1]).clamp(0.0, t.last[1]);
            let stored = t.depths[ty as usize * t.width as usize + tx as usize];
            let inside = fx.abs() < t.half && fy.abs() < t.half;
            let lit = (-(depth2 * b.bias[l])).mul_add(inv_dist, depth * t.k) * stored <= t.near_k;
            if BLOCKERS && inside && !lit && g > 0.0 {
                let depth = (t.near_k / t.k) / stored;
                blockers.count[l] += 1.0;
                blockers.depth_sum[l] += depth;
            }
            !inside || lit
        };
        for c in 0..channels {
            let lit = if visible { g } else { 0.0 };
            sums[c][l] = t.weight[c].mul_add(lit, sums[c][l]);
            sums[channels + c][l] = t.weight[c].mul_add(g, sums[channels + c][l]);
        }
    }
}

fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests;
