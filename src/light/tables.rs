//! Per-light tables of how each channel's emission is spread over the light (contract §1:
//! visibility per channel), built once per light image and size on the CPU and kept by the
//! methods that look them up:
//!
//! - `edge_table`, the intensity look-up of Rong & Tan 2006 (§3, §4.1), coloured: for a line
//!   across the light, given by its direction from the centre and its distance, the part of
//!   each channel's emission on the centre's side. `jfa-l`, `jfa-e` and `brabec` read it
//!   (`shaders/common/edge_table.wgsl`); `key_table` holds its luminance on a grid over the
//!   light, the keys JFA's rounds compare (`shaders/methods/jfa/common.wgsl`).
//! - `sector_table`: the emission of the sectors around the light centre, from direction 0
//!   to each angle, beyond each fraction of the way to the rectangle's edge — exact along
//!   each ray for the piecewise-constant image. `wedges` integrates each channel over the
//!   region a wedge cuts off with it (`shaders/methods/wedges/rasterize.wgsl`).
//! - `emitting_octagon`: a convex octagon around the light's emitting texels, by which
//!   `wedges` recognises the wedges that can hide nothing that emits.

use glam::Vec2;

use super::{AreaLight, LightImage};

/// Directions of the edge table's lines, over the full turn.
pub const EDGE_ANGLES: u32 = 256;
/// Distances per direction, at s = 0, 1/(n−1), …, 1 of the way to the rectangle's edge.
pub const EDGE_STATIONS: u32 = 64;

/// Sample points per side of the light integrating each entry (nearest texel): the lines cut
/// through texels, so even a 1×1 image needs many.
const EDGE_SAMPLES: u32 = 256;

/// Bins of each direction's histogram of the samples' distances along it.
const EDGE_BINS: usize = 2048;

/// Rec. 709's luminance weights, which jump flooding's keys use (`shaders/methods/jfa/common.wgsl`).
pub const LUMINANCE: glam::Vec3 = glam::Vec3::new(0.2126, 0.7152, 0.0722);

/// Cells per side of `key_table`'s grid over the light.
pub const KEY_CELLS: u32 = 128;

/// The keys jump flooding minimises (`shaders/methods/jfa/common.wgsl`) at every point q of
/// the light: the luminance of the edge table's entry for the line through q orthogonal to
/// c→q (Rong & Tan 2006 §3), as `edge_lookup` interpolates it. Sampled at the corners of a
/// grid of KEY_CELLS × KEY_CELLS cells over the rectangle (x along r, y along u, from the
/// (−r, −u) corner) and laid out for a bilinear look-up in one load: element (row j, column i)
/// holds the keys at cell (i, j)'s corners (i, j), (i + 1, j), (i, j + 1) and (i + 1, j + 1).
///
/// A grid over the light rather than the edge table's (direction, distance): a round looks a
/// key up for each of a pixel's nine neighbours, and finding a point's direction (an atan2)
/// and distance (a square root, three divisions) cost lavapipe a sixth of `jfa-e`'s rounds;
/// a grid cell is two multiplications away. The key only
/// ranks occluders (the final pass recomputes the colour from the edge table itself), and the
/// grid departs from the polar look-up only within a cell of the centre, where the direction
/// of the line turns fastest.
pub fn key_table(light: &AreaLight, table: &[[f32; 4]]) -> Vec<[f32; 4]> {
    let n = KEY_CELLS;
    let key = |i: u32, j: u32| {
        let q = (Vec2::new(i as f32, j as f32) / n as f32 - Vec2::splat(0.5)) * light.size_m;
        edge_lookup(table, light.size_m * 0.5, q).truncate().dot(LUMINANCE)
    };
    let corners: Vec<f32> = (0..=n).flat_map(|j| (0..=n).map(move |i| (i, j))).map(|(i, j)| key(i, j)).collect();
    let at = |i: u32, j: u32| corners[(j * (n + 1) + i) as usize];
    (0..n).flat_map(|j| (0..n).map(move |i| (i, j))).map(|(i, j)| [at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)]).collect()
}

/// The edge table's look-up for the line through light point `q` (light-local metres, the
/// centre at the origin) orthogonal to c→q, interpolated between neighbouring directions and
/// distances: `edge_fraction_at` in `shaders/common/edge_table.wgsl`, step for step.
fn edge_lookup(table: &[[f32; 4]], half: Vec2, q: Vec2) -> glam::Vec4 {
    let length = q.length();
    let (e, s) = if length > 0.0 { (q / length, length / edge_distance(half, q / length)) } else { (Vec2::X, 0.0) };
    let turns = (e.y.atan2(e.x) / std::f32::consts::TAU + 1.0).fract();
    let y = turns * EDGE_ANGLES as f32;
    let row = y as u32;
    let x = s.clamp(0.0, 1.0) * (EDGE_STATIONS - 1) as f32;
    let entry = |row: u32| {
        let i = (x as u32).min(EDGE_STATIONS - 2);
        let at = ((row % EDGE_ANGLES) * EDGE_STATIONS + i) as usize;
        glam::Vec4::from(table[at]).lerp(glam::Vec4::from(table[at + 1]), (x - i as f32).clamp(0.0, 1.0))
    };
    entry(row).lerp(entry(row + 1), y - row as f32)
}

/// The edge table: the intensity look-up of Rong & Tan 2006 (§3, §4.1), coloured and indexed
/// by the line rather than by a point of the light. Row i is the direction
/// eᵢ = (cos φᵢ, sin φᵢ), φᵢ = 2π·i/EDGE_ANGLES, in light-local coordinates (x along r, y along
/// u); entry j is the line orthogonal to eᵢ at distance λ = sⱼ·ρ(eᵢ) from the centre,
/// sⱼ = j/(EDGE_STATIONS − 1), ρ the distance to the rectangle's edge along eᵢ. It holds in rgb
/// the fraction of each channel's emission on the centre's side of that line (y·eᵢ < λ), in w
/// the same fraction of the light's white twin (`LightImage::white_twin`: the shape alone) —
/// what a method that estimates visibility without the colours is an estimate of. A straight occluder edge projected onto the light is such
/// a line: the part of the light it leaves visible is one side of it. Indexing by (direction,
/// distance) rather than by a grid over the light keeps the direction exact next to the centre,
/// where a grid's neighbouring texels hold lines of every orientation.
pub fn edge_table(light: &AreaLight, image: &LightImage) -> Vec<[f32; 4]> {
    let n = EDGE_SAMPLES;
    // Emitting sample points in light-local metres with their emission (rgb) and their weight
    // in the light's white twin (w: the texel's alpha).
    let samples: Vec<(Vec2, glam::Vec4)> = (0..n)
        .flat_map(|j| (0..n).map(move |i| (i, j)))
        .filter_map(|(i, j)| {
            let (s, t) = ((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
            let texel = image.texel_at(s, t);
            let e = image.emission(texel.0, texel.1);
            (e.max_element() > 0.0).then(|| (local(light, s, t), e.extend(image.alpha(texel.0, texel.1))))
        })
        .collect();
    let total = samples.iter().fold(glam::Vec4::ZERO, |acc, (_, e)| acc + *e);
    let half = light.size_m * 0.5;
    let radius = half.length();
    let row = |i: u32| -> Vec<[f32; 4]> {
        let phi = std::f64::consts::TAU * f64::from(i) / f64::from(EDGE_ANGLES);
        let e = Vec2::new(phi.cos() as f32, phi.sin() as f32);
        // Cumulative emission along e, over [−radius, radius] in EDGE_BINS bins.
        let mut bins = vec![glam::Vec4::ZERO; EDGE_BINS + 1];
        let scale = EDGE_BINS as f32 / (2.0 * radius);
        for (y, emission) in &samples {
            let bin = (((y.dot(e) + radius) * scale) as usize).min(EDGE_BINS - 1);
            bins[bin + 1] += *emission;
        }
        for k in 1..bins.len() {
            let before = bins[k - 1];
            bins[k] += before;
        }
        let reach = edge_distance(half, e);
        (0..EDGE_STATIONS)
            .map(|j| {
                let lambda = reach * j as f32 / (EDGE_STATIONS - 1) as f32;
                let x = ((lambda + radius) * scale).clamp(0.0, EDGE_BINS as f32);
                let k = (x as usize).min(EDGE_BINS - 1);
                let inside = bins[k].lerp(bins[k + 1], x - k as f32);
                let shape = if total.w > 0.0 { inside.w / total.w } else { 0.0 };
                // A channel the light does not emit takes the shape's fraction.
                let fraction = |c: usize| if total[c] > 0.0 { inside[c] / total[c] } else { shape };
                [fraction(0), fraction(1), fraction(2), shape]
            })
            .collect()
    };
    // 256 directions × ~6·10⁴ samples: the rows are shared among the CPU's cores.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()) as u32;
    let rows_per_thread = EDGE_ANGLES.div_ceil(threads);
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..EDGE_ANGLES)
            .step_by(rows_per_thread as usize)
            .map(|first| {
                let row = &row;
                scope.spawn(move || (first..(first + rows_per_thread).min(EDGE_ANGLES)).flat_map(row).collect::<Vec<_>>())
            })
            .collect();
        workers.into_iter().flat_map(|worker| worker.join().expect("an edge-table worker panicked")).collect()
    })
}

/// Angular steps of `sector_table` per turn; the table covers two turns (and one row more),
/// so that any interval of angle starting in the first turn reads without wrapping.
pub const SECTOR_ANGLES: u32 = 1024;
/// Radial stations per angle, at s = 0, 1/(n−1), …, 1 of the way to the rectangle's edge.
pub const SECTOR_STATIONS: u32 = 64;

/// The sector table, `2·SECTOR_ANGLES + 1` rows of `SECTOR_STATIONS` entries: entry (i, j) is
/// the emission of the part of the light between the directions 0 and φᵢ = 2π·i/SECTOR_ANGLES
/// from its centre (light-local, x along r, y along u, counter-clockwise) and beyond
/// sⱼ = j/(SECTOR_STATIONS − 1) of the distance ρ(φ) to the rectangle's edge:
/// ∫₀^φᵢ ∫_{sⱼ·ρ(φ)}^{ρ(φ)} emission(ρ, φ) ρ dρ dφ in rgb, and in w the same area without the
/// image (emission 1 everywhere). A region bounded by two rays from the centre, by the
/// rectangle's edge and by a curve ρ = s(φ)·ρ(φ) then has the emission B(φ₁, s) − B(φ₀, s)
/// where s is constant — two look-ups, the shape of a wedge's region (station 0 holds whole
/// sectors) — and a curve that varies is followed in short steps: an image's colour
/// boundaries (whatever their direction) are integrated exactly, what is approximated is only
/// how s varies within a step. Along each ray the integral is exact (the ray is cut where it
/// crosses texel boundaries); over angle each row adds the ray at its step's middle angle.
pub fn sector_table(light: &AreaLight, image: &LightImage) -> Vec<[f32; 4]> {
    let half = light.size_m * 0.5;
    let (width, height) = (image.width, image.height);
    let stations = SECTOR_STATIONS as usize;
    let step = std::f64::consts::TAU / f64::from(SECTOR_ANGLES);
    // One turn of rays at the steps' middle angles, each ray's running integral at the stations.
    let mut rays: Vec<[f32; 4]> = Vec::with_capacity(SECTOR_ANGLES as usize * stations);
    let mut cuts: Vec<f32> = Vec::new();
    for i in 0..SECTOR_ANGLES {
        let phi = step * (f64::from(i) + 0.5);
        let e = Vec2::new(phi.cos() as f32, phi.sin() as f32);
        let reach = edge_distance(half, e);
        // Where the ray crosses texel columns and rows, and the stations.
        cuts.clear();
        for k in 1..width {
            let rho = (k as f32 / width as f32 - 0.5) * light.size_m.x / e.x;
            if rho > 0.0 && rho < reach {
                cuts.push(rho);
            }
        }
        for k in 1..height {
            let rho = (0.5 - k as f32 / height as f32) * light.size_m.y / e.y;
            if rho > 0.0 && rho < reach {
                cuts.push(rho);
            }
        }
        let station = |j: usize| reach * j as f32 / (stations - 1) as f32;
        cuts.extend((0..stations).map(station));
        cuts.sort_by(f32::total_cmp);
        // Running integrals from the centre; each station's is taken from the ray's total below.
        let mut sum = glam::Vec3::ZERO;
        let mut last = 0.0f32;
        let mut next = 0;
        for &rho in &cuts {
            if rho > last {
                let mid = e * (0.5 * (last + rho));
                let s = (mid.x / light.size_m.x + 0.5).clamp(0.0, 1.0);
                let t = (0.5 - mid.y / light.size_m.y).clamp(0.0, 1.0);
                let texel = image.texel_at(s, t);
                sum += image.emission(texel.0, texel.1) * (0.5 * (rho * rho - last * last));
                last = rho;
            }
            while next < stations && station(next) <= rho {
                let r = station(next);
                rays.push([sum.x, sum.y, sum.z, 0.5 * r * r]);
                next += 1;
            }
        }
        // Float rounding can leave the last station (= reach) unmatched.
        while next < stations {
            let r = station(next);
            rays.push([sum.x, sum.y, sum.z, 0.5 * r * r]);
            next += 1;
        }
    }
    // Beyond each station (the ray's total less what lies within), cumulative over angle, for
    // two turns; in f64 until stored, so the differences lose nothing to rounding.
    let rows = 2 * SECTOR_ANGLES as usize + 1;
    let mut table = vec![[0.0f32; 4]; rows * stations];
    let mut running = vec![[0.0f64; 4]; stations];
    for i in 1..rows {
        let ray = &rays[((i - 1) % SECTOR_ANGLES as usize) * stations..][..stations];
        let total = ray[stations - 1];
        for j in 0..stations {
            for k in 0..4 {
                running[j][k] += (f64::from(total[k]) - f64::from(ray[j][k])) * step;
                table[i * stations + j][k] = running[j][k] as f32;
            }
        }
    }
    table
}

/// An octagon holding every texel of the light that emits, as its extent along x, y, x + y
/// and x − y (light-local metres: x along r, y along u), lows then highs — the bounding box
/// with its corners cut. `wedges` skips a wedge whose silhouette edge, projected onto the
/// light, misses it: the light a wedge hides lies beyond the edge, on segments from the
/// centre that cross it, so with the centre inside a convex region that holds every emitting
/// texel such a wedge hides no emission. Where the centre lies outside the texels' octagon
/// (or nothing emits), the rectangle's own octagon, which holds the centre.
pub fn emitting_octagon(light: &AreaLight, image: &LightImage) -> ([f32; 4], [f32; 4]) {
    let axes = |p: Vec2| [p.x, p.y, p.x + p.y, p.x - p.y];
    let half = light.size_m * 0.5;
    let rectangle = ([-half.x, -half.y, -half.x - half.y, -half.x - half.y], [half.x, half.y, half.x + half.y, half.x + half.y]);
    let (mut lo, mut hi) = ([f32::INFINITY; 4], [f32::NEG_INFINITY; 4]);
    let emits = |i: u32, j: u32| image.emission(i, j).max_element() > 0.0;
    for j in 0..image.height {
        // Along a row every extent is reached at its first or its last emitting texel, so
        // each row is searched from both ends (a light that emits everywhere costs two texels
        // a row).
        let Some(first) = (0..image.width).find(|&i| emits(i, j)) else { continue };
        let last = (first..image.width).rev().find(|&i| emits(i, j)).unwrap_or(first);
        let (s0, s1) = (first as f32 / image.width as f32, (last + 1) as f32 / image.width as f32);
        let (t0, t1) = (j as f32 / image.height as f32, (j + 1) as f32 / image.height as f32);
        for corner in [local(light, s0, t0), local(light, s1, t0), local(light, s0, t1), local(light, s1, t1)] {
            for (k, v) in axes(corner).into_iter().enumerate() {
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        }
    }
    if (0..4).all(|k| lo[k] <= 0.0 && hi[k] >= 0.0) {
        (lo, hi)
    } else {
        rectangle
    }
}

/// Distance from the centre of a rectangle of half-sides `half` to its edge along unit `e`.
fn edge_distance(half: Vec2, e: Vec2) -> f32 {
    let x = if e.x != 0.0 { half.x / e.x.abs() } else { f32::INFINITY };
    let y = if e.y != 0.0 { half.y / e.y.abs() } else { f32::INFINITY };
    x.min(y)
}

/// Image coordinates (s right, t down) to light-local metres (x along r, y along u).
fn local(light: &AreaLight, s: f32, t: f32) -> Vec2 {
    Vec2::new((s - 0.5) * light.size_m.x, (0.5 - t) * light.size_m.y)
}

#[cfg(test)]
mod tests;
