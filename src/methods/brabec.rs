//! Method `brabec`: single-sample soft shadows from depth maps (Brabec & Seidel 2002), on
//! the GPU. The paper's CPU loop is the specification; its passes here are compute shaders
//! under `shaders/methods/brabec/`:
//!
//! The design, and each choice where the paper is vague: docs/methods.md#brabec.

use std::sync::Arc;

use super::{Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod, BIAS_TEXELS, SLOPE_BIAS_TEXELS};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::light::tables::edge_table;
use crate::params::choice;
use crate::render::PixelListBuffers;
use crate::timing::PhaseName;

pub struct Brabec;

const MAX_RADIUS_TEXELS: Param<f32> =
    Param::float("max_radius_texels", 32.0, 1.0, 256.0, "cap on the search radius r_max, shadow-map texels");
const R_SCALE: Param<f32> =
    Param::float("r_scale", -1.0, -1.0, 1e6, "paper's r_scale: texels of r_max per metre of P'z; −1 derives r_max from the light size");
const R_BIAS: Param<f32> = Param::float("r_bias", -1.0, -1.0, 1e4, "paper's r_bias, texels; −1 derives r_max from the light size");
const R_SHRINK: Param<f32> = Param::float(
    "r_shrink",
    -1.0,
    -1.0,
    1e6,
    "paper's r_shrink: texels of r_max per metre of Δz on a hit; −1 derives it from the light size",
);
const MEET: Param<f32> = Param::float("meet", 0.5, 0.05, 0.95, "attenuation where inner and outer penumbra meet (§3.3)");
choice! {
    /// Attenuation across the penumbra.
    enum Falloff { Linear = "linear", Sine = "sine" }
}
choice! {
    /// The Δz of the inner search.
    enum InnerDepth { Blocker = "blocker", Paper = "paper" }
}
const FALLOFF: Param<Falloff> = Param::choice("falloff", "attenuation across the penumbra: linear (paper) or the sinusoid of its §6");
const INNER_DEPTH: Param<InnerDepth> =
    Param::choice("inner_depth", "Δz of the inner search: the occluder over P (no ring) or the paper's depth(lit) − z");
const ADAPTIVE: Param<bool> = Param::boolean("adaptive", true, "adaptive sampling with 4×4 blocks (§4.3); off searches every pixel");
const OBJECT_IDS: Param<bool> = Param::boolean("object_ids", true, "object-id test (§3.2); off shows the self-shadowing it prevents");
const JITTER_TEXELS: Param<f32> =
    Param::float("jitter_texels", 0.0, 0.0, 1.0, "jitter of blocker positions for low-resolution maps (§4.3)");

const PARAMS: &[ParamSpec] = &[
    MAX_RADIUS_TEXELS.spec,
    R_SCALE.spec,
    R_BIAS.spec,
    R_SHRINK.spec,
    MEET.spec,
    FALLOFF.spec,
    INNER_DEPTH.spec,
    ADAPTIVE.spec,
    OBJECT_IDS.spec,
    JITTER_TEXELS.spec,
    BIAS_TEXELS.spec,
    SLOPE_BIAS_TEXELS.spec,
];

/// Laid out as `BrabecParams` in `shaders/methods/brabec/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    r_scale: f32,
    r_bias: f32,
    r_shrink: f32,
    k: f32,
    d_near: f32,
    max_radius: f32,
    meet: f32,
    bias_texels: f32,
    slope_bias_texels: f32,
    jitter: f32,
    falloff: u32,
    inner_depth: u32,
    derived: [u32; 2],
    lattice_stride: u32,
    use_ids: u32,
    colored: u32,
    _pad: [u32; 3],
}

/// Adaptive sampling's block side (§4.3: 4×4 is the paper's speed/quality trade-off).
const BLOCK: u32 = 4;

/// Texels per side of the depth map's summary blocks, which prove searches empty; mirrors
/// `SUMMARY_BLOCK` in `shaders/methods/brabec/common.wgsl` (checked by a test below).
const SUMMARY_BLOCK: u32 = 8;

impl ShadowMethod for Brabec {
    /// The ids seen from the light: the search summaries (`summary.wgsl`) and §4.3's
    /// interpolation key (`pixel_key`).
    fn reads_light_surfaces(&self) -> bool {
        true
    }

    /// The receiver's own id against the ids seen from the light (§3.2's object-id test).
    fn reads_object_ids(&self) -> bool {
        true
    }

    fn name(&self) -> &'static str {
        "brabec"
    }

    fn summary(&self) -> &'static str {
        "Brabec & Seidel 2002: search of the light depth map around the warped point, object ids, inner and outer penumbra, adaptive 4×4 sampling"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let uniforms = Uniforms::new(ctx, params);
        let pipelines = Pipelines::new(ctx, uniforms.jitter > 0.0);
        let buffers = Buffers::new(ctx, &uniforms);
        buffers.record(ctx, &pipelines, uniforms.lattice_stride);
        let raw = ctx.read_counters(&buffers.counters)?;
        let (searches, interpolated, radius_16, shaded, unresolved) = (raw[0], raw[1], raw[2], raw[3], raw[4]);
        let mut counters = Counters::from([
            ("pixels_shaded".to_owned(), f64::from(shaded)),
            ("searches".to_owned(), f64::from(searches)),
            ("pixels_interpolated".to_owned(), f64::from(interpolated)),
            ("searched_fraction".to_owned(), if shaded > 0 { f64::from(searches) / f64::from(shaded) } else { 0.0 }),
            ("avg_search_radius_texels".to_owned(), if searches > 0 { f64::from(radius_16) / 16.0 / f64::from(searches) } else { 0.0 }),
            ("k_texels".to_owned(), f64::from(uniforms.k)),
            ("occluders_thin".to_owned(), super::light_view::thin_occluders(ctx, "brabec", "Brabec & Seidel 2002 §3.2–3.3")),
        ]);
        if unresolved > 0 {
            // Every pixel is on the lattice, searched or interpolated; one that is not is a bug
            // in the passes' order, shown lit and reported rather than hidden.
            tracing::error!(unresolved, "brabec left pixels without a penumbra coordinate");
            counters.insert("pixels_unresolved".to_owned(), f64::from(unresolved));
        }
        Ok(counters)
    }
}

impl Uniforms {
    fn new(ctx: &MethodContext<'_>, params: &Params) -> Self {
        let spec = ctx.spec;
        let light = &spec.light;
        let projection = ctx.projection;
        // The one intuitive parameter the paper asks for (§6): the light's size. A light of
        // width w seen from depth z through a blocker at depth d casts a penumbra of
        // w·(z − d)/d metres, i.e. k·(z − d)/(z·d) texels with k = w·res/(2·tan half-angle);
        // the outer half of it is what the outer search measures. w is the side of the square
        // of the light's area (the search is circular).
        let width_m = (light.size_m.x * light.size_m.y).sqrt();
        let k = width_m * spec.shadow_resolution as f32 / (2.0 * projection.tan_half);
        let derived_search = params.get(&R_SCALE) < 0.0 && params.get(&R_BIAS) < 0.0;
        let derived_hit = params.get(&R_SHRINK) < 0.0;
        Self {
            r_scale: params.get(&R_SCALE).max(0.0),
            r_bias: params.get(&R_BIAS).max(0.0),
            r_shrink: params.get(&R_SHRINK).max(0.0),
            k,
            d_near: projection.nearest,
            max_radius: params.get(&MAX_RADIUS_TEXELS),
            meet: params.get(&MEET),
            bias_texels: params.get(&BIAS_TEXELS),
            slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS),
            jitter: params.get(&JITTER_TEXELS),
            falloff: match params.get(&FALLOFF) {
                Falloff::Linear => 0,
                Falloff::Sine => 1,
            },
            inner_depth: match params.get(&INNER_DEPTH) {
                InnerDepth::Blocker => 0,
                InnerDepth::Paper => 1,
            },
            derived: [u32::from(derived_search), u32::from(derived_hit)],
            lattice_stride: if params.get(&ADAPTIVE) { BLOCK } else { 1 },
            use_ids: u32::from(params.get(&OBJECT_IDS)),
            colored: u32::from(!spec.light_image.is_uniform()),
            _pad: [0; 3],
        }
    }
}

/// Group 1 of every pass (`common.wgsl`).
const BINDINGS: [wgpu::BindGroupLayoutEntry; 9] = [
    layout::uniform(0),
    layout::storage_read_write(1),
    layout::storage_read_write(2),
    layout::storage_read_write(3),
    layout::storage_read(4),
    layout::storage_read_write(5),
    layout::storage_read_write(6),
    layout::storage_read_write(7),
    layout::storage_read_write(8),
];

/// The passes, in the order of the module's list.
struct Pipelines {
    summarize: Arc<wgpu::ComputePipeline>,
    classify: Arc<wgpu::ComputePipeline>,
    lattice: Arc<wgpu::ComputePipeline>,
    /// Before the search: the refinement's listing along columns, then rows, and the size of
    /// the search's dispatch.
    mark_columns: Arc<wgpu::ComputePipeline>,
    mark_rows: Arc<wgpu::ComputePipeline>,
    list_size: Arc<wgpu::ComputePipeline>,
    search: Arc<wgpu::ComputePipeline>,
    /// After it: the refinement's interpolation along columns, then rows.
    columns: Arc<wgpu::ComputePipeline>,
    rows: Arc<wgpu::ComputePipeline>,
    finish: Arc<wgpu::ComputePipeline>,
}

impl Pipelines {
    fn new(ctx: &mut MethodContext<'_>, jittered: bool) -> Self {
        let mut pipeline = |name, shader| ctx.screen_pipeline(name, shader, &BINDINGS);
        let (summarize, classify, lattice) = (
            pipeline("brabec.summary", "methods/brabec/summary.wgsl"),
            pipeline("brabec.classify", "methods/brabec/classify.wgsl"),
            pipeline("brabec.lattice", "methods/brabec/lattice.wgsl"),
        );
        let finish = pipeline("brabec.finish", "methods/brabec/finish.wgsl");
        // The refinement along columns, then rows: one shader, its direction a constant
        // (`refine.wgsl`), each before the search (listing) and after it (interpolating).
        let mut refine = |name, entry, along_rows: bool| {
            let constants = [("ALONG_ROWS", f64::from(u8::from(along_rows)))];
            ctx.screen_specialized(name, ("methods/brabec/refine.wgsl", entry), &BINDINGS, &constants)
        };
        let (mark_columns, mark_rows) =
            (refine("brabec.columns.mark", "mark_searches", false), refine("brabec.rows.mark", "mark_searches", true));
        let (columns, rows) = (refine("brabec.columns", "main", false), refine("brabec.rows", "main", true));
        let mut entry = |name, shader, entry| ctx.screen_entry(name, shader, entry, &BINDINGS);
        // The jitter's hash is compiled out of the search unless asked for (`search.wgsl`).
        let (search_key, search_entry) =
            if jittered { ("brabec.search.jittered", "search_listed_jittered") } else { ("brabec.search", "search_listed") };
        Self {
            mark_columns,
            mark_rows,
            list_size: entry("brabec.search.size", "methods/brabec/search.wgsl", "listed_size"),
            search: entry(search_key, "methods/brabec/search.wgsl", search_entry),
            summarize,
            classify,
            lattice,
            columns,
            rows,
            finish,
        }
    }
}

/// What the passes bind in group 1 (`common.wgsl`).
struct Buffers {
    uniforms: wgpu::Buffer,
    /// Every pixel's state: `classify` writes it all.
    state: wgpu::Buffer,
    /// Searches, pixels interpolated, summed search radius, pixels shaded, pixels unresolved.
    counters: wgpu::Buffer,
    /// The light's edge table (`light::tables`); a stand-in under a uniform light, whose
    /// colours are its gray level.
    edges: Arc<wgpu::Buffer>,
    /// Per 8×8 block of the light's map its depth range and id, and the map's texels.
    summary: wgpu::Buffer,
    map_texels: wgpu::Buffer,
    summary_side: u32,
    /// The pixels to search, and the search's dispatch over them.
    to_search: PixelListBuffers,
}

impl Buffers {
    fn new(ctx: &mut MethodContext<'_>, uniforms: &Uniforms) -> Self {
        let resolution = ctx.spec.shadow_resolution;
        let pixels = u64::from(ctx.width) * u64::from(ctx.height);
        let uniforms_buffer = ctx.uniforms("Brabec::uniforms", uniforms);
        // From the pool: `classify` writes every pixel's state, `summary` every block and texel.
        let state = ctx.scratch_buffer("Brabec::state", pixels * 24, wgpu::BufferUsages::STORAGE);
        let counters = ctx.counters("Brabec::counters", 5);
        let summary_side = resolution.div_ceil(SUMMARY_BLOCK);
        let summary = ctx.scratch_buffer("Brabec::summary", u64::from(summary_side).pow(2) * 16, wgpu::BufferUsages::STORAGE);
        let map_texels = ctx.scratch_buffer("Brabec::map_texels", u64::from(resolution).pow(2) * 8, wgpu::BufferUsages::STORAGE);
        let edges =
            if uniforms.colored == 1 { ctx.light_table("edge_table", edge_table) } else { Arc::new(ctx.counters("Brabec::no_table", 4)) };
        let to_search = ctx.pixel_list("Brabec", pixels);
        Self { uniforms: uniforms_buffer, state, counters, edges, summary, map_texels, summary_side, to_search }
    }

    /// Group 1, with the search's dispatch grid bound as `groups` (its stand-in while the
    /// search reads the grid).
    fn bind(&self, ctx: &MethodContext<'_>, pipelines: &Pipelines, groups: &wgpu::Buffer) -> wgpu::BindGroup {
        ctx.bind(
            "Brabec::bind_group",
            &pipelines.classify,
            &[
                self.uniforms.as_entire_binding(),
                self.state.as_entire_binding(),
                self.counters.as_entire_binding(),
                ctx.visibility.as_entire_binding(),
                self.edges.as_entire_binding(),
                self.summary.as_entire_binding(),
                self.to_search.list.as_entire_binding(),
                groups.as_entire_binding(),
                self.map_texels.as_entire_binding(),
            ],
        )
    }

    /// Records the passes: with adaptive sampling (a lattice `stride` of `BLOCK`) the
    /// refinement along columns and rows, without it (stride 1) a search at every pixel.
    fn record(&self, ctx: &mut MethodContext<'_>, pipelines: &Pipelines, stride: u32) {
        let (bind_group, search_group) =
            (self.bind(ctx, pipelines, &self.to_search.groups), self.bind(ctx, pipelines, &self.to_search.stand_in));
        let (w, h) = (ctx.width, ctx.height);
        let lattice_size = ((w - 1) / stride + 2, (h - 1) / stride + 2);
        let line_groups = |n: u32| (n + 2) / BLOCK;
        let column_count = (w - 1) / BLOCK + 1 + u32::from((w - 1) % BLOCK != 0);
        let column_groups = ((column_count * line_groups(h)).div_ceil(64), 1);
        let row_groups = ((h * line_groups(w)).div_ceil(64), 1);
        let side = self.summary_side;
        // Which pixels are searched depends on the keys alone: the lattice and the refinement
        // list them first, one compacted pass searches them all, then the refinement
        // interpolates (`refine` in common.wgsl says why).
        let mut listing = vec![
            ("brabec_summary", &pipelines.summarize, (side.div_ceil(8), side.div_ceil(8))),
            ("brabec_classify", &pipelines.classify, (w.div_ceil(8), h.div_ceil(8))),
            ("brabec_lattice", &pipelines.lattice, (lattice_size.0.div_ceil(8), lattice_size.1.div_ceil(8))),
        ];
        let mut interpolation = vec![];
        if stride == BLOCK {
            listing.extend([
                ("brabec_list_columns", &pipelines.mark_columns, column_groups),
                ("brabec_list_rows", &pipelines.mark_rows, row_groups),
            ]);
            interpolation.extend([("brabec_columns", &pipelines.columns, column_groups), ("brabec_rows", &pipelines.rows, row_groups)]);
        }
        listing.push(("brabec_search_size", &pipelines.list_size, (1, 1)));
        interpolation.push(("brabec_finish", &pipelines.finish, (w.div_ceil(8), h.div_ceil(8))));
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, "Brabec::passes");
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        pass.set_bind_group(1, &bind_group, &[]);
        for (name, pipeline, (x, y)) in listing {
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups(x, y, 1);
            ctx.timer.mark(&mut pass, name);
        }
        pass.set_pipeline(&pipelines.search);
        pass.set_bind_group(1, &search_group, &[]);
        self.to_search.walk(&mut pass, ctx.timer, "brabec_search");
        pass.set_bind_group(1, &bind_group, &[]);
        for (name, pipeline, (x, y)) in interpolation {
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups(x, y, 1);
            ctx.timer.mark(&mut pass, name);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_uniforms_and_bindings_match_the_shaders() {
        crate::gpu::shaders::assert_wgsl_layout!(
            Uniforms,
            "methods/brabec/common.wgsl",
            "BrabecParams",
            [
                r_scale,
                r_bias,
                r_shrink,
                k,
                d_near,
                max_radius,
                meet,
                bias_texels,
                slope_bias_texels,
                jitter,
                falloff,
                inner_depth,
                derived,
                lattice_stride,
                use_ids,
                colored,
                _pad
            ]
        );
        let shaders = ["summary", "classify", "lattice", "refine", "search", "finish"].map(|s| format!("methods/brabec/{s}.wgsl"));
        crate::gpu::shaders::assert_bindings(&shaders.each_ref().map(String::as_str), 1, &BINDINGS);
    }

    #[test]
    fn the_summary_block_matches_its_wgsl_mirror() {
        let declaration = format!("const SUMMARY_BLOCK: i32 = {};", super::SUMMARY_BLOCK);
        crate::gpu::shaders::assert_declares("methods/brabec/common.wgsl", &declaration);
    }
}
