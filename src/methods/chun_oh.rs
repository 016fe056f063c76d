//! Method `chun-oh` (Chun & Oh 2016, "An Efficient Soft Shadow Mapping for Area Lights in
//! Various Shapes and Colors"): the PCSS filter of `pcss.rs`, adaptively subdivided like a
//! quad tree where the shadow or the light is complex, each sub-region's visibility weighting
//! the colour of the matching part of the light image (§3, Fig. 3). Shader:
//! `shaders/methods/pcss/chun_oh.wgsl`.
//!
//! Choices where the paper is brief:
//! - Sub-regions partition the filter's one lattice of shadow tests (kept as bit rows, so a
//!   region's visibility is a few popcounts); subdividing refers to finer groups of the same
//!   tests. Under a uniform light the sum of leaves then equals the undivided average exactly,
//!   and the cost of a split is bookkeeping, as the paper's Table 1 suggests (fixed 4×4 costs
//!   1.67× the plain average, not 16×).
//! - A region splits when its visibility variance E − E² exceeds `threshold`, or when it is
//!   not 0 and the light part it maps to has a relative colour variance above
//!   `light_threshold` ("when we use a colorful area light, we subdivide the filter area even
//!   if the shadow is not very changeful"); never below 4×4.
//! - The light's colour statistics come from one pass over the image per light (the 21 regions
//!   of the quadtree, with overlaps of fractional texels), kept for later jobs.
//! - Orientation: a blocker displaced towards the shadow map's +u (the light's −r side) hides
//!   the light's −r side, which DESIGN.md §1 puts at image column 0: filter column x maps to
//!   image columns mirrored, filter row y to image rows as they are (`light_regions`).

use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::pcss::{self, FILTER_PARAMS};
use super::{Counters, MethodContext, ParamKind, ParamSpec, Params, ShadowMethod};
use crate::gpu::pool::DerivedKey;
use crate::light::LightImage;

pub struct ChunOh;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "mode",
        kind: ParamKind::Choice { default: "adaptive", options: &["adaptive", "fixed"] },
        doc: "adaptive: split where variance asks (0–2 times, the paper's default); fixed: always 4×4 (Table 1)",
    },
    ParamSpec {
        name: "threshold",
        kind: ParamKind::Float { default: 0.2244, min: 0.0, max: 0.25 },
        doc: "visibility variance E − E² above which a region splits (§3; 0.25 is the maximum, so 0.25 never splits)",
    },
    ParamSpec {
        name: "light_threshold",
        kind: ParamKind::Float { default: 0.05, min: 0.0, max: 1.0e6 },
        doc: "relative colour variance of the light part a region maps to above which a partly shadowed region splits",
    },
    FILTER_PARAMS[0],
    FILTER_PARAMS[1],
    FILTER_PARAMS[2],
    FILTER_PARAMS[3],
    FILTER_PARAMS[4],
    FILTER_PARAMS[5],
];

/// `mode` values of `filter.wgsl`.
const MODE_ADAPTIVE: u32 = 1;
const MODE_FIXED: u32 = 2;

impl ShadowMethod for ChunOh {
    fn name(&self) -> &'static str {
        "chun-oh"
    }

    fn summary(&self) -> &'static str {
        "Chun & Oh 2016: PCSS filter from the cone to the light's corners, blocker-average sizing, variance-driven quadtree subdivision up to 4×4, sub-region visibility × light-image colour"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> Counters {
        let mode = if params.choice("mode") == "fixed" { MODE_FIXED } else { MODE_ADAPTIVE };
        let uniforms = pcss::Uniforms::new(ctx, params).subdividing(mode, params.f32("threshold"), params.f32("light_threshold"));
        let regions = light_regions_buffer(ctx);
        let counts = pcss::run(ctx, "chun-oh", "methods/pcss/chun_oh.wgsl", uniforms, &regions);
        let mut counters = counts.counters(u64::from(ctx.width) * u64::from(ctx.height));
        for (level, &count) in counts.levels.iter().enumerate() {
            counters.insert(format!("pixels_subdivided_{level}"), f64::from(count));
        }
        counters.insert("splits_forced_by_light".to_owned(), f64::from(counts.forced_by_light));
        counters
    }
}

/// The frame's light quadtree table on the GPU, built once per light image.
pub(super) fn light_regions_buffer(ctx: &mut MethodContext<'_>) -> Arc<wgpu::Buffer> {
    let (device, image) = (&ctx.gpu.device, &ctx.spec.light_image);
    ctx.derived.get_or_create(DerivedKey { name: "chun-oh.light_regions", fingerprint: image.fingerprint() }, || {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ChunOh::light_regions"),
            contents: bytemuck::cast_slice(&light_regions(image)),
            usage: wgpu::BufferUsages::STORAGE,
        })
    })
}

/// Index of filter cell (x, y) of the 4×4 level, of quadrant (x, y) of the 2×2 level, and of
/// the whole light, in `light_regions`' table.
pub fn cell_index(x: usize, y: usize) -> usize {
    y * 4 + x
}
pub fn quadrant_index(x: usize, y: usize) -> usize {
    16 + y * 2 + x
}
pub const WHOLE: usize = 20;

/// The light image over the filter's quadtree: for each region, rgb the emission integrated
/// over the part of the light it maps to (as a fraction of the light's area, so the whole
/// light's entry is its mean emission) and w that part's relative colour variance
/// E[|e − ē|²] / |ē|² (0 for a uniform part or a black one). Regions are in filter order:
/// filter cell (x, y) of the 4×4 level covers image columns s ∈ [1 − (x+1)/4, 1 − x/4]
/// (mirrored, see the module comment) and rows t ∈ [y/4, (y+1)/4].
pub fn light_regions(image: &LightImage) -> [[f32; 4]; 21] {
    // Per 4×4 cell: Σ e·a, Σ |e|²·a, Σ a, with a the overlap area in unit-square terms.
    let mut sum = [[0f64; 3]; 16];
    let mut square = [0f64; 16];
    let mut area = [0f64; 16];
    // Overlap of texel k of n with quarter q of [0, 1].
    let overlap = |k: u32, n: u32, q: u32| {
        let (lo, hi) = (f64::from(k) / f64::from(n), f64::from(k + 1) / f64::from(n));
        (hi.min(f64::from(q + 1) / 4.0) - lo.max(f64::from(q) / 4.0)).max(0.0)
    };
    for j in 0..image.height {
        for i in 0..image.width {
            let e = image.emission(i, j).as_dvec3();
            for row in 0..4 {
                let oy = overlap(j, image.height, row);
                if oy == 0.0 {
                    continue;
                }
                for quarter in 0..4 {
                    let ox = overlap(i, image.width, quarter);
                    if ox == 0.0 {
                        continue;
                    }
                    let cell = cell_index(3 - quarter as usize, row as usize);
                    let a = ox * oy;
                    for c in 0..3 {
                        sum[cell][c] += e[c] * a;
                    }
                    square[cell] += e.length_squared() * a;
                    area[cell] += a;
                }
            }
        }
    }
    let region = |cells: &[usize]| {
        let total = |f: &dyn Fn(usize) -> f64| cells.iter().map(|&c| f(c)).sum::<f64>();
        let a = total(&|c| area[c]).max(1e-300);
        let rgb = [total(&|c| sum[c][0]), total(&|c| sum[c][1]), total(&|c| sum[c][2])];
        let mean_sq = rgb.iter().map(|x| (x / a) * (x / a)).sum::<f64>();
        let variance = (total(&|c| square[c]) / a - mean_sq).max(0.0);
        let relative = if mean_sq > 0.0 { variance / mean_sq } else { 0.0 };
        [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32, relative as f32]
    };
    let mut table = [[0f32; 4]; 21];
    for y in 0..4 {
        for x in 0..4 {
            table[cell_index(x, y)] = region(&[cell_index(x, y)]);
        }
    }
    for y in 0..2 {
        for x in 0..2 {
            let cells =
                [cell_index(2 * x, 2 * y), cell_index(2 * x + 1, 2 * y), cell_index(2 * x, 2 * y + 1), cell_index(2 * x + 1, 2 * y + 1)];
            table[quadrant_index(x, y)] = region(&cells);
        }
    }
    table[WHOLE] = region(&(0..16).collect::<Vec<_>>());
    table
}

/// One synthetic tile's outcome in `quadtree_probe`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeResult {
    pub visibility: [f32; 3],
    /// Deepest split: 0, 1 (2×2) or 2 (4×4).
    pub level: u32,
    /// Splits only the light's colour asked for.
    pub forced: u32,
}

/// Runs the shader's quadtree (`quadtree.wgsl`, through `quadtree_probe.wgsl`) on synthetic
/// tiles: per tile, lit tests in each 4×4 cell (row-major, x along the shadow map's u), with
/// `cell_taps`² tests per cell, against the light table `regions` (`light_regions`).
pub fn quadtree_probe(
    gpu: &crate::gpu::GpuContext,
    tiles: &[[u32; 16]],
    regions: &[[f32; 4]; 21],
    fixed: bool,
    threshold: f32,
    light_threshold: f32,
    cell_taps: u32,
) -> Vec<ProbeResult> {
    use crate::gpu::layout;
    let device = &gpu.device;
    let storage = |label, contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    };
    let tiles_buffer = storage("Probe::tiles", bytemuck::cast_slice(tiles), wgpu::BufferUsages::STORAGE);
    let regions_buffer = storage("Probe::regions", bytemuck::cast_slice(regions), wgpu::BufferUsages::STORAGE);
    let mode = if fixed { MODE_FIXED } else { MODE_ADAPTIVE };
    let params: [u32; 4] = [mode, threshold.to_bits(), light_threshold.to_bits(), cell_taps];
    let params_buffer = storage("Probe::params", bytemuck::cast_slice(&params), wgpu::BufferUsages::UNIFORM);
    let results = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("Probe::results"),
        size: (tiles.len() * 16) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("Probe::layout"),
        entries: &[layout::storage_read(0), layout::storage_read(1), layout::uniform(2), layout::storage_read_write(3)],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("Probe::pipeline_layout"),
        bind_group_layouts: &[Some(&bind_layout)],
        immediate_size: 0,
    });
    let module = crate::gpu::shaders::module(device, "methods/pcss/quadtree_probe.wgsl");
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("Probe::pipeline"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("Probe::bind_group"),
        layout: &bind_layout,
        entries: &layout::entries(&[
            tiles_buffer.as_entire_binding(),
            regions_buffer.as_entire_binding(),
            params_buffer.as_entire_binding(),
            results.as_entire_binding(),
        ]),
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Probe::encoder") });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("Probe::pass"), timestamp_writes: None });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((tiles.len() as u32).div_ceil(64), 1, 1);
    }
    gpu.queue.submit([encoder.finish()]);
    let values: Vec<[f32; 4]> = bytemuck::cast_slice(&crate::gpu::readback::read_buffer(gpu, &results)).to_vec();
    values
        .iter()
        .map(|v| {
            let code = v[3] as u32;
            ProbeResult { visibility: [v[0], v[1], v[2]], level: code % 4, forced: code / 4 }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn builtin(name: &str) -> LightImage {
        LightImage::builtin(name, &Default::default(), "f").unwrap()
    }

    #[test]
    fn a_uniform_light_has_no_colour_variance_and_equal_parts() {
        let table = light_regions(&builtin("white"));
        for region in &table {
            assert!(region[3].abs() < 1e-9, "{region:?}");
        }
        for cell in &table[..16] {
            assert!((cell[0] - table[WHOLE][0] / 16.0).abs() < 1e-6);
        }
    }

    #[test]
    fn stripes_map_mirrored_columns_and_vary_in_colour() {
        // `stripes`: 6 columns, red at column 0 (image left, the light's −r side). Filter
        // column 3 maps to image columns s ∈ [0, 1/4]: all of the red stripe, half the next.
        let image = builtin("stripes");
        let table = light_regions(&image);
        let red_total = table[WHOLE][0];
        let right = table[cell_index(3, 0)];
        let left = table[cell_index(0, 0)];
        assert!(right[0] > left[0], "red lies in filter column 3: {right:?} vs {left:?}");
        // Direct summation of the red in s ∈ [0, 1/4] (rows don't matter for a 6×1 image).
        let red_quarter: f64 = (0..6000)
            .map(|k| (k as f64 + 0.5) / 6000.0)
            .filter(|s| *s < 0.25)
            .map(|s| f64::from(image.emission(((s * 6.0) as u32).min(5), 0).x))
            .sum::<f64>()
            / 6000.0;
        let column: f32 = (0..4).map(|y| table[cell_index(3, y)][0]).sum();
        assert!((f64::from(column) - red_quarter).abs() < 1e-3, "{column} vs {red_quarter}");
        assert!((table[..16].iter().map(|c| c[0]).sum::<f32>() - red_total).abs() < 1e-5, "cells partition the light");
        assert!(table[WHOLE][3] > 0.5 && table[quadrant_index(1, 0)][3] > 0.05, "a colourful light varies");
    }
}
