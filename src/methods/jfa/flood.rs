//! The pass driver `jfa-l` and `jfa-e` share: seed, `rounds` rounds of jump flooding between two
//! record buffers over the tiles a record can reach, then the final pass over the pixels that
//! hold an occluder (`shaders/methods/jfa/`).

use std::sync::Arc;

use super::{steps, Flood, Flooding, Uniforms, FINAL_ROW, FLOODING, ROUNDS, SILHOUETTE_ROW, TILE};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::light::tables::{edge_table, key_table};
use crate::methods::{MethodContext, Params};
use crate::render::PixelListBuffers;
use crate::timing::PhaseName;

/// Seeds, floods and shades; returns (seeds, penumbra pixels, step lengths, the fraction of
/// tiles the rounds flooded rather than skipped).
pub(super) fn flood(ctx: &mut MethodContext<'_>, which: &Flood, params: &Params, base: Uniforms) -> JobResult<(u32, u32, Vec<i32>, f64)> {
    let grid = if which.light_space { (ctx.spec.shadow_resolution, ctx.spec.shadow_resolution) } else { (ctx.width, ctx.height) };
    let steps = steps(params.get(&ROUNDS), params.get(&FLOODING) == Flooding::Standard);
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
pub(super) const BINDINGS: [wgpu::BindGroupLayoutEntry; 16] = [
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
pub(super) struct FloodPipelines {
    pub(super) seed: Arc<wgpu::ComputePipeline>,
    /// jfa-e lists its boundary pixels and seeds them in a compacted pass (boundary.wgsl):
    /// mark, size the dispatch, seed.
    pub(super) boundary: Option<[Arc<wgpu::ComputePipeline>; 3]>,
    pub(super) round: Arc<wgpu::ComputePipeline>,
    /// Each round runs over the tiles a record may reach, listed just before it
    /// (common.wgsl): list, size the dispatch, reset the list.
    pub(super) tile_passes: [Arc<wgpu::ComputePipeline>; 3],
    pub(super) finish: Arc<wgpu::ComputePipeline>,
    /// The final pass lists the pixels it shades by an occluder and shades them in a
    /// compacted pass (final_light.wgsl, final_eye.wgsl): size the dispatch, shade.
    pub(super) shading: [Arc<wgpu::ComputePipeline>; 2],
}

impl FloodPipelines {
    pub(super) fn new(ctx: &mut MethodContext<'_>, which: &Flood) -> Self {
        let seed = ctx.screen_pipeline(which.seed.0, which.seed.1, &BINDINGS);
        let boundary = (!which.light_space).then(|| {
            let mut entry = |name, entry| ctx.screen_entry(name, which.seed.1, entry, &BINDINGS);
            [
                entry("jfa-e.boundary.mark", "mark_boundary"),
                entry("jfa-e.boundary.size", "boundary_size"),
                entry("jfa-e.boundary.seed", "seed_listed"),
            ]
        });
        let round = ctx.screen_pipeline(which.round.0, which.round.1, &BINDINGS);
        let tile_passes =
            ["list_tiles", "tiles_size", "tiles_reset"].map(|entry| ctx.screen_entry(which.round.0, which.round.1, entry, &BINDINGS));
        let finish = ctx.screen_pipeline(which.finish.0, which.finish.1, &BINDINGS);
        let shading = ["shaded_size", "shade_listed"].map(|entry| ctx.screen_entry(which.finish.0, which.finish.1, entry, &BINDINGS));
        Self { seed, boundary, round, tile_passes, finish, shading }
    }
}

/// What a flood's passes bind in group 1 (`common.wgsl`).
pub(super) struct FloodBuffers {
    /// `Uniforms`, slot 0 for the seed and final passes, then one per round.
    pub(super) uniforms: wgpu::Buffer,
    /// The coloured edge table and the rounds' table of keys made from it (`light::tables`).
    pub(super) lut: Arc<wgpu::Buffer>,
    pub(super) keys: Arc<wgpu::Buffer>,
    /// The two record buffers the rounds ping-pong between.
    pub(super) a: wgpu::Buffer,
    pub(super) b: wgpu::Buffer,
    /// jfa-e's per-pixel flags.
    pub(super) flags: wgpu::Buffer,
    /// Per tile, whether a record may reach it.
    pub(super) tiles: wgpu::Buffer,
    pub(super) tile_count: u32,
    /// Seeds, penumbra pixels and tiles flooded, counted on the GPU.
    pub(super) counters: wgpu::Buffer,
    /// jfa-e's boundary pixels, the tiles of a round, the pixels the final pass shades.
    pub(super) listed: PixelListBuffers,
    pub(super) tile_list: PixelListBuffers,
    pub(super) shaded: PixelListBuffers,
    pub(super) map_depth: wgpu::Buffer,
}

impl FloodBuffers {
    pub(super) fn new(ctx: &mut MethodContext<'_>, which: &Flood, grid: (u32, u32), map_depth: wgpu::Buffer, slots: &[Uniforms]) -> Self {
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
        let listed = ctx.pixel_list("Jfa::boundary", if which.light_space { 0 } else { cells });
        let tile_list = ctx.pixel_list("Jfa::tile_list", u64::from(tile_count));
        let shaded = ctx.pixel_list("Jfa::shaded", u64::from(ctx.width) * u64::from(ctx.height));
        Self { uniforms, lut, keys, a, b, flags, tiles, tile_count, counters, listed, tile_list, shaded, map_depth }
    }

    /// Group 1 with records read from `src` and written to `dst`, and each pixel list's
    /// dispatch grid bound where given (its stand-in while a dispatch reads the grid).
    pub(super) fn bind(
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
    pub(super) fn record(&self, ctx: &mut MethodContext<'_>, which: &Flood, pipelines: &FloodPipelines, grid: (u32, u32), rounds: usize) {
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
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, "Jfa::passes");
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
            listed.walk(&mut pass, ctx.timer, "jfa_seed_boundary");
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
            tile_list.walk(&mut pass, ctx.timer, "jfa_rounds");
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
        shaded.walk(&mut pass, ctx.timer, "jfa_shade");
    }
}
