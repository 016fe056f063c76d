//! The filter pass `pcss` and `chun-oh` share (`shaders/methods/filter.wgsl`): per
//! pixel, a blocker search over the cone from the pixel to the light's four corners cut at
//! the nearest possible occluder depth, a filter sized by the cone cut at the blockers'
//! average depth (Chun & Oh 2016 §3, after Fernando 2005), and a lattice of shadow tests over
//! that filter; with the table of the light image over the filter's quadtree that `chun-oh`
//! weighs its leaves with.
//!
//! Choices where the papers leave room, shared by both so their comparison is fair: the
//! filter is the light's rectangle (its aspect kept), not a square; taps form a regular
//! lattice of (4·`taps_per_cell`)² cell centres (a 4×4 quadtree of cells needs a multiple of
//! 4 per side); each tap is compared with the receiver's tangent plane at that tap, not with
//! the pixel's own depth, so wide filters on tilted receivers do not shadow the receiver
//! itself; and the search region is capped at `max_search_texels`.
//!
//! Orientation: a blocker displaced towards the shadow map's +u (the light's −r side) hides
//! the light's −r side, which contract §1 puts at image column 0: filter column x maps to
//! image columns mirrored, filter row y to image rows as they are (`light_regions`).

use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::{CounterKey, Counters, MethodContext, Param, ParamSpec, Params, BIAS_TEXELS, SLOPE_BIAS_TEXELS};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::DerivedKey;
use crate::light::LightImage;
use crate::timing::PhaseName;

/// Pixels of a row per invocation of the classification (`ROW_PIXELS` in filter.wgsl).
const CLASSIFY_ROW: u32 = 8;

/// Parameters both filter methods take, with the same meaning.
const SEARCH_TAPS: Param<u32> = Param::integer("search_taps", 8, 1, 16, "blocker-search taps per side of the search region");
const TAPS_PER_CELL: Param<u32> = Param::integer(
    "taps_per_cell",
    2,
    1,
    4,
    "filter taps per side of each of the 4×4 quadtree cells: the filter tests (4·this)² shadow-map texels",
);
const MAX_SEARCH_TEXELS: Param<f32> =
    Param::float("max_search_texels", 64.0, 0.5, 1024.0, "cap on the blocker search region's half-width, texels");
const MAX_FILTER_TEXELS: Param<f32> = Param::float("max_filter_texels", 64.0, 0.5, 1024.0, "cap on the filter's half-width, texels");

pub(super) const FILTER_PARAMS: [ParamSpec; 6] =
    [SEARCH_TAPS.spec, TAPS_PER_CELL.spec, MAX_SEARCH_TEXELS.spec, MAX_FILTER_TEXELS.spec, BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec];

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
    map_pitch: u32,
    _pad: u32,
}

/// `mode` values of `filter.wgsl`.
pub(super) const MODE_PCSS: u32 = 0;
pub(super) const MODE_ADAPTIVE: u32 = 1;
pub(super) const MODE_FIXED: u32 = 2;

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

/// Group 1 of the filter's passes (`filter.wgsl`).
const BINDINGS: [wgpu::BindGroupLayoutEntry; 7] = [
    layout::storage_read_write(0),
    layout::uniform(1),
    layout::storage_read(2),
    layout::storage_read_write(3),
    layout::storage_read_write(4),
    layout::storage_read_write(5),
    layout::storage_read_write(6),
];

/// Pixels of the frame no receiver covers.
pub const BACKGROUND_PIXELS: CounterKey = CounterKey("background_pixels");

impl FilterCounts {
    pub fn counters(&self, pixels: u64) -> Counters {
        Counters::from([
            ("pixels_filtered".to_owned(), f64::from(self.filtered)),
            (BACKGROUND_PIXELS.name().to_owned(), (pixels - u64::from(self.covered)) as f64),
        ])
    }
}

impl Uniforms {
    pub fn new(ctx: &MethodContext<'_>, params: &Params) -> Self {
        Self {
            search_taps: params.get(&SEARCH_TAPS),
            lattice: 4 * params.get(&TAPS_PER_CELL),
            max_search_texels: params.get(&MAX_SEARCH_TEXELS),
            max_filter_texels: params.get(&MAX_FILTER_TEXELS),
            bias_texels: params.get(&BIAS_TEXELS),
            slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS),
            nearest: ctx.projection.nearest,
            mode: MODE_PCSS,
            threshold: 0.0,
            light_threshold: 0.0,
            map_pitch: 0, // set by `run`, from the copy it makes
            _pad: 0,
        }
    }

    /// `chun-oh`'s subdivision on top of the shared filter.
    pub fn subdividing(self, mode: u32, threshold: f32, light_threshold: f32) -> Self {
        Self { mode, threshold, light_threshold, ..self }
    }
}

/// Records the filter passes of `pcss` or `chun-oh` (`filter.wgsl`) and reads their counters
/// back: the shadow map copied into a buffer, then the per-pixel pass that lists the covered pixels
/// inside the shadow frustum, and the search and filter over that list alone.
/// `light_regions` is the light's quadtree table (`light_regions`), 21 `vec4`s.
pub(super) fn run(
    ctx: &mut MethodContext<'_>,
    name: &'static str,
    shader: &'static str,
    uniforms: Uniforms,
    light_regions: &wgpu::Buffer,
) -> JobResult<FilterCounts> {
    let mut entry = |entry: &'static str| ctx.screen_entry(name, shader, entry, &BINDINGS);
    let (classify, size, filter) = (entry("classify"), entry("listed_size"), entry("filter_listed"));

    let (map_depth, map_pitch) = ctx.shadow_depth_copy("Filter::map_depth", "filter_copy_map");
    let uniforms = Uniforms { map_pitch, ..uniforms };
    let pixels = u64::from(ctx.width) * u64::from(ctx.height);
    let listed = ctx.pixel_list("Filter", pixels);
    let uniform_buffer = ctx.uniforms("Filter::uniforms", &uniforms);
    let counters = ctx.counters("Filter::counters", 8);
    let bind = |pipeline: &wgpu::ComputePipeline, groups: &wgpu::Buffer| {
        ctx.bind(
            "Filter::bind_group",
            pipeline,
            &[
                ctx.visibility.as_entire_binding(),
                uniform_buffer.as_entire_binding(),
                light_regions.as_entire_binding(),
                counters.as_entire_binding(),
                listed.list.as_entire_binding(),
                groups.as_entire_binding(),
                map_depth.as_entire_binding(),
            ],
        )
    };
    let (classify_group, size_group, filter_group) =
        (bind(&classify, &listed.groups), bind(&size, &listed.groups), bind(&filter, &listed.stand_in));
    let (gx, gy) = ctx.dispatch_size();
    {
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, name);
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        // The classification takes `CLASSIFY_ROW` pixels of a row per invocation.
        pass.set_pipeline(&classify);
        pass.set_bind_group(1, &classify_group, &[]);
        pass.dispatch_workgroups(gx.div_ceil(CLASSIFY_ROW), gy, 1);
        ctx.timer.mark(&mut pass, "filter_classify");
        listed.size_and_walk(
            &mut pass,
            ctx.timer,
            (&size, &size_group),
            (&filter, &filter_group),
            ("filter_listed_size", "filter_search_and_filter"),
        );
    }
    let c = ctx.read_counters(&counters)?;
    Ok(FilterCounts { levels: [c[0], c[1], c[2]], forced_by_light: c[3], filtered: c[4], covered: c[5] })
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

#[cfg(test)]
mod tests {
    use super::*;

    fn builtin(name: &str) -> LightImage {
        LightImage::builtin(name, &Default::default(), "f").unwrap()
    }

    #[test]
    fn the_uniforms_and_bindings_match_the_shader() {
        crate::gpu::shaders::assert_wgsl_layout!(
            Uniforms,
            "methods/pcss.wgsl",
            "FilterParams",
            [
                search_taps,
                lattice,
                max_search_texels,
                max_filter_texels,
                bias_texels,
                slope_bias_texels,
                nearest,
                mode,
                threshold,
                light_threshold,
                map_pitch,
                _pad
            ]
        );
        crate::gpu::shaders::assert_bindings(&["methods/pcss.wgsl", "methods/chun_oh/chun_oh.wgsl"], 1, &BINDINGS);
    }

    #[test]
    fn the_classification_run_matches_the_shader() {
        crate::gpu::shaders::assert_declares("methods/filter.wgsl", &format!("const ROW_PIXELS: u32 = {CLASSIFY_ROW}u;"));
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
