//! Method `wedges`: soft shadow volumes with penumbra wedges, restructured as in Assarsson &
//! Akenine-Möller 2003 — an umbra pass over shadow-volume polygons, a penumbra pass over the
//! wedges, occlusion culling of both per screen tile with the tile's zmin/zmax (§4), z-fail
//! when the eye is inside a shadow (§5), and the three-pass and single-pass arrangements (§6).
//! The one object-space method: its cost follows the silhouette, not only the resolution.
//! Shaders: `shaders/methods/wedges/`.
//!
//! On the CPU, per job: the silhouette edges seen from the light centre (`scene::adjacency`,
//! cached per scene); per edge a side quad of the light centre's shadow volume and a penumbra
//! wedge; their screen bounding boxes; after the GPU has measured every tile's depth range
//! (`tiles.wgsl`), the culling — each (primitive, tile) pair is tested and, if it survives,
//! becomes one work item. `rasterize.wgsl` runs the items (one workgroup each, over the tile's
//! pixels) into a light-intensity buffer of i32 atomics (fixed point, full light = 2¹⁶, so
//! 32 767 overlapping volumes fit where the paper's 16-bit stencil held 127); `resolve.wgsl`
//! turns it into visibility. WGSL has neither geometry shaders nor a stencil buffer that adds
//! arbitrary values, so the rasteriser is a compute pass — which is also how the paper ran
//! its penumbra pass (in software).
//!
//! Choices where the paper defers to its wedge papers [1, 2]:
//! - The umbra volume is the light centre's hard shadow volume (side quads through the edge
//!   and the centre), and a wedge's contribution is computed exactly for the rectangle: the
//!   edge is projected from the pixel's point onto the light; every light point beyond it,
//!   within its angular sector from the centre, is covered by one more layer than the centre
//!   — so that share, clipped to the rectangle, is added where the centre is hidden and taken
//!   away where it is seen. Summed over a closed silhouette this is the exact covered area of
//!   the light (the winding number changes by one at each edge), with no side planes to match
//!   between neighbouring wedges. This is the arrangement of [2]; the paper's restructuring,
//!   culling and z-fail apply to it unchanged (§8). The light is treated as a uniform
//!   rectangle: the image's colours and shape reach the frame through E0 only.
//! - Wedge culling uses the wedge's two tangent planes (through the edge, touching the light
//!   rectangle: the wedge lies between them on the side away from the light) transformed to
//!   screen space, tested with the n/p vertex of the tile's box (Fig. 7), after the quick
//!   z-range rejection; the wedge's side extent is bounded by its screen bounding box.
//! - Volumes are extruded to twice the distance of the scene's farthest corner and closed
//!   there for z-fail; rays are intersected with the polygons analytically, so no far plane
//!   clips them (the role of the paper's infinite far plane).
//! - Surfaces on their own volume's cap (every lit caster) count as outside it.

use glam::{Mat4, Vec3, Vec4};
use wgpu::util::DeviceExt;

use super::{Counters, MethodContext, Param, ParamSpec, Params, ShadowMethod};
use crate::error::JobResult;
use crate::gpu::layout;
use crate::gpu::pool::PipelineKey;
use crate::gpu::readback::read_buffer;
use crate::scene::adjacency::SilhouetteEdge;

pub struct Wedges;

const TILE: Param<u32> =
    Param::integer("tile", 8, 2, 256, "side of the occlusion-culling tiles, pixels (§4; the paper sweeps 2…256, best 8–32)");
const CULLING: Param<bool> = Param::boolean(
    "culling",
    true,
    "occlusion culling with the tiles' zmin and zmax (§4); false rasterises every tile a primitive's bounding box covers",
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

const PARAMS: &[ParamSpec] = &[TILE.spec, CULLING.spec, VOLUME.spec, OBJECT_IDS.spec, PASSES.spec];

/// Full light in the LI buffer's fixed point.
const FULL: i32 = 1 << 16;

/// `VolumePolygon` in `common.wgsl`: v0.w is the multiplicity, v1.w the object id.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PolygonGpu {
    v: [[f32; 4]; 4],
}

/// `Wedge` in `common.wgsl`: a.w is the multiplicity, b.w the object id; the wedge's two
/// tangent planes (inside ≥ 0; (0, 0, 0, 1) when there are none).
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
    _pad: u32,
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
    _pad: [u32; 3],
}

/// A primitive's footprint for culling: its screen bounding box in tiles, its NDC depth range,
/// and the planes (world space, inside ≥ 0) that bound it.
struct Footprint {
    tiles_x: (u32, u32),
    tiles_y: (u32, u32),
    z: (f32, f32),
    planes: Vec<Vec4>,
}

/// The tile grid with each tile's NDC box (x, y from its pixels, z from its depth range).
struct TileGrid {
    across: u32,
    down: u32,
    /// Per tile: (x0, x1, y0, y1, z0, z1) in NDC, or None for background only.
    boxes: Vec<Option<[f32; 6]>>,
}

impl ShadowMethod for Wedges {
    fn name(&self) -> &'static str {
        "wedges"
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
        let silhouette = mesh.silhouette(c);
        let camera = &spec.camera;
        let view_proj = camera.view_proj(spec.width as f32 / spec.height as f32);
        let reach = 2.0 * ctx.scene.corners().iter().map(|p| p.distance(c)).fold(0.0f32, f32::max).max(1e-3);
        let zfail = match params.get(&VOLUME) {
            "zfail" => true,
            "zpass" => false,
            _ => eye_in_shadow(&mesh, c, camera.eye),
        };

        // The light centre's shadow volume: a side quad per silhouette edge, and for z-fail its
        // caps — the triangles facing the light (top) and the same pushed out to `reach` (bottom).
        let extrude = |p: Vec3| c + (p - c) * (reach / (p - c).length().max(1e-6));
        let mut polygons: Vec<[Vec3; 4]> = Vec::new();
        let mut multiplicity: Vec<u32> = Vec::new();
        let mut object: Vec<u32> = Vec::new();
        for e in &silhouette {
            // Always this order, never flipped per quad: (a − b) × (a' − b) is the outward
            // normal (a' the extruded a), and neighbouring quads run their shared extruded
            // edge in opposite directions, which the rasteriser's tie rule relies on; so do
            // the caps with the quads' near and far edges.
            polygons.push([e.b, e.a, extrude(e.a), extrude(e.b)]);
            multiplicity.push(e.multiplicity);
            object.push(e.object);
        }
        let mut caps = 0usize;
        if zfail {
            for (t, tri) in mesh.triangles.iter().enumerate() {
                if mesh.faces(t, c) {
                    let [a, b, d] = tri.map(|i| mesh.positions[i as usize]);
                    polygons.push([a, b, d, d]);
                    polygons.push([extrude(d), extrude(b), extrude(a), extrude(a)]);
                    multiplicity.extend([1, 1]);
                    object.extend([mesh.objects[t]; 2]);
                    caps += 2;
                }
            }
        }
        let wedge_planes: Vec<Vec<Vec4>> = silhouette.iter().map(|e| tangent_planes(e, light)).collect();
        let wedges: Vec<WedgeGpu> = silhouette
            .iter()
            .zip(&wedge_planes)
            .map(|(e, planes)| WedgeGpu {
                a: e.a.extend(e.multiplicity as f32).to_array(),
                b: e.b.extend(e.object as f32).to_array(),
                planes: [0, 1].map(|k| planes.get(k).copied().unwrap_or(Vec4::W).to_array()),
            })
            .collect();

        // Tile depth ranges from the GPU, then culling on the CPU.
        let tile = params.get(&TILE);
        let culling = params.get(&CULLING);
        let device = ctx.gpu.device.clone();
        let grid_size = (spec.width.div_ceil(tile), spec.height.div_ceil(tile));
        let tile_count = (grid_size.0 * grid_size.1) as usize;
        let uniforms = Uniforms {
            tile,
            zfail: u32::from(zfail),
            full: FULL,
            polygon_count: polygons.len() as u32,
            object_ids: u32::from(params.get(&OBJECT_IDS)),
            _pad: [0; 3],
        };
        let storage = |label, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                // wgpu refuses empty bindings: keep at least one element's worth.
                contents: if contents.is_empty() { &[0; 64] } else { contents },
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            })
        };
        let uniform_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("Wedges::uniforms"),
            contents: bytemuck::bytes_of(&uniforms),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let polygon_data: Vec<PolygonGpu> = polygons
            .iter()
            .zip(multiplicity.iter().zip(&object))
            .map(|(p, (&m, &o))| PolygonGpu {
                v: [
                    p[0].extend(m as f32).to_array(),
                    p[1].extend(o as f32).to_array(),
                    p[2].extend(0.0).to_array(),
                    p[3].extend(0.0).to_array(),
                ],
            })
            .collect();
        let polygon_buffer = storage("Wedges::polygons", bytemuck::cast_slice(&polygon_data));
        let wedge_buffer = storage("Wedges::wedges", bytemuck::cast_slice(&wedges));
        let ranges = storage("Wedges::tile_ranges", &vec![0u8; tile_count * 8]);
        let li = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Wedges::li"),
            size: u64::from(spec.width) * u64::from(spec.height) * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let counters = storage("Wedges::counters", &[0u8; 16]);
        let receivers = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Wedges::receivers"),
            size: u64::from(spec.width) * u64::from(spec.height) * 32,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let io = [
            layout::uniform(0),
            layout::storage_read(1),
            layout::storage_read(2),
            layout::storage_read(3),
            layout::storage_read_write(4),
            layout::storage_read_write(5),
            layout::storage_read_write(6),
            layout::storage_texture(7, wgpu::TextureFormat::Rgba32Float),
            layout::storage_read_write(8),
        ];
        let tiles_pipeline = ctx.screen_pipeline(PipelineKey::new("wedges.tiles"), "methods/wedges/tiles.wgsl", &io);
        let umbra_pipeline = ctx.screen_pipeline(PipelineKey::new("wedges.umbra"), "methods/wedges/rasterize_umbra.wgsl", &io);
        let penumbra_pipeline = ctx.screen_pipeline(PipelineKey::new("wedges.penumbra"), "methods/wedges/rasterize_penumbra.wgsl", &io);
        let both_pipeline = ctx.screen_pipeline(PipelineKey::new("wedges.both"), "methods/wedges/rasterize_both.wgsl", &io);
        let resolve = ctx.screen_pipeline(PipelineKey::new("wedges.resolve"), "methods/wedges/resolve.wgsl", &io);
        let bind = |work: &wgpu::Buffer| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("Wedges::bind_group"),
                layout: &tiles_pipeline.get_bind_group_layout(1),
                entries: &layout::entries(&[
                    uniform_buffer.as_entire_binding(),
                    polygon_buffer.as_entire_binding(),
                    wedge_buffer.as_entire_binding(),
                    work.as_entire_binding(),
                    li.as_entire_binding(),
                    ranges.as_entire_binding(),
                    counters.as_entire_binding(),
                    wgpu::BindingResource::TextureView(ctx.visibility),
                    receivers.as_entire_binding(),
                ]),
            })
        };
        let no_work = storage("Wedges::no_work", &[]);
        let mut setup = setup_start.elapsed();
        {
            let group = bind(&no_work);
            let mut pass = ctx.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("Wedges::tiles"),
                timestamp_writes: ctx.timer.compute_scope("method"),
            });
            pass.set_pipeline(&tiles_pipeline);
            pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
            pass.set_bind_group(1, &group, &[]);
            pass.dispatch_workgroups((tile_count as u32).div_ceil(64), 1, 1);
        }
        ctx.flush()?;
        let depth_ranges: Vec<[f32; 2]> = bytemuck::cast_slice(&read_buffer(ctx.gpu, &ranges)?).to_vec();
        let culling_start = std::time::Instant::now();
        let grid = TileGrid::new(grid_size, tile, (spec.width, spec.height), &depth_ranges, camera, &view_proj);

        // Cull: every (primitive, tile) pair in the primitive's bounding box is tested.
        let to_ndc = view_proj.inverse().transpose();
        let mut tested = 0u64;
        let umbra_footprints: Vec<Footprint> = polygons.iter().map(|p| footprint(&view_proj, p, Vec::new(), &grid)).collect();
        let wedge_footprints: Vec<Footprint> = silhouette
            .iter()
            .zip(&wedge_planes)
            .map(|(e, planes)| footprint(&view_proj, &wedge_hull(e, light, reach), planes.clone(), &grid))
            .collect();
        let mut survivors = |footprint: &Footprint, umbra: bool| -> Vec<u32> {
            let mut kept = Vec::new();
            for ty in footprint.tiles_y.0..footprint.tiles_y.1 {
                for tx in footprint.tiles_x.0..footprint.tiles_x.1 {
                    let t = ty * grid.across + tx;
                    tested += 1;
                    if !culling || survives(footprint, grid.boxes[t as usize], umbra, zfail, &to_ndc) {
                        kept.push(t);
                    }
                }
            }
            kept
        };
        let umbra_tiles: Vec<Vec<u32>> = umbra_footprints.iter().map(|f| survivors(f, true)).collect();
        let wedge_tiles: Vec<Vec<u32>> = wedge_footprints.iter().map(|f| survivors(f, false)).collect();
        let single = params.get(&PASSES) == "single";
        let wedge_base = polygons.len() as u32;
        let item = |primitive, tile, both| WorkItem { primitive, tile, both, _pad: 0 };
        // Each pass: its pipeline and its items.
        let mut passes: Vec<(&wgpu::ComputePipeline, Vec<WorkItem>)> = Vec::new();
        if single {
            // An edge's side quad and wedge share the items of the tiles both touch.
            let mut items = Vec::new();
            for (i, quad_tiles) in umbra_tiles.iter().enumerate() {
                let wedge = wedge_tiles.get(i);
                for &t in quad_tiles {
                    let both = wedge.is_some_and(|w| w.binary_search(&t).is_ok());
                    items.push(item(i as u32, t, if both { i as u32 + 1 } else { 0 }));
                }
                if let Some(w) = wedge {
                    items.extend(w.iter().filter(|t| quad_tiles.binary_search(t).is_err()).map(|&t| item(wedge_base + i as u32, t, 0)));
                }
            }
            passes.push((&both_pipeline, items));
        } else {
            let umbra = umbra_tiles.iter().enumerate().flat_map(|(i, ts)| ts.iter().map(move |&t| item(i as u32, t, 0)));
            let penumbra = wedge_tiles.iter().enumerate().flat_map(|(i, ts)| ts.iter().map(move |&t| item(wedge_base + i as u32, t, 0)));
            passes.push((&umbra_pipeline, umbra.collect()));
            passes.push((&penumbra_pipeline, penumbra.collect()));
        }
        let kept: usize = passes.iter().map(|(_, items)| items.len()).sum::<usize>();
        let rasterized = umbra_tiles.iter().chain(&wedge_tiles).map(Vec::len).sum::<usize>() as u64;

        setup += culling_start.elapsed();
        ctx.encoder.clear_buffer(&li, 0, None);
        // Work lists go to the GPU in chunks a storage binding can hold, in pass order.
        let max_items = (device.limits().max_storage_buffer_binding_size as usize / std::mem::size_of::<WorkItem>()).min(1 << 22);
        let chunks: Vec<(&wgpu::ComputePipeline, &[WorkItem])> =
            passes.iter().flat_map(|(pipeline, items)| items.chunks(max_items).map(move |chunk| (*pipeline, chunk))).collect();
        let groups: Vec<wgpu::BindGroup> =
            chunks.iter().map(|(_, items)| bind(&storage("Wedges::work", bytemuck::cast_slice(items)))).collect();
        let resolve_group = bind(&no_work);
        let screen = ctx.dispatch_size();
        {
            let mut pass = ctx.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("Wedges::rasterize"),
                timestamp_writes: ctx.timer.compute_scope("method"),
            });
            pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
            for ((pipeline, items), group) in chunks.iter().zip(&groups) {
                // One workgroup per item, in rows of at most 65 535.
                let n = items.len() as u32;
                pass.set_pipeline(pipeline);
                pass.set_bind_group(1, group, &[]);
                pass.dispatch_workgroups(n.min(65535), n.div_ceil(65535), 1);
            }
            pass.set_pipeline(&resolve);
            pass.set_bind_group(1, &resolve_group, &[]);
            pass.dispatch_workgroups(screen.0, screen.1, 1);
        }
        ctx.flush()?;
        let counts: Vec<u32> = bytemuck::cast_slice(&read_buffer(ctx.gpu, &counters)?).to_vec();
        let stats = mesh.stats;
        Ok(Counters::from([
            ("silhouette_edges".to_owned(), silhouette.len() as f64),
            ("setup_cpu_ms".to_owned(), setup.as_secs_f64() * 1e3),
            ("volume_polygons".to_owned(), polygons.len() as f64),
            ("cap_polygons".to_owned(), caps as f64),
            ("zfail".to_owned(), f64::from(u8::from(zfail))),
            ("tiles_tested".to_owned(), tested as f64),
            ("tiles_culled".to_owned(), (tested - rasterized) as f64),
            ("work_items".to_owned(), kept as f64),
            ("depth_reads".to_owned(), f64::from(counts[0])),
            ("li_writes".to_owned(), f64::from(counts[1])),
            ("boundary_edges".to_owned(), stats.boundary_edges as f64),
            ("non_manifold_edges".to_owned(), stats.non_manifold_edges as f64),
        ]))
    }
}

/// Whether the eye lies in the light centre's hard shadow: the segment from the eye to the
/// centre passes through a light-facing triangle (then z-pass would count wrongly, §5).
fn eye_in_shadow(mesh: &crate::scene::adjacency::EdgeMesh, c: Vec3, eye: Vec3) -> bool {
    let dir = c - eye;
    mesh.triangles.iter().enumerate().any(|(t, tri)| {
        if !mesh.faces(t, c) {
            return false;
        }
        // Möller–Trumbore, restricted to the open segment.
        let [a, b, d] = tri.map(|i| mesh.positions[i as usize]);
        let (e1, e2) = (b - a, d - a);
        let h = dir.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-12 {
            return false;
        }
        let s = eye - a;
        let u = s.dot(h) / det;
        let q = s.cross(e1);
        let v = dir.dot(q) / det;
        let t = e2.dot(q) / det;
        u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 1e-6 && t < 1.0 - 1e-6
    })
}

/// Points whose convex hull holds the edge's wedge out to `reach`: the edge's ends and their
/// shadows from the light's four corners.
fn wedge_hull(e: &SilhouetteEdge, light: &crate::light::AreaLight, reach: f32) -> Vec<Vec3> {
    let mut hull = vec![e.a, e.b];
    for corner in light_corners(light) {
        for p in [e.a, e.b] {
            let d = p - corner;
            hull.push(p + d * ((reach + (p - light.center).length()) / d.length().max(1e-6)));
        }
    }
    hull
}

fn light_corners(light: &crate::light::AreaLight) -> [Vec3; 4] {
    let (hw, hh) = (0.5 * light.size_m.x, 0.5 * light.size_m.y);
    [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(s, t)| light.center + light.r * (s * hw) + light.u * (t * hh))
}

/// The wedge's two planes through the edge's line that touch the light rectangle, as
/// world-space planes with the wedge on their positive side. Empty when the line passes
/// through the light (then every plane through it cuts the light, and only the bounding box
/// bounds the wedge).
fn tangent_planes(e: &SilhouetteEdge, light: &crate::light::AreaLight) -> Vec<Vec4> {
    let corners = light_corners(light);
    let dir = e.b - e.a;
    let scale = dir.length() * light.size_m.max_element();
    let mut planes = Vec::new();
    for &y in &corners {
        let n = dir.cross(y - e.a);
        if n.length() <= 1e-9 * scale {
            continue;
        }
        let sides: Vec<f32> = corners.iter().map(|&z| n.dot(z - e.a) / n.length()).collect();
        let tolerance = 1e-6 * light.size_m.max_element();
        let positive = sides.iter().all(|&s| s >= -tolerance);
        let negative = sides.iter().all(|&s| s <= tolerance);
        if positive == negative {
            continue; // cuts the light, or lies in its plane
        }
        // The light on the positive side: the wedge is on the negative side of both.
        let n = if positive { -n.normalize() } else { n.normalize() };
        let plane = n.extend(-n.dot(e.a));
        if planes.iter().all(|q: &Vec4| (q.truncate().dot(n) - 1.0).abs() > 1e-5) {
            planes.push(plane);
        }
    }
    if planes.len() == 2 {
        planes
    } else {
        Vec::new()
    }
}

impl TileGrid {
    fn new(size: (u32, u32), tile: u32, pixels: (u32, u32), depth: &[[f32; 2]], camera: &crate::render::Camera, view_proj: &Mat4) -> Self {
        let forward = camera.forward();
        let ndc_z = |d: f32| {
            let clip = *view_proj * (camera.eye + forward * d).extend(1.0);
            clip.z / clip.w
        };
        let boxes = (0..size.0 * size.1)
            .map(|t| {
                let [zmin, zmax] = depth[t as usize];
                if zmin > zmax {
                    return None;
                }
                let (tx, ty) = (t % size.0, t / size.0);
                let px = |x: u32| 2.0 * (x.min(pixels.0)) as f32 / pixels.0 as f32 - 1.0;
                let py = |y: u32| 1.0 - 2.0 * (y.min(pixels.1)) as f32 / pixels.1 as f32;
                Some([px(tx * tile), px((tx + 1) * tile), py((ty + 1) * tile), py(ty * tile), ndc_z(zmin), ndc_z(zmax)])
            })
            .collect();
        Self { across: size.0, down: size.1, boxes }
    }
}

/// A primitive's bounding box in tiles and NDC depth range; points behind the eye make it
/// cover the whole screen and every depth.
fn footprint(view_proj: &Mat4, points: &[Vec3], planes: Vec<Vec4>, grid: &TileGrid) -> Footprint {
    let clips: Vec<Vec4> = points.iter().map(|p| *view_proj * p.extend(1.0)).collect();
    if clips.iter().any(|c| c.w <= 1e-6) {
        return Footprint { tiles_x: (0, grid.across), tiles_y: (0, grid.down), z: (f32::NEG_INFINITY, f32::INFINITY), planes };
    }
    let ndc: Vec<Vec3> = clips.iter().map(|c| c.truncate() / c.w).collect();
    let min = ndc.iter().fold(Vec3::splat(f32::INFINITY), |m, p| m.min(*p));
    let max = ndc.iter().fold(Vec3::splat(f32::NEG_INFINITY), |m, p| m.max(*p));
    // NDC x → tile column, NDC y (up) → tile row (down).
    let column = |x: f32| (((x * 0.5 + 0.5) * grid.across as f32).floor().max(0.0) as u32).min(grid.across);
    let row = |y: f32| (((0.5 - y * 0.5) * grid.down as f32).floor().max(0.0) as u32).min(grid.down);
    Footprint {
        tiles_x: (column(min.x), (column(max.x) + 1).min(grid.across)),
        tiles_y: (row(max.y), (row(min.y) + 1).min(grid.down)),
        z: (min.z, max.z),
        planes,
    }
}

/// Occlusion culling of one primitive over one tile (§4): background tiles hold nothing; the
/// quick rejection compares depth ranges — a volume polygon only with zmax (z-pass: it must
/// lie in front of something) or zmin (z-fail: behind something), a wedge with both — and a
/// wedge's planes, in screen space, are tested with the tile box's p-vertex (Fig. 7).
fn survives(footprint: &Footprint, tile: Option<[f32; 6]>, umbra: bool, zfail: bool, to_ndc: &Mat4) -> bool {
    let Some([x0, x1, y0, y1, z0, z1]) = tile else {
        return false;
    };
    let (zmin, zmax) = footprint.z;
    if umbra {
        return if zfail { zmax >= z0 } else { zmin <= z1 };
    }
    if zmin > z1 || zmax < z0 {
        return false;
    }
    footprint.planes.iter().all(|plane| {
        let p = *to_ndc * *plane;
        let vertex = Vec3::new(if p.x > 0.0 { x1 } else { x0 }, if p.y > 0.0 { y1 } else { y0 }, if p.z > 0.0 { z1 } else { z0 });
        p.truncate().dot(vertex) + p.w >= 0.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::AreaLight;
    use glam::Vec2;

    #[test]
    fn tangent_planes_touch_the_light_and_hold_the_wedge() {
        // A light of 2 × 1 m at y = 3 facing down; an edge along z at height 1.
        let light = AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
        let edge = SilhouetteEdge { a: Vec3::new(0.5, 1.0, -5.0), b: Vec3::new(0.5, 1.0, 5.0), multiplicity: 1, object: 0 };
        let planes = tangent_planes(&edge, &light);
        assert_eq!(planes.len(), 2);
        let side = |plane: &Vec4, p: Vec3| plane.truncate().dot(p) + plane.w;
        for plane in &planes {
            // Every corner of the light on the non-positive side, one on the plane.
            let values: Vec<f32> = light_corners(&light).iter().map(|&y| side(plane, y)).collect();
            assert!(values.iter().all(|&v| v <= 1e-4), "{values:?}");
            assert!(values.iter().any(|&v| v.abs() < 1e-4));
        }
        // Below the edge, on the floor straight under it: in the penumbra, inside both.
        assert!(planes.iter().all(|p| side(p, Vec3::new(0.5, 0.0, 0.0)) >= 0.0));
        // Far to the side on the floor: lit, outside one plane.
        assert!(planes.iter().any(|p| side(p, Vec3::new(4.0, 0.0, 0.0)) < 0.0));
        // An edge whose line passes through the light gives no planes.
        let through = SilhouetteEdge { a: Vec3::new(0.0, 1.0, 0.0), b: Vec3::new(0.0, 5.0, 0.0), multiplicity: 1, object: 0 };
        assert!(tangent_planes(&through, &light).is_empty());
    }
}
