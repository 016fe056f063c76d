//! Mesh adjacency for the object-space method `wedges` (Assarsson & Akenine-Möller 2003):
//! vertices welded by position, every undirected edge with the triangles that use it, the
//! surfaces they make up, and the silhouette edges seen from a point.
//!
//! The design, and each choice where the paper is vague: docs/methods.md#surfaces-and-silhouettes-in-the-code-sceneadjacencyrs.

use std::collections::{HashMap, HashSet};

use glam::Vec3;

mod casting;

use casting::FrontFaces;
pub use casting::{crosses, Casting};

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
