//! Unit tests of `culling`.

use super::*;
use glam::Vec2;

fn inside(planes: &[Vec4], p: Vec3) -> bool {
    planes.iter().all(|q| q.truncate().dot(p) + q.w >= 0.0)
}

#[test]
fn the_wedge_region_holds_every_point_the_edge_hides_light_from() {
    let light = AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
    let edge = SilhouetteEdge { a: Vec3::new(0.5, 1.0, -0.7), b: Vec3::new(0.2, 1.3, 0.6), multiplicity: 1, object: 0 };
    let (_, planes) = wedge_region(&edge, &light, 20.0, 20.0).unwrap();
    assert!(planes.len() >= 4, "{planes:?}");
    // Points behind the edge as seen from any light point are inside.
    for (i, j, s) in [(0.0, 0.0, 0.5), (1.0, 1.0, 3.0), (0.3, 0.9, 10.0), (0.5, 0.2, 0.01)] {
        let e = edge.a.lerp(edge.b, i);
        let y = light.image_point(j, 1.0 - j);
        assert!(inside(&planes, e + (e - y) * s), "{i} {j} {s}");
    }
    // Beside the light and far to the side on the floor: outside.
    assert!(!inside(&planes, Vec3::new(0.0, 3.0, 0.0)));
    assert!(!inside(&planes, Vec3::new(8.0, 0.0, 0.0)));
    // An edge above the light's plane hides nothing below it.
    let above = SilhouetteEdge { a: Vec3::new(0.0, 4.0, 0.0), b: Vec3::new(1.0, 4.0, 0.0), multiplicity: 1, object: 0 };
    assert!(wedge_region(&above, &light, 20.0, 20.0).is_none());
}

/// Whether `p` lies in the convex hull of `points`, judged by its support in many
/// directions (a point outside is beyond the hull's support in some direction).
fn within_hull(points: &[Vec3], p: Vec3) -> bool {
    let steps = 24;
    (0..steps).all(|i| {
        (0..2 * steps).all(|j| {
            let (theta, phi) = (std::f32::consts::PI * (i as f32 + 0.5) / steps as f32, std::f32::consts::PI * j as f32 / steps as f32);
            let u = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            let support = points.iter().map(|v| u.dot(*v)).fold(f32::NEG_INFINITY, f32::max);
            u.dot(p) <= support + 1e-4
        })
    })
}

#[test]
fn the_wedges_box_holds_every_hidden_receiver_no_deeper_than_the_scene() {
    // The light 3 m up facing down; the scene's deepest point 2.2 m below it, 0.3 m under
    // the edge's deeper end. Hidden points e + s(e − y) at that depth or above lie in the
    // hull; the hull reaches no farther than the scene's depth allows, far short of `reach`.
    let light = AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
    let edge = SilhouetteEdge { a: Vec3::new(0.5, 1.3, -0.7), b: Vec3::new(0.2, 1.1, 0.6), multiplicity: 1, object: 0 };
    let (reach, deepest) = (20.0, 2.2);
    let (hull, _) = wedge_region(&edge, &light, reach, deepest).unwrap();
    let mut held = 0;
    for i in 0..=4 {
        for (j, k) in [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0), (0.5, 0.5), (0.2, 0.7)] {
            let e = edge.a.lerp(edge.b, i as f32 / 4.0);
            // Down to the scene's depth exactly, the hull's extreme.
            let bottom = deepest / light.depth(e) - 1.0 - 1e-5;
            for s in [0.0, 0.05, 0.1, 0.2, 0.3, 0.6, 1.0, 3.0, bottom, 0.5 * bottom] {
                let p = e + (e - light.image_point(j, k)) * s;
                if light.depth(p) <= deepest {
                    assert!(within_hull(&hull, p), "{i} {j} {k} {s}: {p}");
                    held += 1;
                }
            }
        }
    }
    assert!(held > 60, "{held} points tested");
    // Reaching down to the scene's depth from the higher end (1.7 m below the light) takes
    // s ≤ 2.2 / 1.7 − 1 ≈ 0.29 along directions under 2.7 m long: the hull ends within
    // 0.8 m of the edge.
    let far = hull.iter().map(|v| v.distance(edge.a).min(v.distance(edge.b))).fold(0.0f32, f32::max);
    assert!(far < 1.2, "{far}");
    let (loose, _) = wedge_region(&edge, &light, reach, reach).unwrap();
    assert!(loose.iter().any(|v| v.distance(edge.a) > 10.0), "without the scene's depth it reaches out to `reach`");
}

#[test]
fn a_z_pass_polygon_is_cut_where_no_eye_ray_to_a_receiver_crosses_it() {
    // A side quad from an edge 2 m below the light down to 20 m below it, the scene no
    // deeper than 2.5 m, the eye at 1 m: z-pass crossings lie above 2.5 m.
    let light = AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
    let quad = [Vec3::new(0.0, 1.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(1.5, -17.0, 0.5), Vec3::new(-0.5, -17.0, 0.5)];
    let eye = Vec3::new(0.0, 2.0, 5.0);
    let part = crossing_part(&quad, &light, eye, 2.5, false);
    assert_eq!(part.len(), 4);
    assert!(part.iter().all(|p| light.depth(*p) <= 2.5 + 1e-5), "{part:?}");
    // Every point of the quad at most that deep lies in the part.
    for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.5, 0.02), (0.9, 0.027), (0.1, 0.01)] {
        let p = quad[0].lerp(quad[1], u).lerp(quad[3].lerp(quad[2], u), v);
        assert!(light.depth(p) > 2.5 || within_hull(&part, p), "{u} {v}: {p}");
    }
    // An eye deeper than the scene keeps the crossings down to its own depth.
    let low_eye = Vec3::new(0.0, -7.0, 5.0);
    assert!(crossing_part(&quad, &light, low_eye, 2.5, false).iter().any(|p| light.depth(*p) > 9.9));
    // z-fail counts crossings beyond the receiver: the whole quad; and a quad wholly deeper
    // than the scene and the eye crosses no eye ray to a receiver.
    assert_eq!(crossing_part(&quad, &light, eye, 2.5, true), quad.to_vec());
    let deep = quad.map(|p| p - Vec3::Y * 30.0);
    assert!(crossing_part(&deep, &light, eye, 2.5, false).is_empty());
}

/// An edge of `object` under a 2 × 1 m light, and its wedge's footprint over one tile with
/// no NDC test (every depth).
fn edge_under_light(object: u32) -> (AreaLight, SilhouetteEdge, Footprint) {
    let light = AreaLight::new(Vec3::Y * 3.0, -Vec3::Y, -Vec3::Z, Vec2::new(2.0, 1.0), 1.0).unwrap();
    let edge = SilhouetteEdge { a: Vec3::new(0.5, 1.0, -0.7), b: Vec3::new(0.2, 1.3, 0.6), multiplicity: 1, object };
    let (_, planes) = wedge_region(&edge, &light, 20.0, 20.0).unwrap();
    (light, edge, Footprint { tiles_x: (0, 1), tiles_y: (0, 1), z: (f32::NEG_INFINITY, f32::INFINITY), planes, object })
}

#[test]
fn a_tile_is_culled_by_its_receivers_world_box_where_its_ndc_box_passes() {
    let (light, edge, footprint) = edge_under_light(0);
    // An NDC box that passes every NDC test (no NDC planes), and world boxes: a small one
    // around a point the edge hides light from, and one as small far to the side.
    let tile = |centre: Vec3| {
        Some(TileBox {
            ndc: [-1.0, 1.0, -1.0, 1.0, 0.0, 1.0],
            world: [centre - Vec3::splat(0.05), centre + Vec3::splat(0.05)],
            hull: None,
            ignores: None,
        })
    };
    let e = edge.a.lerp(edge.b, 0.5);
    let hidden = e + (e - light.center) * 0.8;
    assert!(survives(&footprint, &[], tile(hidden), false, false));
    assert!(!survives(&footprint, &[], tile(Vec3::new(8.0, 0.0, 0.0)), false, false));
    // A box straddling the region's boundary survives: it may hold a receiver inside.
    let straddling = Some(TileBox {
        ndc: [-1.0, 1.0, -1.0, 1.0, 0.0, 1.0],
        world: [hidden, Vec3::new(8.0, 0.0, 0.0).max(hidden)],
        hull: None,
        ignores: None,
    });
    assert!(survives(&footprint, &[], straddling, false, false));
}

#[test]
fn a_slab_hull_holds_the_tiles_points_and_exists_only_where_it_is_bounded() {
    // A slope seen from above and to the side: the eye at the origin looking down −z, a
    // tile's rays through (±0.1, ±0.1) at unit depth, the ground's points within 0.05 of
    // the plane z = −5 + 0.5x.
    let eye = Vec3::ZERO;
    let rays = [Vec3::new(-0.1, -0.1, -1.0), Vec3::new(0.1, -0.1, -1.0), Vec3::new(0.1, 0.1, -1.0), Vec3::new(-0.1, 0.1, -1.0)];
    let axis = Vec3::new(-0.5, 0.0, 1.0).normalize();
    // The point of the ray through (x, y) at `bump` along the axis off the plane.
    let on_ground = |x: f32, y: f32, bump: f32| -> Vec3 {
        let d = Vec3::new(x, y, -1.0);
        eye + d * ((-5.0 * axis.z + bump) / axis.dot(d))
    };
    let (lo, hi) = (-5.0 * axis.z - 0.05, -5.0 * axis.z + 0.05);
    let hull = slab_hull(eye, &rays, axis, lo, hi).expect("the slope's slab is bounded within the tile");
    // Any plane that holds a point of the tile keeps one of the hull's corners.
    let keeps = |plane: Vec4| hull.iter().any(|v| plane.truncate().dot(*v) + plane.w >= 0.0);
    for (x, y, bump) in [(0.0, 0.0, 0.0), (0.09, -0.09, 0.049), (-0.1, 0.1, -0.05), (0.05, 0.02, 0.03)] {
        let p = on_ground(x, y, bump);
        for normal in [Vec3::X, -Vec3::X, Vec3::Y, Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.4, 0.8).normalize()] {
            assert!(keeps(normal.extend(-normal.dot(p))), "{p} against {normal}");
        }
    }
    // Thin where the box is thick: its corners lie within the slab along the axis.
    assert!(hull.iter().all(|v| axis.dot(*v) >= lo - 1e-4 && axis.dot(*v) <= hi + 1e-4));
    // Unbounded or behind the eye: no hull.
    assert!(slab_hull(eye, &rays, Vec3::Z, -1.0, 1.0).is_none(), "the eye inside the slab");
    assert!(slab_hull(eye, &rays, Vec3::Y, 1.0, 2.0).is_none(), "rays crossing it in opposite senses");
    assert!(slab_hull(eye, &rays, Vec3::ZERO, 1.0, 2.0).is_none(), "no axis");
    assert!(slab_hull(eye, &rays, Vec3::Z, 1.0, 2.0).is_none(), "behind the eye");
}

#[test]
fn a_tile_whose_pixels_all_ignore_an_object_is_culled_for_that_objects_primitives() {
    let (light, edge, footprint) = edge_under_light(3);
    let e = edge.a.lerp(edge.b, 0.5);
    let hidden = e + (e - light.center) * 0.8;
    let tile = |ignores| {
        let world = [hidden - Vec3::splat(0.05), hidden + Vec3::splat(0.05)];
        Some(TileBox { ndc: [-1.0, 1.0, -1.0, 1.0, 0.0, 1.0], world, hull: None, ignores })
    };
    assert!(!survives(&footprint, &[], tile(Some(3)), false, false), "every pixel ignores the edge's object");
    assert!(survives(&footprint, &[], tile(Some(1)), false, false), "they ignore another object");
    assert!(survives(&footprint, &[], tile(None), false, false), "some pixel ignores nothing");
    // A block keeps an object only where all its tiles ignore it.
    let (a, b) = (tile(Some(3)).unwrap(), tile(Some(1)).unwrap());
    assert_eq!((a.union(a).ignores, a.union(b).ignores), (Some(3), None));
}

#[test]
fn the_crossing_region_is_behind_the_polygon_for_z_pass_and_before_it_for_z_fail() {
    let quad = [Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0), Vec3::new(-1.0, 0.0, 1.0)];
    let eye = Vec3::new(0.0, 5.0, 0.0);
    let (zpass, zfail) = (crossing_region(&quad, eye, false), crossing_region(&quad, eye, true));
    assert!(inside(&zpass, Vec3::new(0.3, -1.0, 0.2)) && !inside(&zfail, Vec3::new(0.3, -1.0, 0.2)));
    assert!(inside(&zfail, Vec3::new(0.3, 1.0, 0.2)) && !inside(&zpass, Vec3::new(0.3, 1.0, 0.2)));
    // Outside the polygon's cone from the eye: neither.
    assert!(!inside(&zpass, Vec3::new(3.0, -1.0, 0.0)) && !inside(&zfail, Vec3::new(1.5, 1.0, 0.0)));
}
