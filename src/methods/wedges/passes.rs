//! The GPU side of `wedges`: the group-1 bindings, the pipelines, the per-frame buffers, and
//! the passes they record — each tile's depth range measured, then the culled work items
//! rasterised into the light-intensity buffer and resolved (`shaders/methods/wedges/`).

use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::geometry::Volume;
use super::{Uniforms, WorkItem, INSIDE_PAIRS};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::readback::read_buffer;
use crate::light::tables::sector_table;
use crate::methods::MethodContext;
use crate::timing::PhaseName;

/// Group 1 of every pass (`common.wgsl`): one layout for all of them.
pub(super) const BINDINGS: [wgpu::BindGroupLayoutEntry; 13] = [
    layout::uniform(0),
    layout::storage_read(1),
    layout::storage_read(2),
    layout::storage_read(3),
    layout::storage_read_write(4),
    layout::storage_read_write(5),
    layout::storage_read_write(6),
    layout::storage_read_write(7),
    layout::storage_read_write(8),
    layout::storage_read(9),
    layout::storage_read(10),
    layout::storage_read_write(11),
    layout::storage_read_write(12),
];

/// The method's passes: the tiles' depth ranges, the rasterisers of the umbra polygons, the
/// wedges and both (§6), the penumbra pass's steps over the pixels inside its wedges, and
/// the resolve into visibility.
pub(super) struct Pipelines {
    pub(super) tiles: Arc<wgpu::ComputePipeline>,
    pub(super) umbra: Arc<wgpu::ComputePipeline>,
    pub(super) penumbra: Arc<wgpu::ComputePipeline>,
    pub(super) both: Arc<wgpu::ComputePipeline>,
    /// Per chunk of penumbra items: list the pixels inside each wedge, size the dispatch over
    /// them, shade them, empty the list.
    pub(super) mark_inside: Arc<wgpu::ComputePipeline>,
    pub(super) inside_size: Arc<wgpu::ComputePipeline>,
    pub(super) shade_listed: Arc<wgpu::ComputePipeline>,
    pub(super) inside_reset: Arc<wgpu::ComputePipeline>,
    pub(super) resolve: Arc<wgpu::ComputePipeline>,
}

impl Pipelines {
    pub(super) fn new(ctx: &mut MethodContext<'_>, uniforms: &Uniforms) -> Self {
        let tiles = ctx.screen_pipeline("wedges.tiles", "methods/wedges/tiles.wgsl", &BINDINGS);
        let resolve = ctx.screen_pipeline("wedges.resolve", "methods/wedges/resolve.wgsl", &BINDINGS);
        // The rasteriser's pipelines are specialised by the LI buffer's channels and the colour
        // steps (pipeline constants in rasterize.wgsl): a uniform light's passes hold no colour
        // code, and the colour loop has a fixed count; by the tile's side (a pixel's place in
        // its tile is a shift, not a division); and by `ACUTE_EDGES` (common/light.wgsl).
        // `LANES` in rasterize.wgsl, by the kind of device (fixed per pipeline cache).
        let lanes: u32 = if ctx.gpu.software { 8 } else { 64 };
        let spec = ctx.spec;
        let constants = [
            ("CHANNELS", f64::from(uniforms.channels)),
            ("COLOR_ANGLES", f64::from(uniforms.color_angles)),
            ("TILE", f64::from(uniforms.tile)),
            ("LANES", f64::from(lanes)),
            spec.acute_edges_constant(),
        ];
        let mut raster = |name: &'static str, shader: &'static str, entry: &'static str| {
            ctx.screen_specialized(name, (shader, entry), &BINDINGS, &constants)
        };
        let penumbra = "methods/wedges/rasterize_penumbra.wgsl";
        Self {
            umbra: raster("wedges.umbra", "methods/wedges/rasterize_umbra.wgsl", "main"),
            penumbra: raster("wedges.penumbra", penumbra, "main"),
            both: raster("wedges.both", "methods/wedges/rasterize_both.wgsl", "main"),
            mark_inside: raster("wedges.inside", penumbra, "mark_inside"),
            inside_size: raster("wedges.inside_size", penumbra, "inside_size"),
            shade_listed: raster("wedges.shade", penumbra, "shade_listed"),
            inside_reset: raster("wedges.inside_reset", penumbra, "inside_reset"),
            tiles,
            resolve,
        }
    }
}

/// A storage buffer holding `contents`; wgpu refuses empty bindings, so an empty one holds
/// one element's worth of zeros.
pub(super) fn storage(device: &wgpu::Device, label: &str, contents: &[u8]) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: if contents.is_empty() { &[0; 64] } else { contents },
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    })
}

/// What the passes bind in group 1 but the work list and the dispatch arguments: the volume,
/// the tiles' ranges, the LI buffer and the rest (`common.wgsl`).
pub(super) struct Buffers {
    pub(super) grid_size: (u32, u32),
    pub(super) uniforms: wgpu::Buffer,
    pub(super) polygons: wgpu::Buffer,
    pub(super) wedges: wgpu::Buffer,
    /// Each tile's depth range and receivers' box, written by the tiles pass.
    pub(super) ranges: wgpu::Buffer,
    /// The LI buffer: light intensity per pixel and channel, fixed point.
    pub(super) li: wgpu::Buffer,
    /// Depth reads, LI writes and wedge pixels inside, counted on the GPU.
    pub(super) counters: wgpu::Buffer,
    /// Every pixel's receiver record, written by the tiles pass.
    pub(super) receivers: wgpu::Buffer,
    /// A coloured light's sector table (`light::tables`).
    pub(super) sectors: Arc<wgpu::Buffer>,
    pub(super) visibility: wgpu::Buffer,
    pub(super) e0: wgpu::Buffer,
    /// The pixels inside each wedge of a chunk of penumbra items.
    pub(super) inside: crate::render::PixelListBuffers,
    /// The work list's binding where a pass reads none.
    pub(super) no_work: wgpu::Buffer,
    /// Items of the penumbra pass in one chunk: as many as the inside list holds the pixels of.
    pub(super) inside_items: usize,
}

impl Buffers {
    pub(super) fn new(ctx: &mut MethodContext<'_>, volume: &Volume, uniforms: &Uniforms) -> Self {
        let device = ctx.gpu.device.clone();
        let (width, height) = (ctx.spec.width, ctx.spec.height);
        let grid_size = (width.div_ceil(uniforms.tile), height.div_ceil(uniforms.tile));
        let tile_count = (grid_size.0 * grid_size.1) as usize;
        // From the pool: the LI buffer is cleared before the rasteriser runs, and the tiles pass
        // writes every pixel's receiver record.
        let pixels = u64::from(width) * u64::from(height);
        let li = ctx.scratch_buffer(
            "Wedges::li",
            pixels * 4 * u64::from(uniforms.channels),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        );
        let receivers = ctx.scratch_buffer("Wedges::receivers", pixels * 32, wgpu::BufferUsages::STORAGE);
        let sectors = if uniforms.channels == 3 {
            ctx.light_table("wedges.sectors", sector_table)
        } else {
            Arc::new(storage(&device, "Wedges::no_sectors", &[]))
        };
        let tile_pixels = u64::from(uniforms.tile) * u64::from(uniforms.tile);
        // The penumbra pass lists the pixels inside each wedge, a chunk of items at a time.
        let inside_items = (INSIDE_PAIRS / tile_pixels).max(1) as usize;
        let inside = ctx.pixel_list_of("Wedges::inside", inside_items as u64 * tile_pixels, 8);
        Self {
            grid_size,
            uniforms: ctx.uniforms("Wedges::uniforms", uniforms),
            polygons: storage(&device, "Wedges::polygons", bytemuck::cast_slice(&volume.polygons_gpu())),
            wedges: storage(&device, "Wedges::wedges", bytemuck::cast_slice(&volume.wedges)),
            ranges: storage(&device, "Wedges::tile_ranges", &vec![0u8; tile_count * 64]),
            li,
            counters: storage(&device, "Wedges::counters", &[0u8; 16]),
            receivers,
            sectors,
            visibility: ctx.visibility.clone(),
            e0: ctx.e0.clone(),
            inside,
            no_work: storage(&device, "Wedges::no_work", &[]),
            inside_items,
        }
    }

    /// Group 1 with `work` as the work list and `inside_groups` where the inside list's
    /// dispatch arguments are written (a stand-in while a dispatch reads them).
    pub(super) fn bind(
        &self,
        ctx: &MethodContext<'_>,
        pipelines: &Pipelines,
        work: &wgpu::Buffer,
        inside_groups: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        ctx.bind(
            "Wedges::bind_group",
            &pipelines.tiles,
            &[
                self.uniforms.as_entire_binding(),
                self.polygons.as_entire_binding(),
                self.wedges.as_entire_binding(),
                work.as_entire_binding(),
                self.li.as_entire_binding(),
                self.ranges.as_entire_binding(),
                self.counters.as_entire_binding(),
                self.visibility.as_entire_binding(),
                self.receivers.as_entire_binding(),
                self.sectors.as_entire_binding(),
                self.e0.as_entire_binding(),
                self.inside.list.as_entire_binding(),
                inside_groups.as_entire_binding(),
            ],
        )
    }

    /// Runs the tiles pass (each tile's depth range and receivers, §4) and reads the ranges
    /// back for the culling.
    pub(super) fn measure_tiles(&self, ctx: &mut MethodContext<'_>, pipelines: &Pipelines) -> JobResult<Vec<[[f32; 4]; 4]>> {
        {
            let group = self.bind(ctx, pipelines, &self.no_work, &self.inside.groups);
            let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, "Wedges::tiles");
            pass.set_pipeline(&pipelines.tiles);
            pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
            pass.set_bind_group(1, &group, &[]);
            pass.dispatch_workgroups((self.grid_size.0 * self.grid_size.1).div_ceil(64), 1, 1);
        }
        ctx.flush()?;
        Ok(bytemuck::cast_slice(&read_buffer(ctx.gpu, &self.ranges)?).to_vec())
    }

    /// Clears the LI buffer, runs the culled work items pass by pass (`passes`, in order) and
    /// resolves the LI buffer into visibility.
    pub(super) fn rasterize(&self, ctx: &mut MethodContext<'_>, pipelines: &Pipelines, passes: &[(&wgpu::ComputePipeline, Vec<WorkItem>)]) {
        ctx.encoder.clear_buffer(&self.li, 0, None);
        // Work lists go to the GPU in chunks a storage binding can hold, in pass order; the
        // penumbra pass's in chunks whose pixels the inside list can hold.
        let max_items = (ctx.gpu.device.limits().max_storage_buffer_binding_size as usize / std::mem::size_of::<WorkItem>()).min(1 << 22);
        let is_penumbra = |pipeline: &wgpu::ComputePipeline| std::ptr::eq(pipeline, &*pipelines.penumbra);
        let chunks: Vec<(&wgpu::ComputePipeline, &[WorkItem])> = passes
            .iter()
            .flat_map(|(pipeline, items)| {
                let size = if is_penumbra(pipeline) { self.inside_items.min(max_items) } else { max_items };
                items.chunks(size).map(move |chunk| (*pipeline, chunk))
            })
            .collect();
        // Per chunk, group 1 with its work list; a penumbra chunk's also with the stand-in for
        // the inside list's dispatch arguments (for the dispatch that reads them).
        let groups: Vec<(wgpu::BindGroup, Option<wgpu::BindGroup>)> = chunks
            .iter()
            .map(|(pipeline, items)| {
                let work = storage(&ctx.gpu.device, "Wedges::work", bytemuck::cast_slice(items));
                let reading = is_penumbra(pipeline).then(|| self.bind(ctx, pipelines, &work, &self.inside.stand_in));
                (self.bind(ctx, pipelines, &work, &self.inside.groups), reading)
            })
            .collect();
        let resolve_group = self.bind(ctx, pipelines, &self.no_work, &self.inside.groups);
        let screen = ctx.dispatch_size();
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, "Wedges::rasterize");
        pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
        for ((pipeline, items), (group, reading_group)) in chunks.iter().zip(&groups) {
            // One workgroup per item, in rows of at most 65 535.
            let (x, y) = item_grid(items.len() as u32);
            pass.set_bind_group(1, group, &[]);
            if let Some(reading_group) = reading_group {
                pass.set_pipeline(&pipelines.mark_inside);
                pass.dispatch_workgroups(x, y, 1);
                ctx.timer.mark(&mut pass, "wedges_penumbra_inside");
                pass.set_pipeline(&pipelines.inside_size);
                pass.dispatch_workgroups(1, 1, 1);
                pass.set_bind_group(1, reading_group, &[]);
                pass.set_pipeline(&pipelines.shade_listed);
                self.inside.walk(&mut pass, ctx.timer, "wedges_penumbra_shade");
                pass.set_bind_group(1, group, &[]);
                pass.set_pipeline(&pipelines.inside_reset);
                pass.dispatch_workgroups(1, 1, 1);
                ctx.timer.mark(&mut pass, "wedges_penumbra_reset");
            } else {
                pass.set_pipeline(pipeline);
                pass.dispatch_workgroups(x, y, 1);
                ctx.timer.mark(&mut pass, if std::ptr::eq(*pipeline, &*pipelines.umbra) { "wedges_umbra" } else { "wedges_both" });
            }
        }
        pass.set_pipeline(&pipelines.resolve);
        pass.set_bind_group(1, &resolve_group, &[]);
        pass.dispatch_workgroups(screen.0, screen.1, 1);
        ctx.timer.mark(&mut pass, "wedges_resolve");
    }
}

/// The workgroup grid of one workgroup per item for `n` items: rows of at most 65 535 (a
/// dimension's guaranteed limit), as even as they can be, so that fewer than one row's count
/// of workgroups fall past the end (`item_index` in `rasterize.wgsl`).
pub(super) fn item_grid(n: u32) -> (u32, u32) {
    let rows = n.div_ceil(65535).max(1);
    (n.div_ceil(rows), rows)
}
