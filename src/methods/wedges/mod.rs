//! Method `wedges`: soft shadow volumes with penumbra wedges, restructured as in Assarsson &
//! Akenine-Möller 2003 — an umbra pass over shadow-volume polygons, a penumbra pass over the
//! wedges, occlusion culling of both per screen tile with the tile's zmin/zmax (§4), z-fail
//! when the eye is inside a shadow (§5), and the three-pass and single-pass arrangements (§6).
//! The one object-space method: its cost follows the silhouette, not only the resolution.
//! Shaders: `shaders/methods/wedges/`.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#wedges.

use super::light_view::{self, LightView};
use super::{Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;
use crate::gpu::readback::read_buffer;
use crate::light::tables::{emitting_octagon, SECTOR_ANGLES, SECTOR_STATIONS};
use crate::params::choice;

mod culling;
mod geometry;
mod passes;

use culling::{cull, TileGrid};
use geometry::{eye_in_shadow, Volume};
use passes::{Buffers, Pipelines};

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
choice! {
    /// Where shadow-volume crossings are counted (§5).
    enum VolumeCount { Auto = "auto", ZPass = "zpass", ZFail = "zfail" }
}
choice! {
    /// The arrangement of the umbra and penumbra passes (§6).
    enum Passes { Three = "three", Single = "single" }
}
const VOLUME: Param<VolumeCount> = Param::choice(
    "volume",
    "count shadow-volume crossings in front of the point (z-pass) or beyond it (z-fail, §5); auto picks z-fail when the eye is in shadow",
);
const OBJECT_IDS: Param<bool> = Param::boolean("object_ids", true, "a receiver facing away from the light centre takes no shadow from its own object's volume and wedges: the horizon already hides that part of the light (E0)");
const PASSES: Param<Passes> = Param::choice(
    "passes",
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
    v0: [f32; 4],
    v1: [f32; 4],
    v2: [f32; 4],
    v3: [f32; 4],
}

/// `Wedge` in `common.wgsl` (a and b its `edge`): a.w is the multiplicity, b.w the object id;
/// the wedge's two tangent planes (inside ≥ 0; (0, 0, 0, 1) when there are none).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct WedgeGpu {
    a: [f32; 4],
    b: [f32; 4],
    front: [f32; 4],
    back: [f32; 4],
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
            VolumeCount::ZFail => true,
            VolumeCount::ZPass => false,
            VolumeCount::Auto => eye_in_shadow(&mesh, &casting, c, camera.eye),
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
        let single = match params.get(&PASSES) {
            Passes::Three => false,
            Passes::Single => true,
        };
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

#[cfg(test)]
mod tests {
    use super::passes::item_grid;
    use super::*;

    #[test]
    fn the_gpu_structs_and_bindings_match_the_shaders() {
        use crate::gpu::shaders::assert_wgsl_layout;
        let common = "methods/wedges/common.wgsl";
        assert_wgsl_layout!(PolygonGpu, common, "VolumePolygon", [v0, v1, v2, v3]);
        assert_wgsl_layout!(WedgeGpu, common, "Wedge", [a, b, front, back]);
        assert_wgsl_layout!(WorkItem, common, "WorkItem", [primitive, tile, both, origin]);
        assert_wgsl_layout!(
            Uniforms,
            common,
            "WedgeParams",
            [
                tile,
                zfail,
                full,
                polygon_count,
                object_ids,
                channels,
                color_angles,
                sector_angles,
                sector_stations,
                _pad,
                emitting_lo,
                emitting_hi
            ]
        );
        let shaders =
            ["tiles", "rasterize_umbra", "rasterize_penumbra", "rasterize_both", "resolve"].map(|s| format!("methods/wedges/{s}.wgsl"));
        crate::gpu::shaders::assert_bindings(&shaders.each_ref().map(String::as_str), 1, &passes::BINDINGS);
    }

    #[test]
    fn the_item_grid_covers_every_item_with_less_than_a_row_to_spare() {
        for n in [0, 1, 64, 65535, 65536, 70000, 131070, 131071, 972487, 4 << 20] {
            let (x, y) = item_grid(n);
            assert!(x <= 65535 && x * y >= n && x * y - n < y, "{n}: {x}×{y}");
        }
    }
}
