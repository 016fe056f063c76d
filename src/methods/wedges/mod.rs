//! Method `wedges`: soft shadow volumes with penumbra wedges, restructured as in Assarsson &
//! Akenine-Möller 2003 — an umbra pass over shadow-volume polygons, a penumbra pass over the
//! wedges, occlusion culling of both per screen tile with the tile's zmin/zmax (§4), z-fail
//! when the eye is inside a shadow (§5), and the three-pass and single-pass arrangements (§6).
//! The one object-space method: its cost follows the silhouette, not only the resolution.
//! Shaders: `shaders/methods/wedges/`.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#wedges.

use std::sync::Arc;

use wgpu::util::DeviceExt;

mod culling;
mod geometry;

use super::light_view::{self, LightView};
use super::{Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;
use crate::gpu::readback::read_buffer;
use crate::light::tables::{emitting_octagon, sector_table, SECTOR_ANGLES, SECTOR_STATIONS};
use culling::{cull, TileGrid};
use geometry::{eye_in_shadow, Volume};

pub struct Wedges;

/// Most (item, pixel) pairs the penumbra pass lists at once (8 bytes each).
const INSIDE_PAIRS: u64 = 1 << 21;

const TILE: Param<u32> =
    Param::integer("tile", 8, 2, 256, "side of the occlusion-culling tiles, pixels (§4; the paper sweeps 2…256, best 8–32)");
const CULLING: Param<bool> = Param::boolean(
    "culling",
    true,
    "occlusion culling with the tiles' zmin and zmax (§4) and their receivers' world-space boxes; false rasterises every tile a primitive's bounding box covers",
);
const VOLUME: Param<&str> = Param::choice(
    "volume",
    "auto",
    &["auto", "zpass", "zfail"],
    "count shadow-volume crossings in front of the point (z-pass) or beyond it (z-fail, §5); auto picks z-fail when the eye is in shadow",
);
const OBJECT_IDS: Param<bool> = Param::boolean("object_ids", true, "a receiver facing away from the light centre takes no shadow from its own object's volume and wedges: the horizon already hides that part of the light (E0)");
const PASSES: Param<&str> = Param::choice(
    "passes",
    "three",
    &["three", "single"],
    "three: umbra polygons, then wedges (§6.1); single: an edge's umbra and penumbra in one pass where both touch a tile (§6.2)",
);

const COLOR_ANGLES: Param<u32> = Param::integer(
    "color_angles",
    8,
    1,
    32,
    "angular steps across a wedge's region (an eighth of a turn or wider; a narrower one takes proportionally fewer, at least two) in which a coloured light's emission is integrated (the image exactly, the edge's line held at each step's middle); a uniform light needs none",
);

const PARAMS: &[ParamSpec] = &[TILE.spec, CULLING.spec, VOLUME.spec, OBJECT_IDS.spec, PASSES.spec, COLOR_ANGLES.spec];

/// Full light in the LI buffer's fixed point.
const FULL: i32 = 1 << 16;

/// `VolumePolygon` in `common.wgsl`: v0.w is the multiplicity, v1.w the object id.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PolygonGpu {
    v: [[f32; 4]; 4],
}

/// `Wedge` in `common.wgsl` (a and b its `edge`): a.w is the multiplicity, b.w the object id;
/// the wedge's two tangent planes (inside ≥ 0; (0, 0, 0, 1) when there are none).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct WedgeGpu {
    a: [f32; 4],
    b: [f32; 4],
    planes: [[f32; 4]; 2],
}

/// `WorkItem` in `common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
struct WorkItem {
    primitive: u32,
    tile: u32,
    both: u32,
    /// The tile's first pixel: x in the low 16 bits, y in the high.
    origin: u32,
}

/// `WedgeParams` in `common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    tile: u32,
    zfail: u32,
    full: i32,
    polygon_count: u32,
    object_ids: u32,
    channels: u32,
    color_angles: u32,
    sector_angles: u32,
    sector_stations: u32,
    _pad: [u32; 3],
    emitting_lo: [f32; 4],
    emitting_hi: [f32; 4],
}

impl ShadowMethod for Wedges {
    fn name(&self) -> &'static str {
        "wedges"
    }

    /// A receiver facing away from the light centre ignores its own object (`tiles.wgsl`).
    fn reads_object_ids(&self) -> bool {
        true
    }

    /// Shadow volumes of the scene's triangles: no shadow map.
    fn reads_shadow_map(&self) -> bool {
        false
    }

    fn summary(&self) -> &'static str {
        "Assarsson & Akenine-Möller 2003: soft shadow volumes — silhouette edges from the light centre, penumbra wedges, LI buffer, umbra by z-pass or z-fail, zmin/zmax tile occlusion culling, three-pass or single-pass"
    }

    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }

    fn record(&self, ctx: &mut MethodContext<'_>, params: &Params) -> JobResult<Counters> {
        // CPU time spent on the object-space set-up (silhouette, primitives, culling): the part
        // of the cost GPU timestamps do not see.
        let setup_start = std::time::Instant::now();
        let spec = ctx.spec;
        let light = &spec.light;
        let c = light.center;
        let mesh = ctx.scene.edge_mesh();
        let casting = ctx.scene.casting_from(c);
        let silhouette = mesh.silhouette(&casting);
        let overlap = LightView::measure(&mesh, &casting, light).overlap;
        if overlap > light_view::OVERLAP_WARNING {
            ctx.warnings.push(format!(
                "wedges: {:.0} % of the shadows' outline lies behind two occluding layers or more, seen from the light; wedges adds \
                 what each silhouette hides (Assarsson & Akenine-Möller 2003 §2–3) rather than uniting it, so there its penumbrae \
                 come out darker and harder than the light that gets through (pcss and reference unite them)",
                100.0 * overlap
            ));
        }
        let camera = &spec.camera;
        let view_proj = camera.view_proj(spec.width as f32 / spec.height as f32);
        let reach = 2.0 * ctx.scene.corners().iter().map(|p| p.distance(c)).fold(0.0f32, f32::max).max(1e-3);
        let zfail = match params.get(&VOLUME) {
            "zfail" => true,
            "zpass" => false,
            _ => eye_in_shadow(&mesh, &casting, c, camera.eye),
        };
        let volume = Volume::build(&mesh, &casting, &silhouette, light, reach, zfail);
        let uniforms = Uniforms::new(ctx, params, zfail, volume.polygons.len());
        let pipelines = Pipelines::new(ctx, &uniforms);
        let buffers = Buffers::new(ctx, &volume, &uniforms);
        let mut setup = setup_start.elapsed();

        // Tile depth ranges from the GPU, then culling on the CPU.
        let tile_ranges = buffers.measure_tiles(ctx, &pipelines)?;
        let culling_start = std::time::Instant::now();
        let grid = TileGrid::new(buffers.grid_size, uniforms.tile, (spec.width, spec.height), &tile_ranges, camera, &view_proj);
        // How far below the light's plane the scene reaches: no receiver lies deeper.
        let deepest = ctx.scene.corners().iter().map(|p| light.depth(*p)).fold(0.0f32, f32::max);
        let work = cull(&volume, &silhouette, light, reach, deepest, &grid, &view_proj, camera.eye, params.get(&CULLING), zfail);
        let single = params.get(&PASSES) == "single";
        let passes = work.passes(single, [&*pipelines.umbra, &*pipelines.penumbra, &*pipelines.both]);
        let kept: usize = passes.iter().map(|(_, items)| items.len()).sum::<usize>();
        let (tested, rasterized) = (work.tested, work.rasterized());
        setup += culling_start.elapsed();

        buffers.rasterize(ctx, &pipelines, &passes);
        ctx.flush()?;
        let counts: Vec<u32> = bytemuck::cast_slice(&read_buffer(ctx.gpu, &buffers.counters)?).to_vec();
        let stats = mesh.stats;
        Ok(Counters::from([
            ("silhouette_edges".to_owned(), silhouette.len() as f64),
            ("occluders_overlapping".to_owned(), overlap),
            ("setup_cpu_ms".to_owned(), setup.as_secs_f64() * 1e3),
            ("volume_polygons".to_owned(), volume.polygons.len() as f64),
            ("cap_polygons".to_owned(), volume.caps as f64),
            ("zfail".to_owned(), f64::from(u8::from(zfail))),
            ("tiles_tested".to_owned(), tested as f64),
            ("tiles_culled".to_owned(), (tested - rasterized) as f64),
            ("work_items".to_owned(), kept as f64),
            ("depth_reads".to_owned(), f64::from(counts[0])),
            ("li_writes".to_owned(), f64::from(counts[1])),
            ("wedge_pixels_inside".to_owned(), f64::from(counts[2])),
            ("boundary_edges".to_owned(), stats.boundary_edges as f64),
            ("non_manifold_edges".to_owned(), stats.non_manifold_edges as f64),
            ("channels".to_owned(), f64::from(uniforms.channels)),
        ]))
    }
}

impl Uniforms {
    fn new(ctx: &MethodContext<'_>, params: &Params, zfail: bool, polygon_count: usize) -> Self {
        let spec = ctx.spec;
        let (emitting_lo, emitting_hi) = emitting_octagon(&spec.light, &spec.light_image);
        Self {
            tile: params.get(&TILE),
            zfail: u32::from(zfail),
            full: FULL,
            polygon_count: polygon_count as u32,
            object_ids: u32::from(params.get(&OBJECT_IDS)),
            channels: if spec.light_image.is_uniform() { 1 } else { 3 },
            color_angles: params.get(&COLOR_ANGLES),
            sector_angles: SECTOR_ANGLES,
            sector_stations: SECTOR_STATIONS,
            _pad: [0; 3],
            emitting_lo,
            emitting_hi,
        }
    }
}

/// Group 1 of every pass (`common.wgsl`): one layout for all of them.
const BINDINGS: [wgpu::BindGroupLayoutEntry; 13] = [
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
struct Pipelines {
    tiles: Arc<wgpu::ComputePipeline>,
    umbra: Arc<wgpu::ComputePipeline>,
    penumbra: Arc<wgpu::ComputePipeline>,
    both: Arc<wgpu::ComputePipeline>,
    /// Per chunk of penumbra items: list the pixels inside each wedge, size the dispatch over
    /// them, shade them, empty the list.
    mark_inside: Arc<wgpu::ComputePipeline>,
    inside_size: Arc<wgpu::ComputePipeline>,
    shade_listed: Arc<wgpu::ComputePipeline>,
    inside_reset: Arc<wgpu::ComputePipeline>,
    resolve: Arc<wgpu::ComputePipeline>,
}

impl Pipelines {
    fn new(ctx: &mut MethodContext<'_>, uniforms: &Uniforms) -> Self {
        let tiles = ctx.screen_pipeline(PipelineKey::new("wedges.tiles"), "methods/wedges/tiles.wgsl", &BINDINGS);
        let resolve = ctx.screen_pipeline(PipelineKey::new("wedges.resolve"), "methods/wedges/resolve.wgsl", &BINDINGS);
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
        let variant = u32::from(spec.acute_edges) << 24 | uniforms.channels << 16 | uniforms.tile << 6 | uniforms.color_angles;
        let mut raster = |name: &'static str, shader: &'static str, entry: &'static str| {
            ctx.screen_specialized(PipelineKey { name, variant }, (shader, entry), &BINDINGS, &constants)
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
fn storage(device: &wgpu::Device, label: &str, contents: &[u8]) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: if contents.is_empty() { &[0; 64] } else { contents },
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    })
}

/// What the passes bind in group 1 but the work list and the dispatch arguments: the volume,
/// the tiles' ranges, the LI buffer and the rest (`common.wgsl`).
struct Buffers {
    grid_size: (u32, u32),
    uniforms: wgpu::Buffer,
    polygons: wgpu::Buffer,
    wedges: wgpu::Buffer,
    /// Each tile's depth range and receivers' box, written by the tiles pass.
    ranges: wgpu::Buffer,
    /// The LI buffer: light intensity per pixel and channel, fixed point.
    li: wgpu::Buffer,
    /// Depth reads, LI writes and wedge pixels inside, counted on the GPU.
    counters: wgpu::Buffer,
    /// Every pixel's receiver record, written by the tiles pass.
    receivers: wgpu::Buffer,
    /// A coloured light's sector table (`light::tables`).
    sectors: Arc<wgpu::Buffer>,
    visibility: wgpu::Buffer,
    e0: wgpu::Buffer,
    /// The pixels inside each wedge of a chunk of penumbra items.
    inside: crate::render::PixelListBuffers,
    /// The work list's binding where a pass reads none.
    no_work: wgpu::Buffer,
    /// Items of the penumbra pass in one chunk: as many as the inside list holds the pixels of.
    inside_items: usize,
}

impl Buffers {
    fn new(ctx: &mut MethodContext<'_>, volume: &Volume, uniforms: &Uniforms) -> Self {
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
        let inside = crate::render::PixelListBuffers::new_of(&device, ctx.encoder, "Wedges::inside", inside_items as u64 * tile_pixels, 8);
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
    fn bind(&self, ctx: &MethodContext<'_>, pipelines: &Pipelines, work: &wgpu::Buffer, inside_groups: &wgpu::Buffer) -> wgpu::BindGroup {
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
    fn measure_tiles(&self, ctx: &mut MethodContext<'_>, pipelines: &Pipelines) -> JobResult<Vec<[[f32; 4]; 4]>> {
        {
            let group = self.bind(ctx, pipelines, &self.no_work, &self.inside.groups);
            let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, "method", "Wedges::tiles");
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
    fn rasterize(&self, ctx: &mut MethodContext<'_>, pipelines: &Pipelines, passes: &[(&wgpu::ComputePipeline, Vec<WorkItem>)]) {
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
        let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, "method", "Wedges::rasterize");
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
                pass.dispatch_workgroups_indirect(&self.inside.groups, 0);
                ctx.timer.mark(&mut pass, "wedges_penumbra_shade");
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
fn item_grid(n: u32) -> (u32, u32) {
    let rows = n.div_ceil(65535).max(1);
    (n.div_ceil(rows), rows)
}

#[cfg(test)]
mod tests {
    use super::item_grid;

    #[test]
    fn the_item_grid_covers_every_item_with_less_than_a_row_to_spare() {
        for n in [0, 1, 64, 65535, 65536, 70000, 131070, 131071, 972487, 4 << 20] {
            let (x, y) = item_grid(n);
            assert!(x <= 65535 && x * y >= n && x * y - n < y, "{n}: {x}×{y}");
        }
    }
}
