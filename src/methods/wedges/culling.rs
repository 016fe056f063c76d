//! Occlusion culling of the wedges method (Assarsson & Akenine-Möller 2003 §4): each
//! primitive's footprint in screen tiles, the tiles' NDC boxes from their zmin/zmax, the test
//! of a (primitive, tile) pair, and the work items the rasteriser runs.

use glam::{Mat4, Vec3, Vec4};

use super::geometry::{wedge_hull, Volume};
use super::WorkItem;
use crate::light::AreaLight;
use crate::scene::adjacency::SilhouetteEdge;

/// A primitive's footprint for culling: its screen bounding box in tiles, its NDC depth range,
/// and the planes (world space, inside ≥ 0) that bound it.
pub(super) struct Footprint {
    tiles_x: (u32, u32),
    tiles_y: (u32, u32),
    z: (f32, f32),
    planes: Vec<Vec4>,
}

/// The tile grid with each tile's NDC box (x, y from its pixels, z from its depth range).
pub(super) struct TileGrid {
    across: u32,
    down: u32,
    /// Per tile: (x0, x1, y0, y1, z0, z1) in NDC, or None for background only.
    boxes: Vec<Option<[f32; 6]>>,
}

/// What survived culling: per volume polygon and per wedge, the tiles it must be rasterised
/// over, and how many pairs were tested.
pub(super) struct Work {
    pub umbra_tiles: Vec<Vec<u32>>,
    pub wedge_tiles: Vec<Vec<u32>>,
    pub tested: u64,
    /// Index of the first wedge among the rasteriser's primitives (after the polygons).
    wedge_base: u32,
}

/// Culls every (primitive, tile) pair in each primitive's bounding box; without `culling`,
/// every such pair survives.
#[allow(clippy::too_many_arguments)]
pub(super) fn cull(
    volume: &Volume,
    silhouette: &[SilhouetteEdge],
    light: &AreaLight,
    reach: f32,
    grid: &TileGrid,
    view_proj: &Mat4,
    culling: bool,
    zfail: bool,
) -> Work {
    let polygons = &volume.polygons;
    let wedge_planes = &volume.wedge_planes;
    // Cull: every (primitive, tile) pair in the primitive's bounding box is tested.
    let to_ndc = view_proj.inverse().transpose();
    let mut tested = 0u64;
    let umbra_footprints: Vec<Footprint> = polygons.iter().map(|p| footprint(view_proj, p, Vec::new(), grid)).collect();
    let wedge_footprints: Vec<Footprint> = silhouette
        .iter()
        .zip(wedge_planes)
        .map(|(e, planes)| footprint(view_proj, &wedge_hull(e, light, reach), planes.clone(), grid))
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
    Work { umbra_tiles, wedge_tiles, tested, wedge_base: polygons.len() as u32 }
}

impl Work {
    /// (primitive, tile) pairs that survived.
    pub fn rasterized(&self) -> u64 {
        self.umbra_tiles.iter().chain(&self.wedge_tiles).map(Vec::len).sum::<usize>() as u64
    }

    /// The rasteriser's passes, each its pipeline and its work items (§6): three passes run
    /// the volume polygons (`umbra`), then the wedges (`penumbra`); a single pass (`both`)
    /// runs an edge's side quad and wedge together in the tiles both touch.
    pub fn passes<'p>(
        &self,
        single: bool,
        [umbra, penumbra, both]: [&'p wgpu::ComputePipeline; 3],
    ) -> Vec<(&'p wgpu::ComputePipeline, Vec<WorkItem>)> {
        let wedge_base = self.wedge_base;
        let item = |primitive, tile, both| WorkItem { primitive, tile, both, _pad: 0 };
        if single {
            let mut items = Vec::new();
            for (i, quad_tiles) in self.umbra_tiles.iter().enumerate() {
                let wedge = self.wedge_tiles.get(i);
                for &t in quad_tiles {
                    let shared = wedge.is_some_and(|w| w.binary_search(&t).is_ok());
                    items.push(item(i as u32, t, if shared { i as u32 + 1 } else { 0 }));
                }
                if let Some(w) = wedge {
                    items.extend(w.iter().filter(|t| quad_tiles.binary_search(t).is_err()).map(|&t| item(wedge_base + i as u32, t, 0)));
                }
            }
            vec![(both, items)]
        } else {
            let volume = self.umbra_tiles.iter().enumerate().flat_map(|(i, ts)| ts.iter().map(move |&t| item(i as u32, t, 0)));
            let wedges = self.wedge_tiles.iter().enumerate().flat_map(|(i, ts)| ts.iter().map(move |&t| item(wedge_base + i as u32, t, 0)));
            vec![(umbra, volume.collect()), (penumbra, wedges.collect())]
        }
    }
}

impl TileGrid {
    pub fn new(
        size: (u32, u32),
        tile: u32,
        pixels: (u32, u32),
        depth: &[[f32; 2]],
        camera: &crate::render::Camera,
        view_proj: &Mat4,
    ) -> Self {
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
