//! Occlusion culling of the wedges method (Assarsson & Akenine-Möller 2003 §4): each
//! primitive's footprint in screen tiles, the tiles' NDC boxes from their zmin/zmax, the test
//! of a (primitive, tile) pair, and the work items the rasteriser runs.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#wedges.

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;

use super::geometry::Volume;
use super::WorkItem;
use crate::light::AreaLight;
use crate::scene::adjacency::SilhouetteEdge;

mod regions;

use regions::{crossing_part, crossing_region, wedge_region};

/// Tiles per side of a culling block.
const BLOCK: u32 = 8;

/// How much a tile's depth range is widened, relative to the depth, on either side.
const DEPTH_MARGIN: f32 = 1e-3;

/// A primitive's footprint for culling: its screen bounding box in tiles, its NDC depth range,
/// and the planes (world space, inside ≥ 0) that bound it.
pub(super) struct Footprint {
    tiles_x: (u32, u32),
    tiles_y: (u32, u32),
    z: (f32, f32),
    planes: Vec<Vec4>,
    /// The primitive's object: receivers that ignore it (`tiles.wgsl`) are not changed by it.
    object: u32,
}

impl Footprint {
    /// No tiles: the primitive changes no receiver.
    fn none(object: u32) -> Self {
        Footprint { tiles_x: (0, 0), tiles_y: (0, 0), z: (0.0, 0.0), planes: Vec::new(), object }
    }
}

/// An NDC box: (x0, x1, y0, y1, z0, z1).
type NdcBox = [f32; 6];

/// What a tile (or a block of tiles) is tested by: its NDC box, the world-space box of its
/// receivers' points (min, max), and for a tile (not a block) the corners of its slab hull
/// where it has one (`slab_hull`).
#[derive(Clone, Copy)]
struct TileBox {
    ndc: NdcBox,
    world: [Vec3; 2],
    hull: Option<[Vec3; 8]>,
    /// The object every covered pixel ignores, or None.
    ignores: Option<u32>,
}

impl TileBox {
    fn union(self, other: Self) -> Self {
        let (u, b) = (self.ndc, other.ndc);
        Self {
            ndc: [u[0].min(b[0]), u[1].max(b[1]), u[2].min(b[2]), u[3].max(b[3]), u[4].min(b[4]), u[5].max(b[5])],
            world: [self.world[0].min(other.world[0]), self.world[1].max(other.world[1])],
            hull: None,
            ignores: if self.ignores == other.ignores { self.ignores } else { None },
        }
    }
}

/// The corners of the region a tile's receivers lie in between the slab they span along one
/// axis (`tiles.wgsl`: the normal at the tile's centre pixel), `lo ≤ axis · x ≤ hi`, and the
/// rays from the eye through the tile's corners (`rays`): the eight points where the rays
/// cross the slab's two planes, whose hull is that region. None where it is unbounded or
/// reaches behind the eye — a ray parallel to the slab, rays crossing it in opposite senses,
/// the eye inside it — or the tile has no axis.
fn slab_hull(eye: Vec3, rays: &[Vec3; 4], axis: Vec3, lo: f32, hi: f32) -> Option<[Vec3; 8]> {
    if axis == Vec3::ZERO || lo > hi {
        return None;
    }
    let from_eye = axis.dot(eye);
    let mut hull = [Vec3::ZERO; 8];
    let sense = axis.dot(rays[0]).signum();
    for (k, ray) in rays.iter().enumerate() {
        let rate = axis.dot(*ray);
        if rate.signum() != sense || rate.abs() <= 1e-6 * ray.length() {
            return None;
        }
        let (near, far) = ((lo - from_eye) / rate, (hi - from_eye) / rate);
        if near <= 0.0 || far <= 0.0 {
            return None;
        }
        hull[2 * k] = eye + *ray * near;
        hull[2 * k + 1] = eye + *ray * far;
    }
    Some(hull)
}

/// The tile grid with each tile's boxes (NDC: x, y from its pixels, z from its depth range;
/// world: its receivers'), and the boxes of blocks of `BLOCK`² tiles.
pub(super) struct TileGrid {
    across: u32,
    /// Pixels per tile side, and the frame's pixels across and down.
    tile: u32,
    pixels: (u32, u32),
    down: u32,
    /// Per tile, or None for background only.
    boxes: Vec<Option<TileBox>>,
    blocks_across: u32,
    /// Per block: the boxes holding every covered tile's, or None for background only.
    blocks: Vec<Option<TileBox>>,
    supers_across: u32,
    /// Per block of `BLOCK`² blocks: the boxes holding every covered block's.
    supers: Vec<Option<TileBox>>,
}

/// What survived culling: per volume polygon and per wedge, the tiles it must be rasterised
/// over, and how many pairs were tested.
pub(super) struct Work {
    pub umbra_tiles: Vec<Vec<u32>>,
    pub wedge_tiles: Vec<Vec<u32>>,
    pub tested: u64,
    /// Index of the first wedge among the rasteriser's primitives (after the polygons).
    wedge_base: u32,
    /// Tiles per row, and pixels per tile side.
    across: u32,
    tile: u32,
}

/// Culls every (primitive, tile) pair in each primitive's bounding box; without `culling`,
/// every such pair survives. `deepest`: how far below the light's plane the scene's deepest
/// point lies (no receiver lies deeper).
#[allow(clippy::too_many_arguments)]
pub(super) fn cull(
    volume: &Volume,
    silhouette: &[SilhouetteEdge],
    light: &AreaLight,
    reach: f32,
    deepest: f32,
    grid: &TileGrid,
    view_proj: &Mat4,
    eye: Vec3,
    culling: bool,
    zfail: bool,
) -> Work {
    let to_ndc = view_proj.inverse().transpose();
    // Primitives are culled independently: on all cores (a frame's culling waits on the CPU
    // while the device idles).
    let deepest = deepest + 1e-5 * reach;
    let umbra: Vec<Footprint> = (volume.polygons.par_iter().zip(&volume.object))
        .map(|(p, &object)| match crossing_part(p, light, eye, deepest, zfail) {
            part if part.is_empty() => Footprint::none(object),
            part => footprint(view_proj, &part, crossing_region(p, eye, zfail), object, grid),
        })
        .collect();
    let wedges: Vec<Footprint> = silhouette
        .par_iter()
        .map(|e| match wedge_region(e, light, reach, deepest) {
            Some((hull, planes)) => footprint(view_proj, &hull, planes, e.object, grid),
            None => Footprint::none(e.object),
        })
        .collect();
    let survivors = |footprint: &Footprint, umbra: bool| -> Vec<u32> {
        let (x, y) = (footprint.tiles_x, footprint.tiles_y);
        if !culling {
            return (y.0..y.1).flat_map(|ty| (x.0..x.1).map(move |tx| ty * grid.across + tx)).collect();
        }
        let planes: Vec<Vec4> = footprint.planes.iter().map(|plane| to_ndc * *plane).collect();
        let test = |b: Option<TileBox>| survives(footprint, &planes, b, umbra, zfail);
        // Blocks of blocks first, then blocks, then the tiles of surviving blocks in
        // row-major order (the single pass looks tiles up by binary search).
        let blocks_x = (x.0 / BLOCK, x.1.div_ceil(BLOCK));
        let blocks_y = (y.0 / BLOCK, y.1.div_ceil(BLOCK));
        let supers_x = (blocks_x.0 / BLOCK, blocks_x.1.div_ceil(BLOCK));
        let supers_open: Vec<bool> = (blocks_y.0 / BLOCK..blocks_y.1.div_ceil(BLOCK))
            .flat_map(|sy| (supers_x.0..supers_x.1).map(move |sx| (sx, sy)))
            .map(|(sx, sy)| test(grid.supers[(sy * grid.supers_across + sx) as usize]))
            .collect();
        let super_row = (supers_x.1 - supers_x.0) as usize;
        let super_open =
            |bx: u32, by: u32| supers_open[(by / BLOCK - blocks_y.0 / BLOCK) as usize * super_row + (bx / BLOCK - supers_x.0) as usize];
        let open: Vec<bool> = (blocks_y.0..blocks_y.1)
            .flat_map(|by| (blocks_x.0..blocks_x.1).map(move |bx| (bx, by)))
            .map(|(bx, by)| super_open(bx, by) && test(grid.blocks[(by * grid.blocks_across + bx) as usize]))
            .collect();
        let row = (blocks_x.1 - blocks_x.0) as usize;
        let mut kept = Vec::new();
        for ty in y.0..y.1 {
            let blocks = &open[(ty / BLOCK - y.0 / BLOCK) as usize * row..][..row];
            // A closed block is passed over as a whole: nearly every block of a large wedge's
            // bounding box is closed (terrain: 99.8 % of its tiles culled), and visiting its
            // tiles one by one only to skip them was most of the culling's time.
            for (bx, _) in (blocks_x.0..).zip(blocks).filter(|(_, &open)| open) {
                for tx in (bx * BLOCK).max(x.0)..((bx + 1) * BLOCK).min(x.1) {
                    let t = ty * grid.across + tx;
                    if test(grid.boxes[t as usize]) {
                        kept.push(t);
                    }
                }
            }
        }
        kept
    };
    let tested = umbra
        .iter()
        .chain(&wedges)
        .map(|f| u64::from(f.tiles_x.1.saturating_sub(f.tiles_x.0)) * u64::from(f.tiles_y.1.saturating_sub(f.tiles_y.0)))
        .sum();
    let umbra_tiles: Vec<Vec<u32>> = umbra.par_iter().map(|f| survivors(f, true)).collect();
    let wedge_tiles: Vec<Vec<u32>> = wedges.par_iter().map(|f| survivors(f, false)).collect();
    Work { umbra_tiles, wedge_tiles, tested, wedge_base: volume.polygons.len() as u32, across: grid.across, tile: grid.tile }
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
        let (across, side) = (self.across, self.tile);
        // The tile's first pixel, packed, so that the rasteriser divides by nothing.
        let item = |primitive, tile: u32, both| {
            let origin = ((tile % across) * side) | (((tile / across) * side) << 16);
            WorkItem { primitive, tile, both, origin }
        };
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
    /// `ranges`: per tile, as `tiles.wgsl` writes them, the world-space box of its receivers
    /// with their view depth range in w (lo, hi), and the slab they span along an axis (the
    /// axis and the slab's low end, then its high end).
    pub fn new(
        size: (u32, u32),
        tile: u32,
        pixels: (u32, u32),
        ranges: &[[[f32; 4]; 4]],
        camera: &crate::render::Camera,
        view_proj: &Mat4,
    ) -> Self {
        let unproject = view_proj.inverse();
        // The direction from the eye through an NDC point (x, y).
        let ray = |x: f32, y: f32| unproject.project_point3(Vec3::new(x, y, 0.5)) - camera.eye;
        let forward = camera.forward();
        let ndc_z = |d: f32| {
            let clip = *view_proj * (camera.eye + forward * d).extend(1.0);
            clip.z / clip.w
        };
        // Half a pixel beyond the tile on every side, in NDC.
        let (half_x, half_y) = (1.0 / pixels.0 as f32, 1.0 / pixels.1 as f32);
        let px = |x: u32| 2.0 * (x.min(pixels.0)) as f32 / pixels.0 as f32 - 1.0;
        let py = |y: u32| 1.0 - 2.0 * (y.min(pixels.1)) as f32 / pixels.1 as f32;
        let boxes: Vec<Option<TileBox>> = (0..size.0 * size.1)
            .map(|t| {
                let [lo, hi, axis, most] = ranges[t as usize];
                let (zmin, zmax) = (lo[3], hi[3]);
                if zmin > zmax {
                    return None;
                }
                let (tx, ty) = (t % size.0, t / size.0);
                // The same margin as the depth range's, a thousandth of the view depth.
                let margin = DEPTH_MARGIN * zmax.abs();
                let (x0, x1) = (px(tx * tile) - half_x, px((tx + 1) * tile) + half_x);
                let (y0, y1) = (py((ty + 1) * tile) - half_y, py(ty * tile) + half_y);
                let axis_direction = Vec3::from_slice(&axis[..3]);
                let rays = [ray(x0, y0), ray(x1, y0), ray(x1, y1), ray(x0, y1)];
                // The slab widens by the same margin as the boxes (in metres along the axis).
                let slab_margin = margin * axis_direction.length();
                Some(TileBox {
                    ndc: [x0, x1, y0, y1, ndc_z(zmin * (1.0 - DEPTH_MARGIN)), ndc_z(zmax * (1.0 + DEPTH_MARGIN))],
                    world: [Vec3::from_slice(&lo[..3]) - Vec3::splat(margin), Vec3::from_slice(&hi[..3]) + Vec3::splat(margin)],
                    hull: slab_hull(camera.eye, &rays, axis_direction, axis[3] - slab_margin, most[0] + slab_margin),
                    // An object id as `tiles.wgsl` writes it, a float; negative: none.
                    ignores: (most[1] >= 0.0).then_some(most[1] as u32),
                })
            })
            .collect();
        let (blocks_across, blocks) = in_blocks(&boxes, size.0, size.1);
        let (supers_across, supers) = in_blocks(&blocks, blocks_across, size.1.div_ceil(BLOCK));
        Self { across: size.0, tile, pixels, down: size.1, boxes, blocks_across, blocks, supers_across, supers }
    }
}

/// A grid of boxes (`across` × `down`, row-major) gathered into blocks of `BLOCK`²: each
/// block's boxes hold every covered member's, or None where none is covered. Returns the
/// blocks per row and the blocks.
fn in_blocks(boxes: &[Option<TileBox>], across: u32, down: u32) -> (u32, Vec<Option<TileBox>>) {
    let blocks_across = across.div_ceil(BLOCK);
    let mut blocks: Vec<Option<TileBox>> = vec![None; (blocks_across * down.div_ceil(BLOCK)) as usize];
    for (i, member) in boxes.iter().enumerate() {
        let Some(b) = member else { continue };
        let (x, y) = (i as u32 % across, i as u32 / across);
        let block = &mut blocks[((y / BLOCK) * blocks_across + x / BLOCK) as usize];
        *block = Some(block.map_or(*b, |u| u.union(*b)));
    }
    (blocks_across, blocks)
}

/// A primitive's bounding box in tiles and NDC depth range; points behind the eye make it
/// cover the whole screen and every depth.
fn footprint(view_proj: &Mat4, points: &[Vec3], planes: Vec<Vec4>, object: u32, grid: &TileGrid) -> Footprint {
    let clips: Vec<Vec4> = points.iter().map(|p| *view_proj * p.extend(1.0)).collect();
    if clips.iter().any(|c| c.w <= 1e-6) {
        return Footprint { tiles_x: (0, grid.across), tiles_y: (0, grid.down), z: (f32::NEG_INFINITY, f32::INFINITY), planes, object };
    }
    let ndc: Vec<Vec3> = clips.iter().map(|c| c.truncate() / c.w).collect();
    let min = ndc.iter().fold(Vec3::splat(f32::INFINITY), |m, p| m.min(*p));
    let max = ndc.iter().fold(Vec3::splat(f32::NEG_INFINITY), |m, p| m.max(*p));
    // NDC x → pixel column → tile column, NDC y (up) → pixel row → tile row (down): through
    // pixels, since where the tile does not divide the frame the last tile is cut short and
    // the grid spans more than the screen.
    let (width, height, tile) = (grid.pixels.0 as f32, grid.pixels.1 as f32, grid.tile as f32);
    let column = |x: f32| (((x * 0.5 + 0.5) * width / tile).floor().max(0.0) as u32).min(grid.across);
    let row = |y: f32| (((0.5 - y * 0.5) * height / tile).floor().max(0.0) as u32).min(grid.down);
    Footprint {
        tiles_x: (column(min.x), (column(max.x) + 1).min(grid.across)),
        tiles_y: (row(max.y), (row(min.y) + 1).min(grid.down)),
        z: (min.z, max.z),
        planes,
        object,
    }
}

/// Occlusion culling of one primitive over one tile or block (§4): background holds nothing,
/// nor does a tile whose pixels all ignore the primitive's object; the quick rejection
/// compares depth ranges — a volume polygon only with zmax (z-pass: it must lie in front of
/// something) or zmin (z-fail: behind something), a wedge with both — and then the region's
/// planes, in NDC (`planes`), are tested with the NDC box's p-vertex (Fig. 7), and in world
/// space (`footprint.planes`) with the world box's and with the corners of the tile's slab
/// hull where it has one.
fn survives(footprint: &Footprint, planes: &[Vec4], tile_box: Option<TileBox>, umbra: bool, zfail: bool) -> bool {
    let Some(TileBox { ndc: [x0, x1, y0, y1, z0, z1], world: [lo, hi], hull, ignores }) = tile_box else {
        return false;
    };
    if ignores == Some(footprint.object) {
        return false;
    }
    let (zmin, zmax) = footprint.z;
    let quick = if !umbra {
        zmin <= z1 && zmax >= z0
    } else if zfail {
        zmax >= z0
    } else {
        zmin <= z1
    };
    let p_vertex_inside =
        |p: &Vec4, lo: Vec3, hi: Vec3| p.truncate().dot(Vec3::select(p.truncate().cmpgt(Vec3::ZERO), hi, lo)) + p.w >= 0.0;
    let ndc = (Vec3::new(x0, y0, z0), Vec3::new(x1, y1, z1));
    let hull_inside = |p: &Vec4, hull: &[Vec3; 8]| hull.iter().any(|v| p.truncate().dot(*v) + p.w >= 0.0);
    quick
        && planes.iter().all(|p| p_vertex_inside(p, ndc.0, ndc.1))
        && footprint.planes.iter().all(|p| p_vertex_inside(p, lo, hi))
        && hull.is_none_or(|hull| footprint.planes.iter().all(|p| hull_inside(p, &hull)))
}

#[cfg(test)]
mod tests;
