//! Method `chun-oh` (Chun & Oh 2016, "An Efficient Soft Shadow Mapping for Area Lights in
//! Various Shapes and Colors"): the PCSS filter of `filter.rs`, adaptively subdivided like a
//! quad tree where the shadow or the light is complex, each sub-region's visibility weighting
//! the colour of the matching part of the light image (§3, Fig. 3). Shader:
//! `shaders/methods/chun_oh/chun_oh.wgsl`.
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
//! - Orientation: as `filter.rs` says.

use wgpu::util::DeviceExt;

use super::filter::{self, light_regions_buffer, Uniforms, FILTER_PARAMS, MODE_ADAPTIVE, MODE_FIXED};
use super::{Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;

pub struct ChunOh;

const MODE: Param<&str> = Param::choice(
    "mode",
    "adaptive",
    &["adaptive", "fixed"],
    "adaptive: split where variance asks (0–2 times, the paper's default); fixed: always 4×4 (Table 1)",
);
const THRESHOLD: Param<f32> = Param::float(
    "threshold",
    0.2244,
    0.0,
    0.25,
    "visibility variance E − E² above which a region splits (§3; 0.25 is the maximum, so 0.25 never splits)",
);
const LIGHT_THRESHOLD: Param<f32> = Param::float(
    "light_threshold",
    0.05,
    0.0,
    1.0e6,
    "relative colour variance of the light part a region maps to above which a partly shadowed region splits",
);

const PARAMS: &[ParamSpec] = &[
    MODE.spec,
    THRESHOLD.spec,
    LIGHT_THRESHOLD.spec,
    FILTER_PARAMS[0],
    FILTER_PARAMS[1],
    FILTER_PARAMS[2],
    FILTER_PARAMS[3],
    FILTER_PARAMS[4],
    FILTER_PARAMS[5],
];

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

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let mode = if params.get(&MODE) == "fixed" { MODE_FIXED } else { MODE_ADAPTIVE };
        let uniforms = Uniforms::new(ctx, params).subdividing(mode, params.get(&THRESHOLD), params.get(&LIGHT_THRESHOLD));
        let regions = light_regions_buffer(ctx);
        let counts = filter::run(ctx, "chun-oh", "methods/chun_oh/chun_oh.wgsl", uniforms, &regions)?;
        let mut counters = counts.counters(u64::from(ctx.width) * u64::from(ctx.height));
        for (level, &count) in counts.levels.iter().enumerate() {
            counters.insert(format!("pixels_subdivided_{level}"), f64::from(count));
        }
        counters.insert("splits_forced_by_light".to_owned(), f64::from(counts.forced_by_light));
        Ok(counters)
    }
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
) -> Result<Vec<ProbeResult>, crate::gpu::GpuError> {
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
    let pipeline = crate::gpu::shaders::compute_pipeline(
        device,
        "Probe::pipeline",
        ("methods/chun_oh/quadtree_probe.wgsl", "main"),
        &[&bind_layout],
        &[],
    );
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
    let values: Vec<[f32; 4]> = bytemuck::cast_slice(&crate::gpu::readback::read_buffer(gpu, &results)?).to_vec();
    Ok(values
        .iter()
        .map(|v| {
            let code = v[3] as u32;
            ProbeResult { visibility: [v[0], v[1], v[2]], level: code % 4, forced: code / 4 }
        })
        .collect())
}
