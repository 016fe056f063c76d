//! Tiles of the frame that a set of samples all see lit, found without testing their pixels:
//! each sample's map kept as the largest depth it stores per cell of texels, and a tile's
//! receivers bounded as a whole. Where no cell a tile's receivers can read stores anything as
//! near as they are, every test of theirs is lit — what `filtered`'s probes would say there,
//! for a fraction of their cost (its module docs).

use glam::Vec3;
use rayon::prelude::*;

use super::{rotation_rows, CpuSample, Geometry, Maps, Spent, TestConstants};
use crate::render::method::Surfaces;

/// Texels a cell side: a tile of eight pixels reads a few cells of a 2,048² map at 1080p.
pub(super) const CELL: u32 = 8;

/// A sample's map as the largest depth stored in each cell of `CELL`² texels (0: nothing
/// drawn there; an empty map has no cells).
pub(in crate::methods::reference) struct CellMaxima {
    /// The map's size in texels.
    size: [u32; 2],
    columns: u32,
    /// Per cell, row after row, its largest depth's bits: depths are ≥ 0, and such floats
    /// order as their bits do.
    cells: Vec<u32>,
}

impl CellMaxima {
    /// The cells of a map of `size` texels, all 0; none for an empty map.
    pub(super) fn new(size: [u32; 2], empty: bool) -> Self {
        let (columns, rows) = if empty { (0, 0) } else { (size[0].div_ceil(CELL), size[1].div_ceil(CELL)) };
        Self { size, columns, cells: vec![0; (columns * rows) as usize] }
    }

    /// Adds row `y`'s texels from `first` on, `depths`.
    pub(super) fn add_row(&mut self, y: u32, first: u32, depths: &[f32]) {
        let row = (y / CELL * self.columns) as usize;
        let (mut x, mut rest) = (first, depths);
        while !rest.is_empty() {
            // Up to the next cell's edge.
            let (part, tail) = rest.split_at(((CELL - x % CELL) as usize).min(rest.len()));
            let most = part.iter().fold(0u32, |most, d| most.max(d.to_bits()));
            let cell = &mut self.cells[row + (x / CELL) as usize];
            *cell = (*cell).max(most);
            x += part.len() as u32;
            rest = tail;
        }
    }

    /// The largest depth stored over texels `x` × `y` (inclusive ranges, within the map).
    fn most(&self, x: [u32; 2], y: [u32; 2]) -> f32 {
        let mut most = 0;
        for cy in y[0] / CELL..=y[1] / CELL {
            let row = &self.cells[(cy * self.columns) as usize..][..self.columns as usize];
            most = row[(x[0] / CELL) as usize..=(x[1] / CELL) as usize].iter().fold(most, |m, &c| m.max(c));
        }
        f32::from_bits(most)
    }
}

/// Draws `samples`' maps into `maps`, a round of them at a time on every core, and keeps each
/// as its `CellMaxima`.
pub(in crate::methods::reference) fn cell_maxima(
    samples: &[CpuSample],
    geometry: Geometry<'_>,
    maps: &mut Maps,
) -> (Vec<CellMaxima>, Spent) {
    let started = std::time::Instant::now();
    let threads = rayon::current_num_threads().max(1);
    let maps = maps.first(threads.min(samples.len()));
    let mut maxima = Vec::with_capacity(samples.len());
    for chunk in samples.chunks(maps.len().max(1)) {
        let round: Vec<CellMaxima> = maps
            .par_iter_mut()
            .zip(chunk)
            .map(|(map, sample)| {
                map.draw(sample, geometry);
                map.cell_maxima()
            })
            .collect();
        maxima.extend(round);
    }
    (maxima, Spent { maps_ms: started.elapsed().as_secs_f64() * 1e3, tests_ms: 0.0, round: maps.len() })
}

/// Per tile of `tile`² pixels of `surfaces` (rows of ⌈width / tile⌉ tiles), whether every
/// covered pixel in it would come out of `samples`' tests lit by every one and lit at all —
/// `estimate::Texel` sums equal shadowed and unshadowed, not zero — so that its tests can be
/// left out. A tile holds when:
/// - each covered pixel lies in front of the light's plane and some sample of some light
///   lights it (its G > 0 by the tests' own arithmetic, `scalar_add_sample`);
/// - for each sample with a map, the largest depth stored over the texels the tile's
///   receivers can read (their box in the sample's view, one texel wider each way than
///   rounding could move them) passes the test of the tile's farthest receiver without its
///   bias. The test `(depth·k − depth²·bias / distance) · stored ≤ near·k` only grows with
///   depth and stored and shrinks with the bias (≥ 0), in exact arithmetic and in rounded
///   floats alike (rounding is monotonic), so every receiver passes too.
///
/// A tile with no covered pixel holds (there is nothing to test).
pub(in crate::methods::reference) fn lit_tiles(
    surfaces: &Surfaces,
    tile: u32,
    samples: &[CpuSample],
    maxima: &[CellMaxima],
    c: &TestConstants,
    channels: usize,
) -> Vec<bool> {
    let rotation = rotation_rows(c);
    let (columns, rows) = (surfaces.width.div_ceil(tile), surfaces.height.div_ceil(tile));
    let half = 0.5 * c.resolution as f32;
    // The samples that light anything, in the channels kept.
    let lighting: Vec<&CpuSample> = samples.iter().filter(|s| s.weight.to_array()[..channels].iter().any(|&w| w > 0.0)).collect();
    // Whether some sample lights a receiver at view coordinates `at`: G = cos·depth / dist⁴ >
    // 0 as the tests compute it (`scalar_add_sample`). Their cos is taken the same way; where
    // cos·depth ≥ 10⁻¹⁸ and dist² ≤ 10⁸, G ≥ 10⁻³⁴, above f32's least normal, so that the
    // division and the square root are spared.
    let lights = |normal: Vec3, [x, y, depth]: [f32; 3]| -> bool {
        let n = Vec3::new(rotation[0].dot(normal), rotation[1].dot(normal), rotation[2].dot(normal));
        let (depth2, n_dot_z) = (depth * depth, -n.z * depth);
        lighting.iter().any(|s| {
            let (dx, dy) = (x - s.origin[0], y - s.origin[1]);
            let dist2 = dx.mul_add(dx, dy.mul_add(dy, depth2));
            let cos = (-n.x.mul_add(dx, n.y.mul_add(dy, n_dot_z))).max(0.0);
            if cos * depth >= 1e-18 && dist2 <= 1e8 {
                return true;
            }
            let inv_dist = 1.0 / dist2.sqrt();
            let inv_dist2 = inv_dist * inv_dist;
            cos * depth.max(0.0) * inv_dist2 * inv_dist2 > 0.0
        })
    };
    (0..rows)
        .into_par_iter()
        .flat_map_iter(|ty| {
            (0..columns).map(move |tx| {
                // The tile's receivers' box in the samples' view coordinates.
                let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
                for py in ty * tile..((ty + 1) * tile).min(surfaces.height) {
                    for px in tx * tile..((tx + 1) * tile).min(surfaces.width) {
                        let Some(normal) = surfaces.normal(px, py) else { continue };
                        let world = surfaces.position(px, py);
                        let at = [rotation[0].dot(world), rotation[1].dot(world), c.depth_of(world)];
                        if at[2].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !lights(normal, at) {
                            return false;
                        }
                        for k in 0..3 {
                            lo[k] = lo[k].min(at[k]);
                            hi[k] = hi[k].max(at[k]);
                        }
                    }
                }
                if lo[2] > hi[2] {
                    return true; // No covered pixel.
                }
                samples.iter().zip(maxima).all(|(s, cells)| {
                    let Some(crop) = s.crop_origin else { return true }; // An empty map: lit.
                    let k = s.texels_per_tan;
                    if k.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                        return false;
                    }
                    // f = (x − origin)·k / depth, over the box: a product of two intervals.
                    let span = |axis: usize| {
                        let d = [lo[axis] - s.origin[axis], hi[axis] - s.origin[axis]];
                        let inverse = [1.0 / hi[2], 1.0 / lo[2]];
                        let products = [d[0] * inverse[0], d[0] * inverse[1], d[1] * inverse[0], d[1] * inverse[1]].map(|p| p * k);
                        products.iter().fold([f32::MAX, f32::MIN], |[a, b], &p| [a.min(p), b.max(p)])
                    };
                    let ([fx0, fx1], [fy0, fy1]) = (span(0), span(1));
                    let last = [cells.size[0] as f32 - 1.0, cells.size[1] as f32 - 1.0];
                    let texel = |v: f32, axis: usize| v.clamp(0.0, last[axis]) as u32;
                    let x = [texel(half + fx0 - crop.x as f32 - 1.0, 0), texel(half + fx1 - crop.x as f32 + 1.0, 0)];
                    let y = [texel(half - fy1 - crop.y as f32 - 1.0, 1), texel(half - fy0 - crop.y as f32 + 1.0, 1)];
                    let stored = cells.most(x, y);
                    stored == 0.0 || hi[2] * k * stored <= c.near * k
                })
            })
        })
        .collect()
}
