//! Method `pcss` (Fernando 2005, "Percentage-closer soft shadows"), and the pass it shares
//! with `chun-oh`: per pixel, a blocker search over the cone from the pixel to the light's
//! four corners cut at the nearest possible occluder depth, a filter sized by the cone cut at
//! the blockers' average depth, and a lattice of shadow tests over that filter
//! (`shaders/methods/pcss/filter.wgsl`). `pcss` returns their plain average, gray — the
//! baseline Chun & Oh 2016 compare with; `chun-oh` (`chun_oh.rs`) subdivides the same lattice.
//!
//! Choices where the papers leave room, shared by both so their comparison is fair: the
//! filter is the light's rectangle (its aspect kept), not a square; taps form a regular
//! lattice of (4·`taps_per_cell`)² cell centres (a 4×4 quadtree of cells needs a multiple of
//! 4 per side); each tap is compared with the receiver's tangent plane at that tap, not with
//! the pixel's own depth, so wide filters on tilted receivers do not shadow the receiver
//! itself; and the search region is capped at `max_search_texels`.

use wgpu::util::DeviceExt;

use super::{Counters, MethodContext, ParamKind, ParamSpec, Params, ShadowMethod, BIAS_TEXELS, SLOPE_BIAS_TEXELS};
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;
use crate::gpu::readback::read_buffer;

pub struct Pcss;

/// Parameters both filter methods take, with the same meaning.
pub(super) const FILTER_PARAMS: [ParamSpec; 6] = [
    ParamSpec {
        name: "search_taps",
        kind: ParamKind::Integer { default: 8, min: 1, max: 16 },
        doc: "blocker-search taps per side of the search region",
    },
    ParamSpec {
        name: "taps_per_cell",
        kind: ParamKind::Integer { default: 2, min: 1, max: 4 },
        doc: "filter taps per side of each of the 4×4 quadtree cells: the filter tests (4·this)² shadow-map texels",
    },
    ParamSpec {
        name: "max_search_texels",
        kind: ParamKind::Float { default: 64.0, min: 0.5, max: 1024.0 },
        doc: "cap on the blocker search region's half-width, texels",
    },
    ParamSpec {
        name: "max_filter_texels",
        kind: ParamKind::Float { default: 64.0, min: 0.5, max: 1024.0 },
        doc: "cap on the filter's half-width, texels",
    },
    BIAS_TEXELS,
    SLOPE_BIAS_TEXELS,
];

/// Laid out as `FilterParams` in `filter.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct Uniforms {
    search_taps: u32,
    lattice: u32,
    max_search_texels: f32,
    max_filter_texels: f32,
    bias_texels: f32,
    slope_bias_texels: f32,
    nearest: f32,
    mode: u32,
    threshold: f32,
    light_threshold: f32,
    _pad: [u32; 2],
}

/// `mode` values of `filter.wgsl`.
pub(super) const MODE_PCSS: u32 = 0;

/// What the filter pass counted (`counters` in `filter.wgsl`).
pub(super) struct FilterCounts {
    /// Covered pixels by subdivision level 0, 1, 2 (Chun & Oh Table 2).
    pub levels: [u32; 3],
    /// Region splits that only the light's colour variance asked for.
    pub forced_by_light: u32,
    /// Pixels whose blocker search found a blocker, so the filter ran.
    pub filtered: u32,
    pub covered: u32,
}

impl FilterCounts {
    pub fn counters(&self, pixels: u64) -> Counters {
        Counters::from([
            ("pixels_filtered".to_owned(), f64::from(self.filtered)),
            ("background_pixels".to_owned(), (pixels - u64::from(self.covered)) as f64),
        ])
    }
}

impl Uniforms {
    pub fn new(ctx: &MethodContext<'_>, params: &Params) -> Self {
        Self {
            search_taps: params.u32("search_taps"),
            lattice: 4 * params.u32("taps_per_cell"),
            max_search_texels: params.f32("max_search_texels"),
            max_filter_texels: params.f32("max_filter_texels"),
            bias_texels: params.f32("bias_texels"),
            slope_bias_texels: params.f32("slope_bias_texels"),
            nearest: ctx.projection.nearest,
            mode: MODE_PCSS,
            threshold: 0.0,
            light_threshold: 0.0,
            _pad: [0; 2],
        }
    }

    /// `chun-oh`'s subdivision on top of the shared filter.
    pub fn subdividing(self, mode: u32, threshold: f32, light_threshold: f32) -> Self {
        Self { mode, threshold, light_threshold, ..self }
    }
}

/// Records the one filter pass of `pcss` or `chun-oh` and reads its counters back.
/// `light_regions` is the light's quadtree table (`chun_oh::light_regions`), 21 `vec4`s.
pub(super) fn run(
    ctx: &mut MethodContext<'_>,
    name: &'static str,
    shader: &'static str,
    uniforms: Uniforms,
    light_regions: &wgpu::Buffer,
) -> FilterCounts {
    let pipeline = ctx.screen_pipeline(
        PipelineKey::new(name),
        shader,
        &[
            layout::storage_texture(0, wgpu::TextureFormat::Rgba32Float),
            layout::uniform(1),
            layout::storage_read(2),
            layout::storage_read_write(3),
        ],
    );
    let device = &ctx.gpu.device;
    let uniform_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("Filter::uniforms"),
        contents: bytemuck::bytes_of(&uniforms),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let counters = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("Filter::counters"),
        contents: &[0; 32],
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("Filter::bind_group"),
        layout: &pipeline.get_bind_group_layout(1),
        entries: &layout::entries(&[
            wgpu::BindingResource::TextureView(ctx.visibility),
            uniform_buffer.as_entire_binding(),
            light_regions.as_entire_binding(),
            counters.as_entire_binding(),
        ]),
    });
    let (gx, gy) = ctx.dispatch_size();
    {
        let mut pass = ctx.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("Filter::pass"),
            timestamp_writes: ctx.timer.compute_scope("method"),
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        pass.set_bind_group(1, &bind_group, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
    }
    ctx.flush();
    let c: Vec<u32> = bytemuck::cast_slice(&read_buffer(ctx.gpu, &counters)).to_vec();
    FilterCounts { levels: [c[0], c[1], c[2]], forced_by_light: c[3], filtered: c[4], covered: c[5] }
}

impl ShadowMethod for Pcss {
    fn name(&self) -> &'static str {
        "pcss"
    }

    fn summary(&self) -> &'static str {
        "Fernando 2005: blocker search, penumbra estimate from light size and blocker/receiver depths, percentage-closer filtering (plain average, gray)"
    }

    fn params(&self) -> &'static [ParamSpec] {
        &FILTER_PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> Counters {
        let uniforms = Uniforms::new(ctx, params);
        // pcss reads no light colours; the binding still needs a table.
        let regions = super::chun_oh::light_regions_buffer(ctx);
        let counts = run(ctx, "pcss", "methods/pcss/pcss.wgsl", uniforms, &regions);
        counts.counters(u64::from(ctx.width) * u64::from(ctx.height))
    }
}
