//! Mesh adjacency for the object-space method `wedges` (Assarsson & Akenine-Möller 2003):
//! vertices welded by position, every undirected edge with the triangles that use it, and the
//! silhouette edges seen from a point.
//!
//! The silhouette is the oriented boundary of the triangles that face the point: each such
//! triangle contributes its three edges in its own winding, and an edge's multiplicity is the
//! number of uses a→b minus the uses b→a. Between a front- and a back-facing triangle of a
//! consistently wound closed mesh that is ±1; between two front-facing ones 0. Being a
//! boundary, the result is always closed — every vertex has as many silhouette edges in as
//! out — whatever the mesh: an open mesh gets the border of its front-facing part (a surface
//! facing away from the point casts nothing, as with back-face culling from the light),
//! a non-manifold edge whatever its triangles add up to, and degenerate triangles are dropped.

use std::collections::HashMap;

use glam::Vec3;

/// One undirected edge, `a < b`, used by `faces` (a range of `EdgeMesh::uses`).
#[derive(Debug, Clone, Copy)]
pub struct Edge {
    pub a: u32,
    pub b: u32,
    first_use: u32,
    use_count: u32,
}

/// A triangle's use of an edge: which triangle, and whether it runs a → b (else b → a).
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
    /// Edges whose two triangles run them the same way (inconsistent winding).
    pub inconsistent_edges: usize,
    /// Triangles dropped for repeating a vertex or having no area.
    pub degenerate_triangles: usize,
}

/// A silhouette edge, oriented so that its multiplicity is positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SilhouetteEdge {
    pub a: Vec3,
    pub b: Vec3,
    /// How many times the front-facing triangles' boundary runs a → b (1 for a closed mesh).
    pub multiplicity: u32,
    /// The object of a front-facing triangle on the edge.
    pub object: u32,
}

pub struct EdgeMesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Object id by triangle.
    pub objects: Vec<u32>,
    /// Unnormalised normals (b − a) × (c − a), by triangle.
    normals: Vec<Vec3>,
    pub edges: Vec<Edge>,
    uses: Vec<EdgeUse>,
    pub stats: AdjacencyStats,
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
        let mut normals = Vec::with_capacity(indices.len() / 3);
        let mut objects = Vec::with_capacity(indices.len() / 3);
        for t in indices.chunks_exact(3) {
            let [a, b, c] = [remap[t[0] as usize], remap[t[1] as usize], remap[t[2] as usize]];
            let normal = (unique[b as usize] - unique[a as usize]).cross(unique[c as usize] - unique[a as usize]);
            if a == b || b == c || a == c || normal.length_squared() == 0.0 || !normal.is_finite() {
                stats.degenerate_triangles += 1;
                continue;
            }
            triangles.push([a, b, c]);
            normals.push(normal);
            objects.push(vertex_objects.get(t[0] as usize).copied().unwrap_or(0));
        }
        stats.triangles = triangles.len();
        // Every directed use of an edge, sorted so that one edge's uses are adjacent.
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
            let count = end - start;
            match count {
                1 => stats.boundary_edges += 1,
                2 if uses[start].2.forward == uses[start + 1].2.forward => stats.inconsistent_edges += 1,
                2 => {}
                _ => stats.non_manifold_edges += 1,
            }
            edges.push(Edge { a, b, first_use: start as u32, use_count: count as u32 });
            start = end;
        }
        stats.edges = edges.len();
        Self { positions: unique, triangles, objects, normals, edges, uses: uses.into_iter().map(|u| u.2).collect(), stats }
    }

    /// Whether triangle `t` faces `point` (its winding is counter-clockwise seen from there).
    pub fn faces(&self, t: usize, point: Vec3) -> bool {
        self.normals[t].dot(point - self.positions[self.triangles[t][0] as usize]) > 0.0
    }

    /// The silhouette seen from `point`: the oriented boundary of the triangles facing it.
    pub fn silhouette(&self, point: Vec3) -> Vec<SilhouetteEdge> {
        let facing: Vec<bool> = (0..self.triangles.len()).map(|t| self.faces(t, point)).collect();
        self.edges
            .iter()
            .filter_map(|e| {
                let uses = &self.uses[e.first_use as usize..(e.first_use + e.use_count) as usize];
                let m: i32 = uses.iter().filter(|u| facing[u.triangle as usize]).map(|u| if u.forward { 1 } else { -1 }).sum();
                let (a, b) = (self.positions[e.a as usize], self.positions[e.b as usize]);
                let object = uses.iter().find(|u| facing[u.triangle as usize]).map_or(0, |u| self.objects[u.triangle as usize]);
                match m {
                    0 => None,
                    m if m > 0 => Some(SilhouetteEdge { a, b, multiplicity: m as u32, object }),
                    m => Some(SilhouetteEdge { a: b, b: a, multiplicity: (-m) as u32, object }),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks that silhouette edges form closed loops: at every point, multiplicities in and
    /// out balance (the boundary of a boundary is empty).
    fn assert_closed(edges: &[SilhouetteEdge]) {
        let mut balance: HashMap<[u32; 3], i64> = HashMap::new();
        for e in edges {
            *balance.entry(e.a.to_array().map(f32::to_bits)).or_default() -= i64::from(e.multiplicity);
            *balance.entry(e.b.to_array().map(f32::to_bits)).or_default() += i64::from(e.multiplicity);
        }
        assert!(balance.values().all(|&b| b == 0), "open silhouette: {balance:?}");
    }

    /// A unit cube, counter-clockwise outward, with each face's 4 vertices separate (as
    /// meshes with per-face normals store them), so welding has work to do.
    fn cube() -> (Vec<Vec3>, Vec<u32>) {
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let n = Vec3::AXES[axis] * sign;
                let u = Vec3::AXES[(axis + 1) % 3];
                let v = n.cross(u);
                let base = positions.len() as u32;
                for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    positions.push(n + u * s + v * t);
                }
                indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
            }
        }
        (positions, indices)
    }

    #[test]
    fn a_closed_cube_welds_and_shows_a_hexagon_from_a_corner() {
        let (positions, indices) = cube();
        let mesh = EdgeMesh::build(&positions, &indices, &[]);
        assert_eq!(mesh.stats.vertices, 8);
        assert_eq!(
            (mesh.stats.edges, mesh.stats.boundary_edges, mesh.stats.non_manifold_edges, mesh.stats.inconsistent_edges),
            (18, 0, 0, 0)
        );
        let silhouette = mesh.silhouette(Vec3::new(5.0, 6.0, 7.0));
        assert_eq!(silhouette.len(), 6, "{silhouette:?}");
        assert!(silhouette.iter().all(|e| e.multiplicity == 1));
        assert_closed(&silhouette);
        // From straight above one face only that face is seen: its 4 edges.
        let above = mesh.silhouette(Vec3::new(0.2, 0.1, 9.0));
        assert_eq!(above.len(), 4);
        assert_closed(&above);
    }

    #[test]
    fn an_open_quad_casts_from_its_front_only() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let mesh = EdgeMesh::build(&positions, &[0, 1, 2, 0, 2, 3], &[]);
        assert_eq!((mesh.stats.edges, mesh.stats.boundary_edges), (5, 4));
        let front = mesh.silhouette(Vec3::new(0.3, 0.4, 2.0));
        assert_eq!(front.len(), 4, "the border, not the diagonal");
        assert_closed(&front);
        assert!(mesh.silhouette(Vec3::new(0.3, 0.4, -2.0)).is_empty(), "facing away, it casts nothing");
    }

    #[test]
    fn non_manifold_and_degenerate_meshes_neither_panic_nor_open_the_silhouette() {
        // Three triangles on one edge (a fin), a repeated-vertex triangle and a zero-area one.
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(0.5, -1.0, 0.1), Vec3::new(0.5, 0.2, 1.0), Vec3::new(2.0, 0.0, 0.0)];
        let indices = [0, 1, 2, 1, 0, 3, 0, 1, 4, 0, 0, 2, 0, 1, 5];
        let mesh = EdgeMesh::build(&positions, &indices, &[]);
        assert_eq!(mesh.stats.degenerate_triangles, 2);
        assert_eq!(mesh.stats.non_manifold_edges, 1);
        for point in [Vec3::new(0.3, 0.3, 3.0), Vec3::new(-1.0, 2.0, -3.0), Vec3::new(0.5, -4.0, 0.5)] {
            assert_closed(&mesh.silhouette(point));
        }
        let empty = EdgeMesh::build(&[], &[], &[]);
        assert!(empty.silhouette(Vec3::ONE).is_empty());
    }
}

#[cfg(test)]
mod builtin_tests {
    use super::*;
    use crate::job::Limits;

    #[test]
    fn built_in_objects_are_closed_only_their_floors_are_open() {
        // Seam and pole vertices repeat bit for bit, so every object but the floor planes (and
        // the occluder's square) is closed: 4 boundary edges per plane.
        for (name, planes) in [("torus", 1), ("crowd", 1), ("columns", 1), ("occluder", 2)] {
            let scene = crate::scene::builtin::build(name, &Default::default(), "scene", &Limits::default()).unwrap();
            let positions: Vec<Vec3> = scene.vertices.iter().map(|v| Vec3::from(v.position)).collect();
            let objects: Vec<u32> = scene.vertices.iter().map(|v| v.object_id).collect();
            let mesh = EdgeMesh::build(&positions, &scene.indices, &objects);
            assert_eq!(mesh.stats.boundary_edges, 4 * planes, "{name}: {:?}", mesh.stats);
            assert_eq!((mesh.stats.non_manifold_edges, mesh.stats.inconsistent_edges), (0, 0), "{name}: {:?}", mesh.stats);
        }
    }
}
