//! The CPU engine's rasteriser: a sample's depth map drawn by Vulkan's rules (fixed-point
//! vertices, the top-left rule, depth interpolated as lavapipe does), so that it holds the
//! same texels and depths as the GPU engine's map.

use glam::{UVec2, Vec3, Vec4};

use super::settled::CellMaxima;
use super::{CpuSample, Geometry};

/// Fixed-point steps per texel of a map's vertex coordinates: llvmpipe's 8 bits of sub-texel
/// precision (`FIXED_ORDER`), so that a vertex lands where lavapipe puts it and a texel centre
/// on a shared edge goes to the triangle Vulkan's top-left rule gives it.
pub(super) const SUBTEXEL: f32 = 256.0;

/// Coordinates (texels) within which a triangle is rasterised in exact fixed point: products of
/// two such coordinates in sub-texel steps stay far inside an `i64`. Beyond it (a vertex just
/// past the near plane of a wide frustum) the edges are evaluated in `f64` instead.
pub(super) const FIXED_RANGE: f32 = (1 << 20) as f32;

/// Rows of a triangle at least this many texels wide find where they are covered by solving
/// each edge for x (three divisions) instead of testing every texel: the same texels, fewer
/// steps on the large triangles of a simple scene.
const SPAN_FROM: i64 = 8;

/// A sample's map, drawn: `size` texels, near / view depth of the nearest surface, 0 where
/// nothing was drawn.
pub(super) struct Map {
    pub(super) size: UVec2,
    pub(super) depths: Vec<f32>,
    /// Nothing drawn (no receiver falls in this sample's map): every test lit.
    pub(super) empty: bool,
    /// Per row, the texels `[first, last]` that the last drawing may have written (first >
    /// last: none), so that the next one clears those alone: without the floor
    /// (`scene::bounding`) most of a map is never written, and clearing all of it cost about
    /// half as much as drawing the figures on it (docs/performance-log.md).
    written: Vec<[u32; 2]>,
    /// Per vertex of the scene, its clip coordinates and where it lands on this map: taken once
    /// a map, not once for each of the (on a mesh, about six) triangles that share it.
    clip: Vec<Vec4>,
    projected: Vec<Projected>,
    /// The CPU has AVX2: a small triangle's rows eight texels at a time
    /// (`avx2::narrow_triangle`).
    avx2: bool,
}

/// A vertex in front of the near plane, on a map: texels (x right, y down) and depth, and
/// snapped to the rasteriser's fixed point where it fits (`FIXED_RANGE`).
#[derive(Clone, Copy)]
struct Projected {
    screen: Vec3,
    fixed: Option<[i64; 2]>,
}

/// A row no triangle wrote.
const UNWRITTEN: [u32; 2] = [u32::MAX, 0];

impl Map {
    /// A map of `size` texels, not drawn yet (empty).
    pub(super) fn new(size: UVec2) -> Self {
        let avx2 = super::has_avx2();
        Self { size, depths: Vec::new(), empty: true, written: Vec::new(), clip: Vec::new(), projected: Vec::new(), avx2 }
    }

    /// A map of `size` texels holding `depths`, every texel counted as written.
    #[cfg(test)]
    pub(super) fn with_depths(size: UVec2, depths: Vec<f32>) -> Self {
        let written = vec![[0, size.x - 1]; size.y as usize];
        Self { size, depths, empty: false, written, clip: Vec::new(), projected: Vec::new(), avx2: super::has_avx2() }
    }

    /// This map, drawing every triangle with the scalar code (to test the AVX2 path by).
    #[cfg(test)]
    pub(super) fn scalar(self) -> Self {
        Self { avx2: false, ..self }
    }

    /// Draws `sample`'s map: every triangle of `geometry`'s runs, as lavapipe draws
    /// `sample_depth.wgsl` with depth test `Greater` into a map cleared to 0.
    pub(super) fn draw(&mut self, sample: &CpuSample, geometry: Geometry<'_>) {
        self.empty = sample.crop_origin.is_none();
        if self.empty {
            return;
        }
        self.clear();
        let (mut clip, mut projected) = (std::mem::take(&mut self.clip), std::mem::take(&mut self.projected));
        clip.clear();
        clip.extend(geometry.positions.iter().map(|p| sample.view_proj * p.extend(1.0)));
        // A vertex behind the near plane is projected too, and never read.
        projected.clear();
        projected.extend(clip.iter().map(|&v| self.project(v)));
        // Every map's projection is reversed-Z with the far plane at infinity: clip z is the
        // near plane and w the view depth, so Vulkan's clip volume 0 ≤ z ≤ w leaves only the
        // near plane to clip against (w ≥ z); x and y are clipped by the map's bounds below.
        for triangle in geometry.triangles() {
            let [a, b, c] = [0, 1, 2].map(|k| triangle[k] as usize);
            let inside = (clip[a].w >= clip[a].z, clip[b].w >= clip[b].z, clip[c].w >= clip[c].z);
            match inside {
                (true, true, true) => self.projected_triangle([projected[a], projected[b], projected[c]]),
                (false, false, false) => {}
                _ => {
                    let polygon = clip_near([clip[a], clip[b], clip[c]]);
                    for k in 1..polygon.len().saturating_sub(1) {
                        self.triangle([polygon[0], polygon[k], polygon[k + 1]]);
                    }
                }
            }
        }
        (self.clip, self.projected) = (clip, projected);
    }

    /// The map's largest depth per cell (`settled::CellMaxima`), read from the texels the last
    /// drawing wrote: the rest are 0.
    pub(super) fn cell_maxima(&self) -> CellMaxima {
        let mut cells = CellMaxima::new([self.size.x, self.size.y], self.empty);
        if !self.empty {
            let width = self.size.x as usize;
            for (y, span) in self.written.iter().enumerate().filter(|(_, span)| span[0] <= span[1]) {
                let row = &self.depths[y * width..][..width];
                cells.add_row(y as u32, span[0], &row[span[0] as usize..=span[1] as usize]);
            }
        }
        cells
    }

    /// Where a vertex in clip coordinates lands on this map (viewport transform: x right and
    /// y down from the top-left corner, in texels; depth z / w, as the rasteriser
    /// interpolates it, affine across the screen), and its fixed point where it fits.
    #[inline]
    fn project(&self, v: Vec4) -> Projected {
        let (w, h) = (self.size.x as f32, self.size.y as f32);
        let inv = 1.0 / v.w;
        let screen = Vec3::new((v.x * inv + 1.0) * 0.5 * w, (1.0 - v.y * inv) * 0.5 * h, v.z * inv);
        let fits = screen.x.abs() < FIXED_RANGE && screen.y.abs() < FIXED_RANGE;
        Projected { screen, fixed: fits.then(|| [round_to_i64(screen.x * SUBTEXEL), round_to_i64(screen.y * SUBTEXEL)]) }
    }

    /// Every texel 0: those the last drawing wrote, or all of them for a map of a new size.
    fn clear(&mut self) {
        let (width, rows) = (self.size.x as usize, self.size.y as usize);
        if self.depths.len() != width * rows || self.written.len() != rows {
            self.depths.clear();
            self.depths.resize(width * rows, 0.0);
            self.written.clear();
            self.written.resize(rows, UNWRITTEN);
            return;
        }
        for (row, span) in self.depths.chunks_exact_mut(width).zip(&mut self.written) {
            if span[0] <= span[1] {
                row[span[0] as usize..=span[1] as usize].fill(0.0);
            }
            *span = UNWRITTEN;
        }
    }

    /// Notes that row `y`'s texels `first..=last` may be written.
    #[inline]
    fn mark(&mut self, y: i64, first: i64, last: i64) {
        let span = &mut self.written[y as usize];
        *span = [span[0].min(first as u32), span[1].max(last as u32)];
    }

    /// Rasterises one triangle in clip coordinates (every vertex in front of the near plane).
    pub(super) fn triangle(&mut self, vertices: [Vec4; 3]) {
        self.projected_triangle(vertices.map(|v| self.project(v)));
    }

    /// Rasterises one triangle of projected vertices: in fixed point where every vertex fits.
    fn projected_triangle(&mut self, vertices: [Projected; 3]) {
        let screen = vertices.map(|v| v.screen);
        match vertices.map(|v| v.fixed) {
            [Some(a), Some(b), Some(c)] => self.fixed_spans_from(screen, [a, b, c], SPAN_FROM),
            _ => self.wide(screen),
        }
    }

    /// Vulkan's rules in exact fixed point: vertices snapped to 1/`SUBTEXEL` (`fixed`), a
    /// texel covered when its centre is inside every edge, or on an edge that is a top or a
    /// left one. The covered span of rows at least `span_from` texels wide is found by solving
    /// the edges (`SPAN_FROM`), every texel of narrower ones tested.
    pub(super) fn fixed_spans_from(&mut self, screen: [Vec3; 3], fixed: [[i64; 2]; 3], span_from: i64) {
        let area = cross(fixed[0], fixed[1], fixed[2]);
        if area == 0 {
            return;
        }
        // Both faces are drawn (contract §1: a back face casts a shadow too): order the
        // vertices so that the inside of every edge is where its function is positive.
        let order = if area > 0 { [0, 1, 2] } else { [0, 2, 1] };
        let [p0, p1, p2] = [fixed[order[0]], fixed[order[1]], fixed[order[2]]];
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
        // Each edge function's step a texel along a row and a row down.
        let (step_x, step_y) = (edges.each_ref().map(|e| e.a * sub), edges.each_ref().map(|e| e.b * sub));
        let centre = |i: i64| i * sub + sub / 2;
        let at = |e: &Edge| e.a * centre(x0) + e.b * centre(y0) + e.c;
        let mut row = [at(&edges[0]), at(&edges[1]), at(&edges[2])];
        let depth = DepthPlane::new([screen[order[0]], screen[order[1]], screen[order[2]]]);
        let width = self.size.x as usize;
        // Texel centres as f32 are exact (integers and a half, far below 2²³): the first's plus
        // i gives what converting each would.
        let px0 = x0 as f32 + 0.5;
        #[cfg(target_arch = "x86_64")]
        if self.avx2 && x1 - x0 < span_from.min(8) {
            for y in y0..=y1 {
                self.mark(y, x0, x1);
            }
            let plane = [depth.origin.z, depth.origin.x, depth.dx, depth.origin.y, depth.dy];
            let (columns, rows) = ((x0 as usize, (x1 - x0 + 1) as usize), y0 as usize..y1 as usize + 1);
            // Safety: `avx2` says the CPU has AVX2 (`super::has_avx2`); the box lies in the map
            // and is at most eight texels wide.
            unsafe { super::avx2::narrow_triangle(&mut self.depths, width, columns, rows, row, step_x, step_y, plane) };
            return;
        }
        for y in y0..=y1 {
            let across = depth.row(y as f32 + 0.5);
            if x1 - x0 >= span_from {
                let (mut from, mut to) = (x0, x1);
                for k in 0..3 {
                    let step = step_x[k];
                    match step.signum() {
                        // w + step·(x − x0) ≥ 0 from x0 + ⌈−w / step⌉ on.
                        1 => from = from.max(x0 + (-row[k] + step - 1).div_euclid(step)),
                        // … up to x0 + ⌊w / −step⌋.
                        -1 => to = to.min(x0 + row[k].div_euclid(-step)),
                        _ if row[k] < 0 => to = from - 1,
                        _ => {}
                    }
                }
                if from <= to {
                    self.mark(y, from, to);
                    let line = &mut self.depths[y as usize * width..][..width];
                    // Each centre from its index, not stepped: the loop has no carried value
                    // and is vectorised (the same centres: exact either way).
                    let first = from as i32;
                    for (i, stored) in line[from as usize..=to as usize].iter_mut().enumerate() {
                        let px = (first + i as i32) as f32 + 0.5;
                        *stored = stored.max(across.at(px));
                    }
                }
            } else {
                self.mark(y, x0, x1);
                let line = &mut self.depths[y as usize * width..][..width];
                let mut w = row;
                // Without a branch (whether a texel of a small triangle's box is covered is
                // as good as a coin toss) and with each centre from its index (a stepped one
                // would carry a float add's latency from texel to texel): the same values.
                for (i, stored) in line[x0 as usize..=x1 as usize].iter_mut().enumerate() {
                    let covered = (w[0] | w[1] | w[2]) >= 0;
                    let drawn = stored.max(across.at(px0 + i as f32));
                    *stored = if covered { drawn } else { *stored };
                    w = [w[0] + step_x[0], w[1] + step_x[1], w[2] + step_x[2]];
                }
            }
            for k in 0..3 {
                row[k] += step_y[k];
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
            if x0 <= x1 {
                self.mark(y, x0, x1);
            }
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
        self.row(y).at(x)
    }

    /// The plane along the row of texel centres at `y`, its row's term taken once: the last
    /// one added, so a texel's depth is the same to the bit however its row is walked.
    fn row(&self, y: f32) -> DepthRow {
        DepthRow { z: self.origin.z, x: self.origin.x, dx: self.dx, across: self.dy * (y - self.origin.y) }
    }
}

/// `DepthPlane` along one row: z + dx·(x − x₀) + the row's term.
struct DepthRow {
    z: f32,
    x: f32,
    dx: f32,
    across: f32,
}

impl DepthRow {
    #[inline]
    fn at(&self, x: f32) -> f32 {
        self.z + self.dx * (x - self.x) + self.across
    }
}

/// `v.round() as i64` (half away from zero), without a call to libm's `roundf` (baseline x86-64
/// has no rounding instruction): |v| + ½ is exact in f64, and truncating it is rounding |v|.
#[inline]
pub(super) fn round_to_i64(v: f32) -> i64 {
    let magnitude = (f64::from(v.abs()) + 0.5) as i64;
    if v < 0.0 {
        -magnitude
    } else {
        magnitude
    }
}

/// The part of a triangle in front of the near plane (w ≥ z: every map's clip z is its near
/// plane), as a convex polygon of up to four vertices.
pub(super) fn clip_near(vertices: [Vec4; 3]) -> Vec<Vec4> {
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
