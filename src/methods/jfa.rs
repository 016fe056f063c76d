//! Methods `jfa-l` and `jfa-e`: soft shadows by jump flooding (Rong & Tan 2006) in light
//! space (§4) and in eye space (§5), with the intensity look-up of §3 made coloured
//! (`light::tables`). Shaders: `shaders/methods/jfa/`. Both share one pass driver (`flood`): seed,
//! `rounds` rounds of flooding between two record buffers, final pass.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#jfa-l-and-jfa-e.

use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::{Cap, Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod, BIAS_TEXELS, SLOPE_BIAS_TEXELS};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;
use crate::light::tables::{edge_table, key_table};
use crate::render::PixelListBuffers;

pub struct JfaL;
pub struct JfaE;

const ROUNDS: Param<u32> = Param::integer(
    "rounds",
    6,
    1,
    13,
    "jump-flooding rounds: occluders travel up to 2^rounds − 1 pixels (log2 of the resolution floods fully)",
)
.capped(Cap::Rounds);
const FLOODING: Param<&str> = Param::choice(
    "flooding",
    "jump",
    &["jump", "standard"],
    "jump flooding, or standard flooding (step 1, 2^rounds − 1 rounds) for the paper's experiment",
);

const SILHOUETTE_RELATIVE: Param<f32> = Param::float(
    "silhouette_relative",
    0.01,
    0.0,
    1.0,
    "a shadow-map neighbour deeper by more than depth × this lies beyond a silhouette (jfa-l's seeds; both methods' edge directions)",
);
const BOUNDARY_RELATIVE: Param<f32> = Param::float(
    "boundary_relative",
    0.02,
    0.0,
    1.0,
    "a lit neighbour closer in 3D than view depth × this makes a hard-shadow pixel a boundary pixel",
);
const SAME_OBJECT: Param<bool> = Param::boolean("same_object", true, "§5.2 remedy: flood only to pixels of the boundary pixel's object");
const MIDPOINT: Param<bool> =
    Param::boolean("midpoint", true, "§5.2 remedy: the midpoint towards the boundary pixel must already be in a penumbra");

const EDGE_MODEL: Param<&str> = Param::choice(
    "edge",
    "silhouette",
    &["silhouette", "paper"],
    "the occluder edge that bounds the visible light: the silhouette's own direction at the occluder point, or the paper's line orthogonal to c→q (§3)",
);
const INNER: Param<bool> = Param::boolean(
    "inner",
    true,
    "inner penumbra: silhouettes flood into the occluders' footprints and hard-shadowed pixels take their intensity (past the paper; false is the paper's outer penumbra only)",
);

const PARAMS_L: &[ParamSpec] =
    &[ROUNDS.spec, FLOODING.spec, SILHOUETTE_RELATIVE.spec, EDGE_MODEL.spec, INNER.spec, BIAS_TEXELS.spec, SLOPE_BIAS_TEXELS.spec];

const PARAMS_E: &[ParamSpec] = &[
    ROUNDS.spec,
    FLOODING.spec,
    BOUNDARY_RELATIVE.spec,
    SAME_OBJECT.spec,
    MIDPOINT.spec,
    SILHOUETTE_RELATIVE.spec,
    EDGE_MODEL.spec,
    BIAS_TEXELS.spec,
    SLOPE_BIAS_TEXELS.spec,
];

/// Laid out as `JfaParams` in `shaders/methods/jfa/common.wgsl`, one 256-byte slot per pass.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    step: i32,
    silhouette_relative: f32,
    bias_texels: f32,
    slope_bias_texels: f32,
    boundary_relative: f32,
    same_object: u32,
    midpoint: u32,
    light_space: u32,
    edge_model: u32,
    inner: u32,
    map_pitch: u32,
    _pad: u32,
}

/// The flood's workgroups are `TILE`² cells (`TILE` in `neighbours.wgsl`).
const TILE: u32 = 8;
/// Texels per invocation of jfa-l's silhouette pass (`ROW_TEXELS` in silhouette.wgsl).
const SILHOUETTE_ROW: u32 = 4;
/// Pixels per invocation of both final passes' `main` (`ROW_PIXELS` in shading.wgsl).
const FINAL_ROW: u32 = 8;

/// The step lengths of the flood: 2^(rounds−1) … 1, or 1 repeated for standard flooding.
pub fn steps(rounds: u32, standard: bool) -> Vec<i32> {
    if standard {
        vec![1; (1usize << rounds) - 1]
    } else {
        (0..rounds).rev().map(|k| 1 << k).collect()
    }
}

/// Which flood: the grid it runs over and its three shaders.
struct Flood {
    name: &'static str,
    seed: (&'static str, &'static str),
    round: (&'static str, &'static str),
    finish: (&'static str, &'static str),
    light_space: bool,
    /// Bytes of one cell's record (`common.wgsl`): an occluder, plus its origin for jfa-e.
    record_bytes: u64,
}

const LIGHT_SPACE: Flood = Flood {
    name: "jfa-l",
    seed: ("jfa-l.silhouette", "methods/jfa/silhouette.wgsl"),
    round: ("jfa-l.flood", "methods/jfa/flood_light.wgsl"),
    finish: ("jfa-l.final", "methods/jfa/final_light.wgsl"),
    light_space: true,
    record_bytes: 16,
};

const EYE_SPACE: Flood = Flood {
    name: "jfa-e",
    seed: ("jfa-e.boundary", "methods/jfa/boundary.wgsl"),
    round: ("jfa-e.flood", "methods/jfa/flood_eye.wgsl"),
    finish: ("jfa-e.final", "methods/jfa/final_eye.wgsl"),
    light_space: false,
    record_bytes: 32,
};

impl ShadowMethod for JfaL {
    fn name(&self) -> &'static str {
        LIGHT_SPACE.name
    }

    fn summary(&self) -> &'static str {
        "Rong & Tan 2006 §4: silhouette pixels in the shadow map, jump flooding of occluders in light space, intensity by ray to the light through the coloured edge table; outer penumbra, and the inner one past the paper"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS_L
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let uniforms = Uniforms { inner: u32::from(params.get(&INNER)), ..common_uniforms(params) };
        let (seeds, penumbra, steps, flooded) = flood(ctx, &LIGHT_SPACE, params, uniforms)?;
        Ok(Counters::from([
            ("occluders_thin".to_owned(), super::light_view::thin_occluders(ctx, "jfa-l", "Rong & Tan 2006 §3, §4.1")),
            ("rounds".to_owned(), steps.len() as f64),
            ("max_reach_texels".to_owned(), f64::from(steps.iter().sum::<i32>())),
            ("silhouette_texels".to_owned(), f64::from(seeds)),
            ("penumbra_pixels".to_owned(), f64::from(penumbra)),
            ("flooded_tile_fraction".to_owned(), flooded),
        ]))
    }
}

impl ShadowMethod for JfaE {
    fn name(&self) -> &'static str {
        EYE_SPACE.name
    }

    /// The boundary and the flood compare object ids (§5's check against jumping too far).
    fn reads_object_ids(&self) -> bool {
        true
    }

    fn summary(&self) -> &'static str {
        "Rong & Tan 2006 §5: hard shadows with 3D positions, boundary pixels, eye-space jump flooding for inner and outer penumbrae, object-id and midpoint checks against jumping too far"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS_E
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        let uniforms = Uniforms {
            boundary_relative: params.get(&BOUNDARY_RELATIVE),
            same_object: u32::from(params.get(&SAME_OBJECT)),
            midpoint: u32::from(params.get(&MIDPOINT)),
            ..common_uniforms(params)
        };
        let (seeds, penumbra, steps, flooded) = flood(ctx, &EYE_SPACE, params, uniforms)?;
        Ok(Counters::from([
            ("occluders_thin".to_owned(), super::light_view::thin_occluders(ctx, "jfa-e", "Rong & Tan 2006 §3, §5.1")),
            ("rounds".to_owned(), steps.len() as f64),
            ("max_reach_pixels".to_owned(), f64::from(steps.iter().sum::<i32>())),
            ("boundary_pixels".to_owned(), f64::from(seeds)),
            ("penumbra_pixels".to_owned(), f64::from(penumbra)),
            ("flooded_tile_fraction".to_owned(), flooded),
        ]))
    }
}

fn common_uniforms(params: &Params) -> Uniforms {
    Uniforms {
        step: 0,
        silhouette_relative: params.get(&SILHOUETTE_RELATIVE),
        bias_texels: params.get(&BIAS_TEXELS),
        slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS),
        boundary_relative: 0.0,
        same_object: 0,
        midpoint: 0,
        light_space: 0,
        edge_model: u32::from(params.get(&EDGE_MODEL) == "silhouette"),
        inner: 0,
        map_pitch: 0,
        _pad: 0,
    }
}

/// Seeds, floods and shades; returns (seeds, penumbra pixels, step lengths, the fraction of
/// tiles the rounds flooded rather than skipped).
fn flood(ctx: &mut MethodContext<'_>, which: &Flood, params: &Params, base: Uniforms) -> JobResult<(u32, u32, Vec<i32>, f64)> {
    let grid = if which.light_space { (ctx.spec.shadow_resolution, ctx.spec.shadow_resolution) } else { (ctx.width, ctx.height) };
    let steps = steps(params.get(&ROUNDS), params.get(&FLOODING) == "standard");
    // The shadow map's depths, which the seeds, the rounds and the hard-shadow test read.
    let (map_depth, map_pitch) = ctx.shadow_depth_copy("Jfa::map_depth", "jfa_copy_map");
    let base = Uniforms { light_space: u32::from(which.light_space), map_pitch, ..base };
    // Slot 0: seed and final pass; slots 1…: one per round.
    let slots: Vec<Uniforms> = std::iter::once(0).chain(steps.iter().copied()).map(|step| Uniforms { step, ..base }).collect();
    let buffers = FloodBuffers::new(ctx, which, grid, map_depth, &slots);
    let pipelines = FloodPipelines::new(ctx, which);
    buffers.record(ctx, which, &pipelines, grid, steps.len());
    let counts = ctx.read_counters(&buffers.counters)?;
    let flooded = f64::from(counts[2]) / (f64::from(buffers.tile_count) * steps.len() as f64);
    Ok((counts[0], counts[1], steps, flooded))
}

/// Group 1 of every pass of a flood (`common.wgsl`).
const BINDINGS: [wgpu::BindGroupLayoutEntry; 16] = [
    layout::uniform_dynamic(0),
    layout::storage_read(1),
    layout::storage_read(2),
    layout::storage_read_write(3),
    layout::storage_read_write(4),
    layout::storage_read_write(5),
    layout::storage_read_write(6),
    layout::storage_read_write(7),
    layout::storage_read_write(8),
    layout::storage_read_write(9),
    layout::storage_read_write(10),
    layout::storage_read_write(11),
    layout::storage_read_write(12),
    layout::storage_read_write(13),
    layout::storage_read(14),
    layout::storage_read(15),
];

/// A flood's passes: the seeds, per round the listing of the tiles a record may reach and
/// the round itself, the final pass and its compacted shading.
struct FloodPipelines {
    seed: Arc<wgpu::ComputePipeline>,
    /// jfa-e lists its boundary pixels and seeds them in a compacted pass (boundary.wgsl):
    /// mark, size the dispatch, seed.
    boundary: Option<[Arc<wgpu::ComputePipeline>; 3]>,
    round: Arc<wgpu::ComputePipeline>,
    /// Each round runs over the tiles a record may reach, listed just before it
    /// (common.wgsl): list, size the dispatch, reset the list.
    tile_passes: [Arc<wgpu::ComputePipeline>; 3],
    finish: Arc<wgpu::ComputePipeline>,
    /// The final pass lists the pixels it shades by an occluder and shades them in a
    /// compacted pass (final_light.wgsl, final_eye.wgsl): size the dispatch, shade.
    shading: [Arc<wgpu::ComputePipeline>; 2],
}

impl FloodPipelines {
    fn new(ctx: &mut MethodContext<'_>, which: &Flood) -> Self {
        let seed = ctx.screen_pipeline(PipelineKey::new(which.seed.0), which.seed.1, &BINDINGS);
        let boundary = (!which.light_space).then(|| {
            let mut entry = |name, entry| ctx.screen_entry(PipelineKey::new(name), which.seed.1, entry, &BINDINGS);
            [
                entry("jfa-e.boundary.mark", "mark_boundary"),
                entry("jfa-e.boundary.size", "boundary_size"),
                entry("jfa-e.boundary.seed", "seed_listed"),
            ]
        });
        let round = ctx.screen_pipeline(PipelineKey::new(which.round.0), which.round.1, &BINDINGS);
        let tile_passes = [(1, "list_tiles"), (2, "tiles_size"), (3, "tiles_reset")]
            .map(|(variant, entry)| ctx.screen_entry(PipelineKey { name: which.round.0, variant }, which.round.1, entry, &BINDINGS));
        let finish = ctx.screen_pipeline(PipelineKey::new(which.finish.0), which.finish.1, &BINDINGS);
        let shading = [(1, "shaded_size"), (2, "shade_listed")]
            .map(|(variant, entry)| ctx.screen_entry(PipelineKey { name: which.finish.0, variant }, which.finish.1, entry, &BINDINGS));
        Self { seed, boundary, round, tile_passes, finish, shading }
    }
}

/// What a flood's passes bind in group 1 (`common.wgsl`).
struct FloodBuffers {
    /// `Uniforms`, slot 0 for the seed and final passes, then one per round.
    uniforms: wgpu::Buffer,
    /// The coloured edge table and the rounds' table of keys made from it (`light::tables`).
    lut: Arc<wgpu::Buffer>,
    keys: Arc<wgpu::Buffer>,
    /// The two record buffers the rounds ping-pong between.
    a: wgpu::Buffer,
    b: wgpu::Buffer,
    /// jfa-e's per-pixel flags.
    flags: wgpu::Buffer,
    /// Per tile, whether a record may reach it.
    tiles: wgpu::Buffer,
    tile_count: u32,
    /// Seeds, penumbra pixels and tiles flooded, counted on the GPU.
    counters: wgpu::Buffer,
    /// jfa-e's boundary pixels, the tiles of a round, the pixels the final pass shades.
    listed: PixelListBuffers,
    tile_list: PixelListBuffers,
    shaded: PixelListBuffers,
    map_depth: wgpu::Buffer,
}

impl FloodBuffers {
    fn new(ctx: &mut MethodContext<'_>, which: &Flood, grid: (u32, u32), map_depth: wgpu::Buffer, slots: &[Uniforms]) -> Self {
        let device = ctx.gpu.device.clone();
        let uniforms = layout::uniform_slots(&device, "Jfa::uniforms", slots);
        // The coloured look-up depends only on the light image and the light's shape; building it
        // integrates ~6·10⁴ samples per direction on the CPU, so it is kept for later jobs, and
        // the rounds' table of keys is made from it (built once here when neither is kept).
        let mut colours = None;
        let lut = ctx.light_table("edge_table", |light, image| colours.get_or_insert_with(|| edge_table(light, image)).clone());
        let keys = ctx.light_table("jfa_keys", |light, image| key_table(light, colours.get_or_insert_with(|| edge_table(light, image))));
        // From the pool: jfa-e's flags pass writes every flag; the records and the tile flags are
        // cleared before the passes (`record`).
        let cells = u64::from(grid.0) * u64::from(grid.1);
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let a = ctx.scratch_buffer("Jfa::records_a", cells * which.record_bytes, storage);
        let b = ctx.scratch_buffer("Jfa::records_b", cells * which.record_bytes, storage);
        // Only jfa-e keeps per-pixel flags.
        let flags = ctx.scratch_buffer("Jfa::flags", if which.light_space { 4 } else { cells * 4 }, storage);
        let tile_count = grid.0.div_ceil(TILE) * grid.1.div_ceil(TILE);
        let tiles = ctx.scratch_buffer("Jfa::tiles", u64::from(tile_count) * 4, storage);
        let counters = ctx.counters("Jfa::counters", 4);
        let listed = PixelListBuffers::new(&device, ctx.encoder, "Jfa::boundary", if which.light_space { 0 } else { cells });
        let tile_list = PixelListBuffers::new(&device, ctx.encoder, "Jfa::tile_list", u64::from(tile_count));
        let shaded = PixelListBuffers::new(&device, ctx.encoder, "Jfa::shaded", u64::from(ctx.width) * u64::from(ctx.height));
        Self { uniforms, lut, keys, a, b, flags, tiles, tile_count, counters, listed, tile_list, shaded, map_depth }
    }

    /// Group 1 with records read from `src` and written to `dst`, and each pixel list's
    /// dispatch grid bound where given (its stand-in while a dispatch reads the grid).
    fn bind(
        &self,
        ctx: &MethodContext<'_>,
        pipelines: &FloodPipelines,
        (src, dst): (&wgpu::Buffer, &wgpu::Buffer),
        [listed_groups, shaded_groups, tile_groups]: [&wgpu::Buffer; 3],
    ) -> wgpu::BindGroup {
        ctx.bind(
            "Jfa::bind_group",
            &pipelines.seed,
            &[
                layout::slot_binding::<Uniforms>(&self.uniforms),
                self.lut.as_entire_binding(),
                src.as_entire_binding(),
                dst.as_entire_binding(),
                ctx.visibility.as_entire_binding(),
                self.counters.as_entire_binding(),
                self.flags.as_entire_binding(),
                self.tiles.as_entire_binding(),
                self.listed.list.as_entire_binding(),
                listed_groups.as_entire_binding(),
                self.shaded.list.as_entire_binding(),
                shaded_groups.as_entire_binding(),
                self.tile_list.list.as_entire_binding(),
                tile_groups.as_entire_binding(),
                self.map_depth.as_entire_binding(),
                self.keys.as_entire_binding(),
            ],
        )
    }

    /// Records the seeds, `rounds` rounds and the final pass over a `grid` of cells.
    fn record(&self, ctx: &mut MethodContext<'_>, which: &Flood, pipelines: &FloodPipelines, grid: (u32, u32), rounds: usize) {
        let (a, b) = (&self.a, &self.b);
        let (listed, shaded, tile_list) = (&self.listed, &self.shaded, &self.tile_list);
        let grids = [&listed.groups, &shaded.groups, &tile_list.groups];
        // Ping-pong: `a_to_b` reads a and writes b, `b_to_a` the reverse.
        let (a_to_b, b_to_a) = (self.bind(ctx, pipelines, (a, b), grids), self.bind(ctx, pipelines, (b, a), grids));
        // The boundary seeds write a (as the seed pass does), the indirect grid bound as its stand-in.
        let seeding = self.bind(ctx, pipelines, (b, a), [&listed.stand_in, &shaded.groups, &tile_list.groups]);
        // The seeds are in a and each round reads the other buffer: the final passes read a after
        // an even number of rounds.
        let result_in_a = rounds.is_multiple_of(2);
        let final_pair = if result_in_a { (a, b) } else { (b, a) };
        let final_shading = self.bind(ctx, pipelines, final_pair, [&listed.groups, &shaded.stand_in, &tile_list.groups]);
        // The rounds themselves, with the tile list's grid bound as its stand-in.
        let round_grids = [&listed.groups, &shaded.groups, &tile_list.stand_in];
        let (round_a_to_b, round_b_to_a) = (self.bind(ctx, pipelines, (a, b), round_grids), self.bind(ctx, pipelines, (b, a), round_grids));
        // Rounds run over the tiles a record can reach (listed before each round) and leave the
        // others' cells as they are, so both record buffers start empty (all zero) and the tile
        // flags start clear; the seeds are stored in a over its empty records (silhouette.wgsl,
        // boundary.wgsl).
        ctx.encoder.clear_buffer(a, 0, None);
        ctx.encoder.clear_buffer(b, 0, None);
        ctx.encoder.clear_buffer(&self.tiles, 0, None);
        let groups = (grid.0.div_ceil(TILE), grid.1.div_ceil(TILE));
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, "method", "Jfa::passes");
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        // Seeds go to a. jfa-l's silhouette pass takes `SILHOUETTE_ROW` texels per invocation.
        pass.set_pipeline(&pipelines.seed);
        pass.set_bind_group(1, &b_to_a, &[0]);
        let across = if which.light_space { groups.0.div_ceil(SILHOUETTE_ROW) } else { groups.0 };
        pass.dispatch_workgroups(across, groups.1, 1);
        ctx.timer.mark(&mut pass, "jfa_seed");
        if let Some([mark, size, seed_listed]) = &pipelines.boundary {
            for (name, pipeline, (x, y)) in [("jfa_boundary", mark, groups), ("jfa_boundary_size", size, (1, 1))] {
                pass.set_pipeline(pipeline);
                pass.dispatch_workgroups(x, y, 1);
                ctx.timer.mark(&mut pass, name);
            }
            pass.set_pipeline(seed_listed);
            pass.set_bind_group(1, &seeding, &[0]);
            pass.dispatch_workgroups_indirect(&listed.groups, 0);
            ctx.timer.mark(&mut pass, "jfa_seed_boundary");
        }
        let [list_tiles, tiles_size, tiles_reset] = &pipelines.tile_passes;
        for k in 0..rounds {
            let offset = layout::slot_offset(k + 1);
            let (listing, flooding) = if k.is_multiple_of(2) { (&a_to_b, &round_a_to_b) } else { (&b_to_a, &round_b_to_a) };
            pass.set_bind_group(1, listing, &[offset]);
            pass.set_pipeline(list_tiles);
            pass.dispatch_workgroups(groups.0.div_ceil(8), groups.1.div_ceil(8), 1);
            pass.set_pipeline(tiles_size);
            pass.dispatch_workgroups(1, 1, 1);
            ctx.timer.mark(&mut pass, "jfa_list_tiles");
            pass.set_pipeline(&pipelines.round);
            pass.set_bind_group(1, flooding, &[offset]);
            pass.dispatch_workgroups_indirect(&tile_list.groups, 0);
            ctx.timer.mark(&mut pass, "jfa_rounds");
            pass.set_pipeline(tiles_reset);
            pass.set_bind_group(1, listing, &[offset]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        pass.set_pipeline(&pipelines.finish);
        pass.set_bind_group(1, if result_in_a { &a_to_b } else { &b_to_a }, &[0]);
        // 8 × 8 invocations a workgroup, each a run of `FINAL_ROW` pixels.
        pass.dispatch_workgroups(ctx.width.div_ceil(8 * FINAL_ROW), ctx.height.div_ceil(8), 1);
        ctx.timer.mark(&mut pass, "jfa_final");
        let [size, shade] = &pipelines.shading;
        pass.set_pipeline(size);
        pass.dispatch_workgroups(1, 1, 1);
        ctx.timer.mark(&mut pass, "jfa_shaded_size");
        pass.set_pipeline(shade);
        pass.set_bind_group(1, &final_shading, &[0]);
        pass.dispatch_workgroups_indirect(&shaded.groups, 0);
        ctx.timer.mark(&mut pass, "jfa_shade");
    }
}

/// Jump flooding of nearest seeds over a `size`² grid: the Voronoi diagram the flooding pattern
/// approximates (Rong & Tan 2006 §3). Returns, per cell, the index of the seed it ended with
/// (−1 for none). It runs `voronoi.wgsl`, which shares `jump_neighbour` with the shadow
/// methods' floods, so testing it against brute force tests their communication pattern.
pub fn voronoi(
    gpu: &crate::gpu::GpuContext,
    size: u32,
    seeds: &[(u32, u32)],
    rounds: u32,
    standard: bool,
) -> Result<Vec<i32>, crate::gpu::GpuError> {
    let device = &gpu.device;
    let steps = steps(rounds, standard);
    // `VoronoiParams` in `voronoi.wgsl`: step, grid size (both non-negative, so i32 bits do).
    let slots: Vec<[i32; 2]> = steps.iter().map(|&step| [step, size as i32]).collect();
    let uniforms = layout::uniform_slots(device, "Voronoi::uniforms", &slots);
    let seed_coords: Vec<[i32; 2]> = seeds.iter().map(|&(x, y)| [x as i32, y as i32]).collect();
    let seed_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("Voronoi::seeds"),
        contents: bytemuck::cast_slice(&seed_coords),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let mut initial = vec![-1i32; (size * size) as usize];
    for (k, &(x, y)) in seeds.iter().enumerate() {
        initial[(y * size + x) as usize] = k as i32;
    }
    let cells = |label| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(&initial),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        })
    };
    let (a, b) = (cells("Voronoi::cells_a"), cells("Voronoi::cells_b"));
    let tiles_across = size.div_ceil(TILE);
    let mut tile_flags = vec![0u32; (tiles_across * tiles_across) as usize];
    for &(x, y) in seeds {
        tile_flags[(y / TILE * tiles_across + x / TILE) as usize] = 1;
    }
    let tiles = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("Voronoi::tiles"),
        contents: bytemuck::cast_slice(&tile_flags),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("Voronoi::layout"),
        entries: &[
            layout::uniform_dynamic(0),
            layout::storage_read(1),
            layout::storage_read(2),
            layout::storage_read_write(3),
            layout::storage_read_write(4),
        ],
    });
    let pipeline =
        crate::gpu::shaders::compute_pipeline(device, "Voronoi::pipeline", ("methods/jfa/voronoi.wgsl", "main"), &[&bind_layout], &[]);
    let group = |src: &wgpu::Buffer, dst: &wgpu::Buffer| {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Voronoi::bind_group"),
            layout: &bind_layout,
            entries: &layout::entries(&[
                layout::slot_binding::<[i32; 2]>(&uniforms),
                seed_buffer.as_entire_binding(),
                src.as_entire_binding(),
                dst.as_entire_binding(),
                tiles.as_entire_binding(),
            ]),
        })
    };
    let (a_to_b, b_to_a) = (group(&a, &b), group(&b, &a));
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Voronoi::encoder") });
    let mut result_in_a = true;
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("Voronoi::pass"), timestamp_writes: None });
        pass.set_pipeline(&pipeline);
        for k in 0..steps.len() {
            pass.set_bind_group(0, if result_in_a { &a_to_b } else { &b_to_a }, &[layout::slot_offset(k)]);
            pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), 1);
            result_in_a = !result_in_a;
        }
    }
    gpu.queue.submit([encoder.finish()]);
    Ok(bytemuck::cast_slice(&crate::gpu::readback::read_buffer(gpu, if result_in_a { &a } else { &b })?).to_vec())
}

#[cfg(test)]
mod tests;
