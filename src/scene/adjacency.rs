//! Mesh adjacency for the object-space method `wedges` (Assarsson & Akenine-Möller 2003):
//! vertices welded by position, every undirected edge with the triangles that use it, the
//! surfaces they make up, and the silhouette edges seen from a point.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#surfaces-and-silhouettes-in-the-code-sceneadjacencyrs.

use std::collections::{HashMap, HashSet};

use glam::Vec3;

/// One undirected edge, `a < b`, used by `faces` (a range of `EdgeMesh::uses`).
#[derive(Debug, Clone, Copy)]
pub struct Edge {
    pub a: u32,
    pub b: u32,
    first_use: u32,
    use_count: u32,
}

/// A triangle's use of an edge: which triangle, and whether it runs a → b (else b → a), in
/// the triangle's winding as `EdgeMesh::triangles` holds it.
#[derive(Debug, Clone, Copy)]
struct EdgeUse {
    triangle: u32,
    forward: bool,
}

/// What adjacency found about a mesh.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AdjacencyStats {
    pub vertices: usize,
    pub triangles: usize,
    pub edges: usize,
    /// Edges with one triangle: the mesh is open there.
    pub boundary_edges: usize,
    /// Edges with more than two triangles.
    pub non_manifold_edges: usize,
    /// Edges whose two triangles ran them the same way as the file wound them (inconsistent
    /// winding), before the winding was made consistent.
    pub inconsistent_edges: usize,
    /// Triangles dropped for repeating a vertex or having no area.
    pub degenerate_triangles: usize,
    /// Triangles dropped for repeating another's three vertices (either winding).
    pub duplicate_triangles: usize,
    /// Triangles whose winding was turned to agree with their surface (or turned outward).
    pub reoriented_triangles: usize,
    /// Connected surfaces (through shared edges), and those of them that are open.
    pub surfaces: usize,
    pub open_surfaces: usize,
}

/// A silhouette edge, oriented so that its multiplicity is positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SilhouetteEdge {
    pub a: Vec3,
    pub b: Vec3,
    /// How many times the casting triangles' boundary runs a → b (1 for a closed mesh).
    pub multiplicity: u32,
    /// The object of a casting triangle on the edge.
    pub object: u32,
}

pub struct EdgeMesh {
    pub positions: Vec<Vec3>,
    /// Wound consistently within each surface, closed surfaces outward.
    pub triangles: Vec<[u32; 3]>,
    /// Object id by triangle.
    pub objects: Vec<u32>,
    /// Unnormalised normals (b − a) × (c − a), by triangle.
    normals: Vec<Vec3>,
    /// By triangle: its surface (connected through edges), and by surface whether it is
    /// closed (it casts from its front only).
    surface: Vec<u32>,
    closed: Vec<bool>,
    pub edges: Vec<Edge>,
    uses: Vec<EdgeUse>,
    pub stats: AdjacencyStats,
}

/// Disjoint sets of triangles (union by size, path halving).
struct Sets {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl Sets {
    fn new(n: usize) -> Self {
        Self { parent: (0..n as u32).collect(), size: vec![1; n] }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let up = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = up;
            x = up;
        }
        x
    }

    fn union(&mut self, a: u32, b: u32) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a as usize] < self.size[b as usize] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b as usize] = a;
        self.size[a as usize] += self.size[b as usize];
    }
}

/// Every directed use of an edge by `triangles`, sorted so that one edge's uses are adjacent,
/// and the edges they make.
fn edges_of(triangles: &[[u32; 3]]) -> (Vec<Edge>, Vec<EdgeUse>) {
    let mut uses: Vec<(u32, u32, EdgeUse)> = triangles
        .iter()
        .enumerate()
        .flat_map(|(t, tri)| {
            (0..3).map(move |k| {
                let (from, to) = (tri[k], tri[(k + 1) % 3]);
                (from.min(to), from.max(to), EdgeUse { triangle: t as u32, forward: from < to })
            })
        })
        .collect();
    uses.sort_unstable_by_key(|&(a, b, u)| (a, b, u.triangle));
    let mut edges = Vec::new();
    let mut start = 0;
    while start < uses.len() {
        let (a, b) = (uses[start].0, uses[start].1);
        let end = start + uses[start..].iter().take_while(|u| (u.0, u.1) == (a, b)).count();
        edges.push(Edge { a, b, first_use: start as u32, use_count: (end - start) as u32 });
        start = end;
    }
    (edges, uses.into_iter().map(|u| u.2).collect())
}

impl EdgeMesh {
    /// Builds adjacency for triangles `indices` (three per triangle) into `positions`, whose
    /// vertices belong to objects `vertex_objects` (empty: all object 0).
    pub fn build(positions: &[Vec3], indices: &[u32], vertex_objects: &[u32]) -> Self {
        // Weld vertices that share a position exactly: meshes split them for normals or uvs.
        let mut welded: HashMap<[u32; 3], u32> = HashMap::new();
        let mut unique = Vec::new();
        let remap: Vec<u32> = positions
            .iter()
            .map(|p| {
                *welded.entry(p.to_array().map(f32::to_bits)).or_insert_with(|| {
                    unique.push(*p);
                    unique.len() as u32 - 1
                })
            })
            .collect();
        let mut stats = AdjacencyStats { vertices: unique.len(), ..Default::default() };
        let mut triangles = Vec::with_capacity(indices.len() / 3);
        let mut objects = Vec::with_capacity(indices.len() / 3);
        let mut seen: HashSet<[u32; 3]> = HashSet::new();
        for t in indices.chunks_exact(3) {
            let [a, b, c] = [remap[t[0] as usize], remap[t[1] as usize], remap[t[2] as usize]];
            let normal = (unique[b as usize] - unique[a as usize]).cross(unique[c as usize] - unique[a as usize]);
            if a == b || b == c || a == c || normal.length_squared() == 0.0 || !normal.is_finite() {
                stats.degenerate_triangles += 1;
                continue;
            }
            let mut key = [a, b, c];
            key.sort_unstable();
            if !seen.insert(key) {
                stats.duplicate_triangles += 1;
                continue;
            }
            triangles.push([a, b, c]);
            objects.push(vertex_objects.get(t[0] as usize).copied().unwrap_or(0));
        }
        stats.triangles = triangles.len();
        let (edges, uses) = edges_of(&triangles);
        for e in &edges {
            let uses = &uses[e.first_use as usize..(e.first_use + e.use_count) as usize];
            match uses.len() {
                1 => stats.boundary_edges += 1,
                2 if uses[0].forward == uses[1].forward => stats.inconsistent_edges += 1,
                2 => {}
                _ => stats.non_manifold_edges += 1,
            }
        }
        let (surface, closed) = orient(&unique, &mut triangles, &edges, &uses, &mut stats);
        // The winding changed: the uses follow it.
        let (edges, uses) = edges_of(&triangles);
        let normals = triangles
            .iter()
            .map(|t| (unique[t[1] as usize] - unique[t[0] as usize]).cross(unique[t[2] as usize] - unique[t[0] as usize]))
            .collect();
        stats.edges = edges.len();
        Self { positions: unique, triangles, objects, normals, surface, closed, edges, uses, stats }
    }

    /// Which side of triangle `t` `point` lies on: positive where it sees the triangle wound
    /// counter-clockwise (the front), negative behind, 0 in its plane.
    fn side(&self, t: usize, point: Vec3) -> f32 {
        self.normals[t].dot(point - self.positions[self.triangles[t][0] as usize])
    }

    /// Which triangles cast a shadow from `point`, and which way round (the module doc).
    pub fn casting(&self, point: Vec3) -> Casting {
        let mut by_triangle: Vec<Option<bool>> = (0..self.triangles.len())
            .map(|t| match self.side(t, point) {
                s if s > 0.0 => Some(true),
                s if s < 0.0 && !self.closed[self.surface[t] as usize] => Some(false),
                _ => None,
            })
            .collect();
        let backs: Vec<usize> = (0..by_triangle.len()).filter(|&t| by_triangle[t] == Some(false)).collect();
        if !backs.is_empty() {
            let fronts = FrontFaces::new(self, point, |t| by_triangle[t] == Some(true) && !self.closed[self.surface[t] as usize]);
            for t in backs {
                let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
                if fronts.hides(self, (a + b + c) / 3.0, self.surface[t]) {
                    by_triangle[t] = None;
                }
            }
        }
        Casting { by_triangle }
    }

    /// The casting triangles, each turned towards the point: the caps of its volume.
    pub fn casting_triangles<'a>(&'a self, casting: &'a Casting) -> impl Iterator<Item = (usize, [Vec3; 3])> + 'a {
        casting.by_triangle.iter().enumerate().filter_map(move |(t, how)| {
            let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
            how.map(|front| (t, if front { [a, b, c] } else { [a, c, b] }))
        })
    }

    /// The silhouette seen from the point `casting` was made for: the oriented boundary of the
    /// casting triangles.
    pub fn silhouette(&self, casting: &Casting) -> Vec<SilhouetteEdge> {
        let casting = &casting.by_triangle;
        self.edges
            .iter()
            .filter_map(|e| {
                let uses = &self.uses[e.first_use as usize..(e.first_use + e.use_count) as usize];
                let m: i32 =
                    uses.iter().filter_map(|u| casting[u.triangle as usize].map(|front| if u.forward == front { 1 } else { -1 })).sum();
                let (a, b) = (self.positions[e.a as usize], self.positions[e.b as usize]);
                let object = uses.iter().find(|u| casting[u.triangle as usize].is_some()).map_or(0, |u| self.objects[u.triangle as usize]);
                match m {
                    0 => None,
                    m if m > 0 => Some(SilhouetteEdge { a, b, multiplicity: m as u32, object }),
                    m => Some(SilhouetteEdge { a: b, b: a, multiplicity: (-m) as u32, object }),
                }
            })
            .collect()
    }
}

/// How each triangle casts from one point: `Some(true)` in its own winding, `Some(false)`
/// turned over (an open surface's back face that nothing of it closes off), `None` not at all.
pub struct Casting {
    by_triangle: Vec<Option<bool>>,
}

/// Front faces of open surfaces as seen from a point, in a grid over their projection, for
/// asking whether a segment from a surface's back face to the point crosses the same surface
/// first. The projection is the gnomonic one about the mean direction of the triangles'
/// corners, so a segment to the point is a point in it; triangles with a corner near or
/// behind the projection's plane are left out (they answer "not hidden": cast).
struct FrontFaces {
    point: Vec3,
    axes: [Vec3; 3],
    lo: glam::Vec2,
    scale: glam::Vec2,
    side: usize,
    cells: Vec<Vec<u32>>,
    /// Triangles over more than `LARGE_CELLS` cells, tested by every query.
    large: Vec<u32>,
}

/// A triangle over more cells than this is listed among `FrontFaces::large`.
const LARGE_CELLS: usize = 64;
/// The most large triangles kept: every query tests them all.
const MAX_LARGE: usize = 1024;

impl FrontFaces {
    fn new(mesh: &EdgeMesh, point: Vec3, chosen: impl Fn(usize) -> bool) -> Self {
        let chosen: Vec<usize> = (0..mesh.triangles.len()).filter(|&t| chosen(t)).collect();
        let mean = chosen
            .iter()
            .flat_map(|&t| mesh.triangles[t].map(|i| (mesh.positions[i as usize] - point).normalize_or_zero()))
            .fold(Vec3::ZERO, |a, d| a + d);
        let forward = mean.try_normalize().unwrap_or(Vec3::NEG_Y);
        let right = forward.any_orthonormal_vector();
        let axes = [right, forward.cross(right), forward];
        let mut fronts =
            FrontFaces { point, axes, lo: glam::Vec2::ZERO, scale: glam::Vec2::ONE, side: 1, cells: vec![Vec::new()], large: Vec::new() };
        let projected: Vec<(usize, [glam::Vec2; 3])> = chosen
            .iter()
            .filter_map(|&t| {
                let [a, b, c] = mesh.triangles[t].map(|i| fronts.project(mesh.positions[i as usize]));
                Some((t, [a?, b?, c?]))
            })
            .collect();
        if projected.is_empty() {
            return fronts;
        }
        let (lo, hi) =
            projected.iter().flat_map(|(_, p)| *p).fold((glam::Vec2::MAX, glam::Vec2::MIN), |(lo, hi), p| (lo.min(p), hi.max(p)));
        fronts.side = ((projected.len() as f32).sqrt() as usize).clamp(1, 512);
        fronts.lo = lo;
        fronts.scale = fronts.side as f32 / (hi - lo).max(glam::Vec2::splat(1e-12));
        fronts.cells = vec![Vec::new(); fronts.side * fronts.side];
        for (t, p) in projected {
            let (a, b) = (fronts.cell(p[0].min(p[1]).min(p[2])), fronts.cell(p[0].max(p[1]).max(p[2])));
            // A triangle over many cells is listed once, among the ones every query tests, so
            // that a scene of large triangles costs lists, not cells; past `MAX_LARGE` of them
            // the rest are left out (their back faces then cast: the paper's count, not none).
            if (b.0 - a.0 + 1) * (b.1 - a.1 + 1) > LARGE_CELLS {
                if fronts.large.len() < MAX_LARGE {
                    fronts.large.push(t as u32);
                }
                continue;
            }
            for y in a.1..=b.1 {
                for x in a.0..=b.0 {
                    fronts.cells[y * fronts.side + x].push(t as u32);
                }
            }
        }
        fronts
    }

    /// `p` in the projection, if it lies well in front of the projection's plane.
    fn project(&self, p: Vec3) -> Option<glam::Vec2> {
        let d = p - self.point;
        let z = d.dot(self.axes[2]);
        (z > 1e-3 * d.length()).then(|| glam::Vec2::new(d.dot(self.axes[0]), d.dot(self.axes[1])) / z)
    }

    fn cell(&self, p: glam::Vec2) -> (usize, usize) {
        let c = ((p - self.lo) * self.scale).as_ivec2().clamp(glam::IVec2::ZERO, glam::IVec2::splat(self.side as i32 - 1));
        (c.x as usize, c.y as usize)
    }

    /// Whether the open segment from `from` to the point crosses a front face of `surface`.
    fn hides(&self, mesh: &EdgeMesh, from: Vec3, surface: u32) -> bool {
        let Some(p) = self.project(from) else { return false };
        let (x, y) = self.cell(p);
        let dir = from - self.point;
        self.cells[y * self.side + x].iter().chain(&self.large).any(|&t| {
            mesh.surface[t as usize] == surface && {
                let [a, b, c] = mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]);
                crosses(self.point, dir, [a, b, c])
            }
        })
    }
}

/// Whether the open segment `origin + s·dir`, 0 < s < 1, crosses triangle `tri` (Möller–Trumbore).
pub fn crosses(origin: Vec3, dir: Vec3, [a, b, c]: [Vec3; 3]) -> bool {
    let (e1, e2) = (b - a, c - a);
    let h = dir.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return false;
    }
    let s = origin - a;
    let u = s.dot(h) / det;
    let q = s.cross(e1);
    let v = dir.dot(q) / det;
    let t = e2.dot(q) / det;
    u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 1e-6 && t < 1.0 - 1e-6
}

/// Makes each surface's winding consistent and each closed surface face outward, and says by
/// triangle whether its surface is closed.
///
/// Winding spreads from triangle to triangle across edges of exactly two uses (where a third
/// face joins, which side is which is not defined); a patch that meets itself the wrong way
/// (a Möbius strip) cannot be oriented and stays open. Each patch keeps the winding most of
/// its triangles had (what the author meant), then a closed one is turned outward by the sign
/// of the volume it encloses. A surface — triangles connected through any edge — is closed when
/// every one of its edges is run as often one way as the other.
fn orient(
    positions: &[Vec3],
    triangles: &mut [[u32; 3]],
    edges: &[Edge],
    uses: &[EdgeUse],
    stats: &mut AdjacencyStats,
) -> (Vec<u32>, Vec<bool>) {
    let n = triangles.len();
    let mut surfaces = Sets::new(n);
    // Per triangle, its neighbours across two-use edges and whether the pair runs the edge the
    // same way (then one of them must turn over).
    let mut across: Vec<Vec<(u32, bool)>> = vec![Vec::new(); n];
    for e in edges {
        let uses = &uses[e.first_use as usize..(e.first_use + e.use_count) as usize];
        for u in &uses[1..] {
            surfaces.union(uses[0].triangle, u.triangle);
        }
        if let [p, q] = uses {
            let same = p.forward == q.forward;
            across[p.triangle as usize].push((q.triangle, same));
            across[q.triangle as usize].push((p.triangle, same));
        }
    }
    let mut flip = vec![false; n];
    let mut patch = vec![u32::MAX; n];
    let mut unorientable = vec![false; n];
    let mut patches: Vec<Vec<u32>> = Vec::new();
    for seed in 0..n {
        if patch[seed] != u32::MAX {
            continue;
        }
        let id = patches.len() as u32;
        let (mut members, mut stack, mut twisted) = (vec![seed as u32], vec![seed as u32], false);
        patch[seed] = id;
        while let Some(t) = stack.pop() {
            for &(other, same) in &across[t as usize] {
                let wanted = flip[t as usize] ^ same;
                if patch[other as usize] == u32::MAX {
                    patch[other as usize] = id;
                    flip[other as usize] = wanted;
                    members.push(other);
                    stack.push(other);
                } else if flip[other as usize] != wanted {
                    twisted = true;
                }
            }
        }
        if 2 * members.iter().filter(|&&t| flip[t as usize]).count() > members.len() {
            for &t in &members {
                flip[t as usize] = !flip[t as usize];
            }
        }
        if twisted {
            for &t in &members {
                unorientable[t as usize] = true;
            }
        }
        patches.push(members);
    }
    let turn = |t: &mut [u32; 3]| t.swap(1, 2);
    for (t, tri) in triangles.iter_mut().enumerate() {
        if flip[t] {
            turn(tri);
        }
    }
    // Closed surfaces: every edge balanced in the winding now held.
    let mut root_open: HashMap<u32, bool> = HashMap::new();
    for e in edges {
        let uses = &uses[e.first_use as usize..(e.first_use + e.use_count) as usize];
        let balance: i32 = uses.iter().map(|u| if u.forward != flip[u.triangle as usize] { 1 } else { -1 }).sum();
        let open = balance != 0 || uses.iter().any(|u| unorientable[u.triangle as usize]);
        *root_open.entry(surfaces.find(uses[0].triangle)).or_default() |= open;
    }
    let closed: Vec<bool> = (0..n as u32).map(|t| !root_open.get(&surfaces.find(t)).copied().unwrap_or(true)).collect();
    // Outward: a closed patch enclosing negative volume (about its own first vertex, which
    // changes nothing for a closed surface) is inside out.
    for members in &patches {
        if !closed[members[0] as usize] {
            continue;
        }
        let origin = positions[triangles[members[0] as usize][0] as usize];
        let volume: f32 = members
            .iter()
            .map(|&t| {
                let [a, b, c] = triangles[t as usize].map(|i| positions[i as usize] - origin);
                a.dot(b.cross(c))
            })
            .sum();
        if volume < 0.0 {
            for &t in members {
                turn(&mut triangles[t as usize]);
                flip[t as usize] = !flip[t as usize];
            }
        }
    }
    stats.reoriented_triangles = flip.iter().filter(|&&f| f).count();
    // Surfaces numbered from 0 in the order of their first triangle.
    let mut ids: HashMap<u32, u32> = HashMap::new();
    let mut closed_by_surface = Vec::new();
    let surface: Vec<u32> = (0..n)
        .map(|t| {
            *ids.entry(surfaces.find(t as u32)).or_insert_with(|| {
                closed_by_surface.push(closed[t]);
                closed_by_surface.len() as u32 - 1
            })
        })
        .collect();
    stats.surfaces = closed_by_surface.len();
    stats.open_surfaces = closed_by_surface.iter().filter(|closed| !**closed).count();
    (surface, closed_by_surface)
}

#[cfg(test)]
mod tests;
