//! Unit tests of `adjacency`.

use super::*;
use crate::job::Limits;

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

/// The silhouette from `point`.
fn silhouette(mesh: &EdgeMesh, point: Vec3) -> Vec<SilhouetteEdge> {
    mesh.silhouette(&mesh.casting(point))
}

/// The silhouette's edges as sorted pairs of welded positions, with their multiplicity.
fn loop_of(edges: &[SilhouetteEdge]) -> Vec<([i32; 3], [i32; 3], u32)> {
    let key = |p: Vec3| (p * 100.0).round().as_ivec3().to_array();
    let mut out: Vec<_> = edges.iter().map(|e| (key(e.a), key(e.b), e.multiplicity)).collect();
    out.sort();
    out
}

#[test]
fn a_closed_cube_welds_and_shows_a_hexagon_from_a_corner() {
    let (positions, indices) = cube();
    let mesh = EdgeMesh::build(&positions, &indices, &[]);
    assert_eq!(mesh.stats.vertices, 8);
    assert_eq!((mesh.stats.edges, mesh.stats.boundary_edges, mesh.stats.non_manifold_edges, mesh.stats.inconsistent_edges), (18, 0, 0, 0));
    assert_eq!((mesh.stats.surfaces, mesh.stats.open_surfaces, mesh.stats.reoriented_triangles), (1, 0, 0));
    let corner = silhouette(&mesh, Vec3::new(5.0, 6.0, 7.0));
    assert_eq!(corner.len(), 6, "{corner:?}");
    assert!(corner.iter().all(|e| e.multiplicity == 1));
    assert_closed(&corner);
    // From straight above one face only that face is seen: its 4 edges.
    let above = silhouette(&mesh, Vec3::new(0.2, 0.1, 9.0));
    assert_eq!(above.len(), 4);
    assert_closed(&above);
}

/// A flipped face is turned back, and a cube wound inside out is turned outward: both cast
/// as the cube does, from their front only.
#[test]
fn flipped_faces_and_inside_out_surfaces_are_oriented_and_stay_closed() {
    let (positions, indices) = cube();
    let expected = loop_of(&silhouette(&EdgeMesh::build(&positions, &indices, &[]), Vec3::new(5.0, 6.0, 7.0)));
    let mut one_flipped = indices.clone();
    one_flipped.swap(7, 8);
    let inside_out: Vec<u32> = indices.chunks_exact(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
    for (indices, reoriented) in [(one_flipped, 1), (inside_out, 12)] {
        let mesh = EdgeMesh::build(&positions, &indices, &[]);
        assert_eq!((mesh.stats.open_surfaces, mesh.stats.reoriented_triangles), (0, reoriented), "{:?}", mesh.stats);
        assert_eq!(loop_of(&silhouette(&mesh, Vec3::new(5.0, 6.0, 7.0))), expected);
    }
}

/// An open sheet is the only layer there is: it casts from either side, its border the
/// silhouette. A duplicate of it, even wound the other way (a sheet modelled as two faces
/// back to back), is the same sheet.
#[test]
fn an_open_sheet_casts_from_both_sides_and_its_duplicate_is_one_sheet() {
    let positions = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
    for indices in [vec![0, 1, 2, 0, 2, 3], vec![0, 1, 2, 0, 2, 3, 0, 2, 1, 0, 3, 2, 0, 1, 2]] {
        let mesh = EdgeMesh::build(&positions, &indices, &[]);
        assert_eq!((mesh.stats.edges, mesh.stats.boundary_edges, mesh.stats.open_surfaces), (5, 4, 1));
        assert_eq!(mesh.stats.duplicate_triangles, indices.len() / 3 - 2);
        let front = silhouette(&mesh, Vec3::new(0.3, 0.4, 2.0));
        let back = silhouette(&mesh, Vec3::new(0.3, 0.4, -2.0));
        for edges in [&front, &back] {
            assert_eq!(edges.len(), 4, "the border, not the diagonal: {edges:?}");
            assert!(edges.iter().all(|e| e.multiplicity == 1));
            assert_closed(edges);
        }
        // Seen from the other side, the same loop runs the other way.
        let reversed: Vec<SilhouetteEdge> = back.iter().map(|e| SilhouetteEdge { a: e.b, b: e.a, ..*e }).collect();
        assert_eq!(loop_of(&front), loop_of(&reversed));
    }
}

/// A box without its lid: from above, its floor (a back face nothing closes off) casts, and
/// the rim is the silhouette; from the side, the far wall and the floor lie behind the near
/// wall, the same layer, and only the near wall casts.
#[test]
fn an_open_box_casts_its_back_faces_only_where_nothing_of_it_closes_them_off() {
    let (positions, indices) = cube();
    // The cube's faces are in the order −x, +x, −y, +y, −z, +z: leave out +z, the lid.
    let open = &indices[..30];
    let mesh = EdgeMesh::build(&positions, open, &[]);
    assert_eq!((mesh.stats.boundary_edges, mesh.stats.open_surfaces), (4, 1));
    let above = silhouette(&mesh, Vec3::new(0.2, 0.1, 9.0));
    assert_eq!(above.len(), 4, "the rim: {above:?}");
    assert!(above.iter().all(|e| e.multiplicity == 1 && e.a.z == 1.0 && e.b.z == 1.0), "{above:?}");
    let casting = mesh.casting(Vec3::new(9.0, 0.1, 0.2));
    assert_eq!(mesh.casting_triangles(&casting).count(), 2, "the near wall alone");
    let side = mesh.silhouette(&casting);
    assert_eq!(side.len(), 4, "{side:?}");
    assert!(side.iter().all(|e| e.multiplicity == 1 && e.a.x == 1.0 && e.b.x == 1.0), "{side:?}");
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
        assert_closed(&silhouette(&mesh, point));
    }
    let empty = EdgeMesh::build(&[], &[], &[]);
    assert!(silhouette(&empty, Vec3::ONE).is_empty());
}

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
