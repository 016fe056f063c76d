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

use glam::{Mat4, UVec2, Vec3, Vec4};
use rayon::prelude::*;

use crate::render::method::GBufferView;

/// Receivers a block: one AVX2 vector of f32 (and the unit the threads share the frame by).
const LANES: usize = 8;

/// Blocks of receivers a thread takes at a time when the receivers are shared out.
const BLOCKS_PER_TASK: usize = 256;

/// Fixed-point steps per texel of a map's vertex coordinates: llvmpipe's 8 bits of sub-texel
/// precision (`FIXED_ORDER`), so that a vertex lands where lavapipe puts it and a texel centre
/// on a shared edge goes to the triangle Vulkan's top-left rule gives it.
const SUBTEXEL: f32 = 256.0;

/// Coordinates (texels) within which a triangle is rasterised in exact fixed point: products of
/// two such coordinates in sub-texel steps stay far inside an `i64`. Beyond it (a vertex just
/// past the near plane of a wide frustum) the edges are evaluated in `f64` instead.
const FIXED_RANGE: f32 = (1 << 20) as f32;

/// Rows of a triangle at least this many texels wide find where they are covered by solving
/// each edge for x (three divisions) instead of testing every texel: the same texels, fewer
/// steps on the large triangles of a simple scene.
const SPAN_FROM: i64 = 8;

/// Eight receivers, structure of arrays: what the test of `accumulate.wgsl` takes once per
/// pixel, in every sample's view coordinates (`Receiver` there).
#[derive(Clone, Copy, Default)]
pub(super) struct ReceiverBlock {
    x: [f32; LANES],
    y: [f32; LANES],
    nx: [f32; LANES],
    ny: [f32; LANES],
    /// Depth along the light normal from the light's plane, its reciprocal and its square.
    depth: [f32; LANES],
    inv_depth: [f32; LANES],
    depth2: [f32; LANES],
    /// n·v's part along the normal, the same from every sample: `n.z · (−depth)`.
    n_dot_z: [f32; LANES],
    /// `cosθy·|v|`, 0 behind the light's plane (and for the padding past the last receiver).
    g_depth: [f32; LANES],
    /// depth² × the test's bias in texels.
    bias_depth2: [f32; LANES],
}

/// A block's sums per channel (one or three): Σ L·G·V, then Σ L·G.
#[derive(Clone, Copy, Default)]
pub(super) struct SumBlock {
    shadowed: [[f32; LANES]; 3],
    unshadowed: [[f32; LANES]; 3],
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

/// One sample as its map is drawn and read.
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
    /// The covered pixels of the frame's G-buffer, `segment` pixels a listed segment.
    pub fn new(gbuffer: &GBufferView<'_>, segment: u32, c: &TestConstants) -> Self {
        // Row by row on every core: the covered pixels, and the segments that hold one.
        let rows: Vec<(Vec<u32>, u32)> = (0..gbuffer.height)
            .into_par_iter()
            .map(|y| {
                let covered: Vec<u32> = (0..gbuffer.width).filter(|&x| gbuffer.normal(x, y).is_some()).collect();
                let mut segments = 0;
                let mut last = u32::MAX;
                for &x in &covered {
                    if x / segment != last {
                        segments += 1;
                        last = x / segment;
                    }
                }
                (covered.into_iter().map(|x| y * gbuffer.width + x).collect(), segments)
            })
            .collect();
        let segments = rows.iter().map(|(_, count)| count).sum();
        let pixels: Vec<u32> = rows.into_iter().flat_map(|(pixels, _)| pixels).collect();
        let width = gbuffer.width;
        let rotation = [0, 1, 2].map(|i| c.rotation.row(i).truncate());
        let mut blocks = vec![ReceiverBlock::default(); pixels.len().div_ceil(LANES)];
        blocks.par_iter_mut().zip(pixels.par_chunks(LANES)).for_each(|(b, block_pixels)| {
            for (l, &pixel) in block_pixels.iter().enumerate() {
                let (px, py) = (pixel % width, pixel / width);
                let (world, normal) = (gbuffer.position(px, py), gbuffer.normal(px, py).unwrap_or_default());
                let x = Vec3::new(rotation[0].dot(world), rotation[1].dot(world), rotation[2].dot(world));
                let n = Vec3::new(rotation[0].dot(normal), rotation[1].dot(normal), rotation[2].dot(normal));
                // The bias in texels, constant plus slope-scaled by tanθ to the light's centre.
                let cos_c = normal.dot((c.light_center - world).normalize()).clamp(0.0, 1.0);
                let tan_c = ((1.0 - cos_c * cos_c).sqrt() / cos_c.max(0.05)).min(10.0);
                let bias = c.bias_texels + c.slope_bias_texels * tan_c;
                let depth = c.plane - x.z;
                b.x[l] = x.x;
                b.y[l] = x.y;
                b.nx[l] = n.x;
                b.ny[l] = n.y;
                b.depth[l] = depth;
                b.inv_depth[l] = 1.0 / depth;
                b.depth2[l] = depth * depth;
                b.n_dot_z[l] = -n.z * depth;
                b.g_depth[l] = depth.max(0.0);
                b.bias_depth2[l] = depth * depth * bias;
            }
        });
        // The padding lanes keep depth 0: no weight (g_depth 0), whatever their test says.
        Self { blocks, pixels, segments }
    }
}

/// A sample's map, drawn: `size` texels, near / view depth of the nearest surface, 0 where
/// nothing was drawn.
struct Map {
    size: UVec2,
    depths: Vec<f32>,
    /// Nothing drawn (no receiver falls in this sample's map): every test lit.
    empty: bool,
}

/// Wall time of the two kinds of work, summed over the rounds (ms), and the maps a round drew
/// at once (the threads that drew them).
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Spent {
    pub maps_ms: f64,
    pub tests_ms: f64,
    pub round: usize,
}

/// Estimates every receiver's sums over `samples` (drawn from the triangles `positions` /
/// `indices`), `channels` of them (1: every weight gray, the red one stands for all). `after`
/// hears how many samples are done after each round and says whether to go on.
pub(super) fn estimate(
    receivers: &Receivers,
    samples: &[CpuSample],
    constants: &TestConstants,
    (positions, indices): (&[Vec3], &[u32]),
    channels: usize,
    crop_size: UVec2,
    mut after: impl FnMut(usize) -> bool,
) -> (Vec<SumBlock>, Spent) {
    let mut sums = vec![SumBlock::default(); receivers.blocks.len()];
    let mut spent = Spent::default();
    let threads = rayon::current_num_threads().max(1);
    // One map per thread in flight, within the GPU engine's budget for a batch's maps.
    let map_bytes = crop_size.x as usize * crop_size.y as usize * 4;
    let round = threads.min((super::BATCH_MAP_BYTES as usize / map_bytes.max(1)).max(1));
    spent.round = round;
    let mut maps: Vec<Map> = (0..round).map(|_| Map { size: crop_size, depths: Vec::new(), empty: true }).collect();
    let avx2 = has_avx2();
    let mut done = 0;
    for chunk in samples.chunks(round) {
        let start = std::time::Instant::now();
        maps.par_iter_mut().zip(chunk).for_each(|(map, sample)| map.draw(sample, positions, indices));
        let drawn = std::time::Instant::now();
        let maps = &maps[..chunk.len()];
        sums.par_chunks_mut(BLOCKS_PER_TASK).zip(receivers.blocks.par_chunks(BLOCKS_PER_TASK)).for_each(|(sums, blocks)| {
            for (map, sample) in maps.iter().zip(chunk) {
                test_blocks(blocks, sums, map, sample, constants, channels, avx2);
            }
        });
        spent.maps_ms += (drawn - start).as_secs_f64() * 1e3;
        spent.tests_ms += drawn.elapsed().as_secs_f64() * 1e3;
        done += chunk.len();
        if !after(done) {
            break;
        }
    }
    (sums, spent)
}

/// Writes every pixel's visibility into `out`, a `vec4<f32>` of bytes each (rgb; w 1), rows of
/// `width` pixels: the ratio of its receiver's sums per channel (`ratio` in
/// `accumulate.wgsl`), 1 where no receiver is. Row by row on every core.
pub(super) fn write_visibility(receivers: &Receivers, sums: &[SumBlock], channels: usize, width: u32, out: &mut [u8]) {
    let channel = |c: usize| if channels == 1 { 0 } else { c };
    let ratio = |k: usize| {
        let (b, l) = (&sums[k / LANES], k % LANES);
        let shadowed = Vec3::from_array([0, 1, 2].map(|c| b.shadowed[channel(c)][l]));
        let unshadowed = Vec3::from_array([0, 1, 2].map(|c| b.unshadowed[channel(c)][l]));
        let total = unshadowed.element_sum();
        let gray = if total > 0.0 { shadowed.element_sum() / total } else { 1.0 };
        let v = Vec3::from_array([0, 1, 2].map(|c| if unshadowed[c] > 0.0 { shadowed[c] / unshadowed[c] } else { gray }));
        v.clamp(Vec3::ZERO, Vec3::ONE).extend(1.0).to_array()
    };
    let row_bytes = width as usize * 16;
    out.par_chunks_mut(row_bytes).enumerate().for_each(|(y, row)| {
        for texel in row.chunks_exact_mut(16) {
            texel.copy_from_slice(bytemuck::bytes_of(&[1.0f32; 4]));
        }
        // The receivers are listed row by row: this row's lie between these two.
        let first = receivers.pixels.partition_point(|&p| p < y as u32 * width);
        let end = receivers.pixels.partition_point(|&p| p < (y as u32 + 1) * width);
        for k in first..end {
            let x = (receivers.pixels[k] % width) as usize;
            row[16 * x..16 * x + 16].copy_from_slice(bytemuck::bytes_of(&ratio(k)));
        }
    });
}

impl Map {
    /// Draws `sample`'s map: every triangle, as lavapipe draws `sample_depth.wgsl` with depth
    /// test `Greater` into a map cleared to 0.
    fn draw(&mut self, sample: &CpuSample, positions: &[Vec3], indices: &[u32]) {
        self.empty = sample.crop_origin.is_none();
        if self.empty {
            return;
        }
        let texels = self.size.x as usize * self.size.y as usize;
        self.depths.clear();
        self.depths.resize(texels, 0.0);
        let clip: Vec<Vec4> = positions.iter().map(|p| sample.view_proj * p.extend(1.0)).collect();
        // Every map's projection is reversed-Z with the far plane at infinity: clip z is the
        // near plane and w the view depth, so Vulkan's clip volume 0 ≤ z ≤ w leaves only the
        // near plane to clip against (w ≥ z); x and y are clipped by the map's bounds below.
        for triangle in indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|i| clip[triangle[i] as usize]);
            let inside = [a, b, c].map(|v| v.w >= v.z);
            if inside.iter().all(|&i| i) {
                self.triangle([a, b, c]);
            } else if inside.iter().any(|&i| i) {
                let polygon = clip_near([a, b, c]);
                for k in 1..polygon.len().saturating_sub(1) {
                    self.triangle([polygon[0], polygon[k], polygon[k + 1]]);
                }
            }
        }
    }

    /// Rasterises one triangle in clip coordinates (every vertex in front of the near plane).
    fn triangle(&mut self, vertices: [Vec4; 3]) {
        let (w, h) = (self.size.x as f32, self.size.y as f32);
        // Viewport transform: x right and y down from the top-left corner, in texels; depth
        // z / w, as the rasteriser interpolates it (affine across the screen).
        let screen = vertices.map(|v| {
            let inv = 1.0 / v.w;
            Vec3::new((v.x * inv + 1.0) * 0.5 * w, (1.0 - v.y * inv) * 0.5 * h, v.z * inv)
        });
        let fits = screen.iter().all(|s| s.x.abs() < FIXED_RANGE && s.y.abs() < FIXED_RANGE);
        if fits {
            self.fixed(screen);
        } else {
            self.wide(screen);
        }
    }

    /// Vulkan's rules in exact fixed point: vertices snapped to 1/`SUBTEXEL`, a texel covered
    /// when its centre is inside every edge, or on an edge that is a top or a left one.
    fn fixed(&mut self, screen: [Vec3; 3]) {
        self.fixed_spans_from(screen, SPAN_FROM);
    }

    /// `fixed`, finding the covered span of rows at least `span_from` texels wide by solving
    /// the edges (`SPAN_FROM`) and testing every texel of narrower ones.
    fn fixed_spans_from(&mut self, screen: [Vec3; 3], span_from: i64) {
        let fixed = screen.map(|s| [(s.x * SUBTEXEL).round() as i64, (s.y * SUBTEXEL).round() as i64]);
        let area = cross(fixed[0], fixed[1], fixed[2]);
        if area == 0 {
            return;
        }
        // Both faces are drawn (contract §1: a back face casts a shadow too): order the
        // vertices so that the inside of every edge is where its function is positive.
        let order = if area > 0 { [0, 1, 2] } else { [0, 2, 1] };
        let [p0, p1, p2] = order.map(|i| fixed[i]);
        let sub = SUBTEXEL as i64;
        let (lo_x, hi_x) = (p0[0].min(p1[0]).min(p2[0]), p0[0].max(p1[0]).max(p2[0]));
        let (lo_y, hi_y) = (p0[1].min(p1[1]).min(p2[1]), p0[1].max(p1[1]).max(p2[1]));
        // Texels whose centre, (i + ½)·SUBTEXEL, lies within the bounds.
        let first = |lo: i64| (lo - sub / 2 + sub - 1).div_euclid(sub);
        let last = |hi: i64| (hi - sub / 2).div_euclid(sub);
        let x0 = first(lo_x).max(0);
        let x1 = last(hi_x).min(i64::from(self.size.x) - 1);
        let y0 = first(lo_y).max(0);
        let y1 = last(hi_y).min(i64::from(self.size.y) - 1);
        if x0 > x1 || y0 > y1 {
            return;
        }
        let edges = [edge(p1, p2), edge(p2, p0), edge(p0, p1)];
        let centre = |i: i64| i * sub + sub / 2;
        let at = |e: &Edge| e.a * centre(x0) + e.b * centre(y0) + e.c;
        let mut row = edges.each_ref().map(at);
        let depth = DepthPlane::new(order.map(|i| screen[i]));
        let width = self.size.x as usize;
        for y in y0..=y1 {
            let line = &mut self.depths[y as usize * width..][..width];
            let py = y as f32 + 0.5;
            if x1 - x0 >= span_from {
                let (mut from, mut to) = (x0, x1);
                for k in 0..3 {
                    let step = edges[k].a * sub;
                    match step.signum() {
                        // w + step·(x − x0) ≥ 0 from x0 + ⌈−w / step⌉ on.
                        1 => from = from.max(x0 + (-row[k] + step - 1).div_euclid(step)),
                        // … up to x0 + ⌊w / −step⌋.
                        -1 => to = to.min(x0 + row[k].div_euclid(-step)),
                        _ if row[k] < 0 => to = from - 1,
                        _ => {}
                    }
                }
                for x in from..=to {
                    let stored = &mut line[x as usize];
                    *stored = stored.max(depth.at(x as f32 + 0.5, py));
                }
            } else {
                let mut w = row;
                for x in x0..=x1 {
                    if (w[0] | w[1] | w[2]) >= 0 {
                        let stored = &mut line[x as usize];
                        *stored = stored.max(depth.at(x as f32 + 0.5, py));
                    }
                    for k in 0..3 {
                        w[k] += edges[k].a * sub;
                    }
                }
            }
            for k in 0..3 {
                row[k] += edges[k].b * sub;
            }
        }
    }

    /// A triangle too wide for the fixed-point path: its edges in `f64`, unsnapped, over the
    /// texels of the map it covers (a rare case: a vertex just past the near plane).
    fn wide(&mut self, screen: [Vec3; 3]) {
        let p = screen.map(|s| [f64::from(s.x), f64::from(s.y)]);
        let area = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let order = if area > 0.0 { [0, 1, 2] } else { [0, 2, 1] };
        let [p0, p1, p2] = order.map(|i| p[i]);
        let line = |a: [f64; 2], b: [f64; 2]| (a[1] - b[1], b[0] - a[0], a[0] * b[1] - b[0] * a[1]);
        let edges = [line(p1, p2), line(p2, p0), line(p0, p1)];
        let lo = [p0[0].min(p1[0]).min(p2[0]), p0[1].min(p1[1]).min(p2[1])];
        let hi = [p0[0].max(p1[0]).max(p2[0]), p0[1].max(p1[1]).max(p2[1])];
        let x0 = (lo[0] - 0.5).ceil().max(0.0) as i64;
        let y0 = (lo[1] - 0.5).ceil().max(0.0) as i64;
        let x1 = ((hi[0] - 0.5).floor() as i64).min(i64::from(self.size.x) - 1);
        let y1 = ((hi[1] - 0.5).floor() as i64).min(i64::from(self.size.y) - 1);
        let depth = DepthPlane::new(order.map(|i| screen[i]));
        let width = self.size.x as usize;
        for y in y0..=y1 {
            let py = y as f64 + 0.5;
            for x in x0..=x1 {
                let px = x as f64 + 0.5;
                let covered = edges.iter().all(|&(a, b, c)| {
                    let e = a * px + b * py + c;
                    e > 0.0 || (e == 0.0 && top_left(a, b))
                });
                if covered {
                    let stored = &mut self.depths[y as usize * width + x as usize];
                    *stored = stored.max(depth.at(px as f32, py as f32));
                }
            }
        }
    }
}

/// An edge function `a·x + b·y + c` in sub-texel units, positive inside; `c` holds Vulkan's
/// tie-break: a centre exactly on the edge is inside only for a top or a left edge.
struct Edge {
    a: i64,
    b: i64,
    c: i64,
}

/// The edge from `p` to `q` of a triangle whose inside lies to the left going round it (in
/// y-down coordinates: the vertices ordered with a positive `cross`).
fn edge(p: [i64; 2], q: [i64; 2]) -> Edge {
    let (a, b) = (p[1] - q[1], q[0] - p[0]);
    let c = p[0] * q[1] - q[0] * p[1];
    // Integer values: "≥ 0" admits a tie, "≥ 0 after − 1" does not.
    Edge { a, b, c: if top_left(a as f64, b as f64) { c } else { c - 1 } }
}

/// Whether an edge whose inside lies along (a, b) is a left edge (the inside to its right: a
/// > 0) or a top edge (horizontal, the inside below it in y-down coordinates: a = 0, b > 0).
fn top_left(a: f64, b: f64) -> bool {
    a > 0.0 || (a == 0.0 && b > 0.0)
}

/// Twice the signed area of triangle (p, q, r), positive when the edges run with the inside to
/// their left in y-down coordinates.
fn cross(p: [i64; 2], q: [i64; 2], r: [i64; 2]) -> i64 {
    (q[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (q[1] - p[1])
}

/// Depth across a triangle's screen: affine in x and y, from its first vertex.
struct DepthPlane {
    origin: Vec3,
    dx: f32,
    dy: f32,
}

impl DepthPlane {
    /// From the vertices: x, y in texels, z the depth.
    fn new([p0, p1, p2]: [Vec3; 3]) -> Self {
        let (e1, e2) = (p1 - p0, p2 - p0);
        let area = e1.x * e2.y - e2.x * e1.y;
        let dx = (e1.z * e2.y - e2.z * e1.y) / area;
        let dy = (e2.z * e1.x - e1.z * e2.x) / area;
        Self { origin: p0, dx, dy }
    }

    fn at(&self, x: f32, y: f32) -> f32 {
        self.origin.z + self.dx * (x - self.origin.x) + self.dy * (y - self.origin.y)
    }
}

/// The part of a triangle in front of the near plane (w ≥ z: every map's clip z is its near
/// plane), as a convex polygon of up to four vertices.
fn clip_near(vertices: [Vec4; 3]) -> Vec<Vec4> {
    let mut out = Vec::with_capacity(4);
    for k in 0..3 {
        let (p, q) = (vertices[k], vertices[(k + 1) % 3]);
        let (dp, dq) = (p.w - p.z, q.w - q.z);
        if dp >= 0.0 {
            out.push(p);
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            out.push(p + (q - p) * (dp / (dp - dq)));
        }
    }
    out
}

/// Tests `blocks` against one sample's map and adds to their sums (`add_sample` in
/// `accumulate.wgsl`).
fn test_blocks(
    blocks: &[ReceiverBlock],
    sums: &mut [SumBlock],
    map: &Map,
    sample: &CpuSample,
    c: &TestConstants,
    channels: usize,
    avx2: bool,
) {
    let test = SampleTest::new(map, sample, c);
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        for (block, sum) in blocks.iter().zip(sums) {
            // Safety: `has_avx2` found AVX2 and FMA on this CPU.
            unsafe { avx2::add_sample(block, sum, &test, channels) };
        }
        return;
    }
    let _ = avx2;
    for (block, sum) in blocks.iter().zip(sums) {
        scalar_add_sample(block, sum, &test, channels);
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
fn scalar_add_sample(b: &ReceiverBlock, sums: &mut SumBlock, t: &SampleTest<'_>, channels: usize) {
    for l in 0..LANES {
        let dx = b.x[l] - t.origin[0];
        let dy = b.y[l] - t.origin[1];
        let inv_dist = 1.0 / dx.mul_add(dx, dy.mul_add(dy, b.depth2[l])).sqrt();
        let inv_dist2 = inv_dist * inv_dist;
        let g = (-b.nx[l].mul_add(dx, b.ny[l].mul_add(dy, b.n_dot_z[l]))).max(0.0) * b.g_depth[l] * inv_dist2 * inv_dist2;
        let ki = t.k * b.inv_depth[l];
        let (fx, fy) = (dx * ki, dy * ki);
        let visible = t.empty || {
            let tx = (t.half + fx - t.crop[0]).clamp(0.0, t.last[0]);
            let ty = (t.half - fy - t.crop[1]).clamp(0.0, t.last[1]);
            let stored = t.depths[ty as usize * t.width as usize + tx as usize];
            let inside = fx.abs() < t.half && fy.abs() < t.half;
            !inside || (-b.bias_depth2[l]).mul_add(inv_dist, b.depth[l] * t.k) * stored <= t.near_k
        };
        for c in 0..channels {
            let lit = if visible { g } else { 0.0 };
            sums.shadowed[c][l] = t.weight[c].mul_add(lit, sums.shadowed[c][l]);
            sums.unshadowed[c][l] = t.weight[c].mul_add(g, sums.unshadowed[c][l]);
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

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{ReceiverBlock, SampleTest, SumBlock};
    use std::arch::x86_64::*;

    /// `scalar_add_sample` for the eight lanes at once (the texels by one gather).
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn add_sample(b: &ReceiverBlock, sums: &mut SumBlock, t: &SampleTest<'_>, channels: usize) {
        let load = |a: &[f32; 8]| unsafe { _mm256_loadu_ps(a.as_ptr()) };
        let dx = _mm256_sub_ps(load(&b.x), _mm256_set1_ps(t.origin[0]));
        let dy = _mm256_sub_ps(load(&b.y), _mm256_set1_ps(t.origin[1]));
        let dist2 = _mm256_fmadd_ps(dx, dx, _mm256_fmadd_ps(dy, dy, load(&b.depth2)));
        let inv_dist = _mm256_div_ps(_mm256_set1_ps(1.0), _mm256_sqrt_ps(dist2));
        let inv_dist2 = _mm256_mul_ps(inv_dist, inv_dist);
        let facing = _mm256_fmadd_ps(load(&b.nx), dx, _mm256_fmadd_ps(load(&b.ny), dy, load(&b.n_dot_z)));
        let cos = _mm256_max_ps(_mm256_sub_ps(_mm256_setzero_ps(), facing), _mm256_setzero_ps());
        let g = _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(cos, load(&b.g_depth)), inv_dist2), inv_dist2);
        let ki = _mm256_mul_ps(_mm256_set1_ps(t.k), load(&b.inv_depth));
        let (fx, fy) = (_mm256_mul_ps(dx, ki), _mm256_mul_ps(dy, ki));
        let visible = if t.empty {
            _mm256_castsi256_ps(_mm256_set1_epi32(-1))
        } else {
            let half = _mm256_set1_ps(t.half);
            let clamp = |v: __m256, hi: f32| _mm256_min_ps(_mm256_max_ps(v, _mm256_setzero_ps()), _mm256_set1_ps(hi));
            let tx = clamp(_mm256_sub_ps(_mm256_add_ps(half, fx), _mm256_set1_ps(t.crop[0])), t.last[0]);
            let ty = clamp(_mm256_sub_ps(_mm256_sub_ps(half, fy), _mm256_set1_ps(t.crop[1])), t.last[1]);
            let index =
                _mm256_add_epi32(_mm256_mullo_epi32(_mm256_cvttps_epi32(ty), _mm256_set1_epi32(t.width as i32)), _mm256_cvttps_epi32(tx));
            // Safety: every index is clamped into the map.
            let stored = unsafe { _mm256_i32gather_ps::<4>(t.depths.as_ptr(), index) };
            let magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
            let inside = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(fx, magnitude), half),
                _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(fy, magnitude), half),
            );
            let lhs = _mm256_mul_ps(
                _mm256_fmadd_ps(
                    _mm256_sub_ps(_mm256_setzero_ps(), load(&b.bias_depth2)),
                    inv_dist,
                    _mm256_mul_ps(load(&b.depth), _mm256_set1_ps(t.k)),
                ),
                stored,
            );
            let lit = _mm256_cmp_ps::<_CMP_LE_OQ>(lhs, _mm256_set1_ps(t.near_k));
            _mm256_or_ps(_mm256_andnot_ps(inside, _mm256_castsi256_ps(_mm256_set1_epi32(-1))), lit)
        };
        let lit = _mm256_and_ps(visible, g);
        for c in 0..channels {
            let w = _mm256_set1_ps(t.weight[c]);
            let (s, u) = (&mut sums.shadowed[c], &mut sums.unshadowed[c]);
            unsafe {
                _mm256_storeu_ps(s.as_mut_ptr(), _mm256_fmadd_ps(w, lit, _mm256_loadu_ps(s.as_ptr())));
                _mm256_storeu_ps(u.as_mut_ptr(), _mm256_fmadd_ps(w, g, _mm256_loadu_ps(u.as_ptr())));
            }
        }
    }
}

#[cfg(test)]
mod tests;
