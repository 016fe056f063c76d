//! Built-in procedural scenes that need no files: `torus`, `crowd`, `columns`, `terrain`.
//!
//! Each is deterministic (the same parameters give the same triangles, bit for bit), so
//! golden images and cached references stay valid, and each has a view and a light chosen
//! to show penumbrae of different widths.

use std::f32::consts::{PI, TAU};

use glam::{Mat4, Quat, Vec2, Vec3};
use serde_json::{Map, Value};

use super::{MeshData, Scene, SceneBuilder, SceneDefaults};
use crate::error::{ErrorCode, JobError, JobResult};
use crate::job::{AssetRef, Limits};

/// Names of the built-in scenes.
pub const BUILTIN_SCENES: &[&str] = &["torus", "crowd", "columns", "terrain", "occluder"];

/// Default triangle count of `terrain`.
pub const TERRAIN_DEFAULT_TRIANGLES: u64 = 100_000;

/// A built-in scene with its parameters checked: what a job asks for, before anything is built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Builtin {
    Torus,
    Crowd,
    Columns,
    Occluder { height: f32 },
    Terrain { triangles: u64, seed: u32 },
}

/// Checks a built-in scene's name and parameters (at submission, and before building);
/// `field` is where the scene was named in the job (for errors).
pub fn parse(name: &str, params: &Map<String, Value>, field: &str, limits: &Limits) -> JobResult<Builtin> {
    let allowed: &[&str] = match name {
        "terrain" => &["triangles", "seed"],
        "occluder" => &["height"],
        "torus" | "crowd" | "columns" => &[],
        _ => {
            return Err(JobError::field(
                ErrorCode::UnknownBuiltin,
                format!("{field}.builtin"),
                format!("unknown built-in scene `{name}`; known: {}", BUILTIN_SCENES.join(", ")),
            ))
        }
    };
    if let Some(key) = params.keys().find(|k| !allowed.contains(&k.as_str())) {
        return Err(JobError::field(
            ErrorCode::UnknownField,
            format!("{field}.{key}"),
            format!("the built-in scene `{name}` has no parameter `{key}`"),
        ));
    }
    Ok(match name {
        "torus" => Builtin::Torus,
        "crowd" => Builtin::Crowd,
        "columns" => Builtin::Columns,
        "occluder" => {
            let height = match params.get("height") {
                None => OCCLUDER_HEIGHT_M,
                Some(v) => match v.as_f64() {
                    Some(h) if (0.05..=2.9).contains(&h) => h as f32,
                    _ => {
                        return Err(JobError::invalid(
                            format!("{field}.height"),
                            "must be a number in [0.05, 2.9] metres (below the light)",
                        ))
                    }
                },
            };
            Builtin::Occluder { height }
        }
        _ => Builtin::Terrain {
            triangles: integer_param(params, "triangles", field, TERRAIN_DEFAULT_TRIANGLES, 2, limits.max_triangles)?,
            seed: integer_param(params, "seed", field, 1, 0, u64::from(u32::MAX))? as u32,
        },
    })
}

/// Builds a built-in scene; `field` is where the scene was named in the job (for errors).
pub fn build(name: &str, params: &Map<String, Value>, field: &str, limits: &Limits) -> JobResult<Scene> {
    Ok(build_parsed(parse(name, params, field, limits)?))
}

/// Builds a parsed built-in scene.
pub fn build_parsed(builtin: Builtin) -> Scene {
    match builtin {
        Builtin::Torus => torus_scene(),
        Builtin::Crowd => crowd_scene(),
        Builtin::Columns => columns_scene(),
        Builtin::Occluder { height } => occluder_scene(height),
        Builtin::Terrain { triangles, seed } => terrain_scene(triangles, seed),
    }
}

fn integer_param(params: &Map<String, Value>, key: &str, field: &str, default: u64, min: u64, max: u64) -> JobResult<u64> {
    let Some(value) = params.get(key) else { return Ok(default) };
    match crate::params::whole_number(value).and_then(|v| u64::try_from(v).ok()) {
        Some(v) if (min..=max).contains(&v) => Ok(v),
        Some(v) if v > max => {
            Err(JobError::field(ErrorCode::LimitExceeded, format!("{field}.{key}"), format!("{v} exceeds the limit of {max}")))
        }
        _ => Err(JobError::invalid(format!("{field}.{key}"), format!("must be an integer in [{min}, {max}]"))),
    }
}

fn defaults(eye: Vec3, target: Vec3, light_center: Vec3, light_target: Vec3, size: Vec2, intensity: f32) -> SceneDefaults {
    SceneDefaults {
        eye,
        target,
        up: Vec3::Y,
        fov_y_deg: 45.0,
        light_center,
        light_direction: (light_target - light_center).normalize(),
        light_up: -Vec3::Z,
        light_size_m: size,
        light_intensity: intensity,
        light_image: AssetRef::builtin("white"),
    }
}

/// A torus over a ground plane: the simplest scene with a penumbra that widens with the
/// distance between occluder and receiver.
fn torus_scene() -> Scene {
    let mut b = SceneBuilder::default();
    let floor_material = b.color([0.7, 0.7, 0.7]);
    let torus_material = b.color([0.8, 0.45, 0.2]);
    let floor = b.begin_object("floor");
    b.add_mesh(floor, &plane(12.0, 12.0), Mat4::IDENTITY, floor_material);
    let torus_id = b.begin_object("torus");
    let transform = Mat4::from_rotation_translation(Quat::from_rotation_x(0.35), Vec3::new(0.0, 1.3, 0.0));
    b.add_mesh(torus_id, &torus(1.0, 0.3, 64, 24), transform, torus_material);
    b.finish(|_, _| defaults(Vec3::new(0.0, 4.0, 8.0), Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.0, 5.0, 0.0), Vec3::ZERO, Vec2::ONE, 60.0))
}

/// Tori, spheres and boxes at several heights over a floor: overlapping penumbrae of many
/// widths and many object ids.
fn crowd_scene() -> Scene {
    let mut b = SceneBuilder::default();
    let floor_material = b.color([0.65, 0.65, 0.65]);
    let palette = [[0.8, 0.3, 0.25], [0.3, 0.6, 0.8], [0.85, 0.75, 0.3], [0.4, 0.75, 0.4]].map(|c| b.color(c));
    let floor = b.begin_object("floor");
    b.add_mesh(floor, &plane(16.0, 16.0), Mat4::IDENTITY, floor_material);
    let mut rng = Lcg(7);
    for k in 0..12 {
        let (gx, gz) = ((k % 4) as f32 - 1.5, (k / 4) as f32 - 1.0);
        let position = Vec3::new(gx * 2.2 + rng.next() * 0.6, 0.5 + 2.0 * rng.next(), gz * 2.4 + rng.next() * 0.6);
        let rotation = Quat::from_euler(glam::EulerRot::XYZ, rng.next() * PI, rng.next() * PI, 0.0);
        let transform = Mat4::from_rotation_translation(rotation, position);
        let (name, mesh) = match k % 3 {
            0 => ("torus", torus(0.55, 0.18, 40, 16)),
            1 => ("sphere", uv_sphere(0.5, 32, 16)),
            _ => ("box", cuboid(Vec3::new(0.8, 0.5, 0.6))),
        };
        let id = b.begin_object(format!("{name}-{k}"));
        b.add_mesh(id, &mesh, transform, palette[k % palette.len()]);
    }
    b.finish(|_, _| {
        defaults(
            Vec3::new(0.0, 7.0, 11.0),
            Vec3::new(0.0, 0.5, 0.0),
            Vec3::new(1.0, 8.0, 1.0),
            Vec3::new(0.0, 0.0, 0.0),
            Vec2::splat(1.5),
            90.0,
        )
    })
}

/// A colonnade on a floor, lit from the side: long shadows with wide penumbrae far from
/// the columns' feet and sharp ones at them.
fn columns_scene() -> Scene {
    let mut b = SceneBuilder::default();
    let floor_material = b.color([0.7, 0.68, 0.62]);
    let stone = b.color([0.85, 0.82, 0.75]);
    let floor = b.begin_object("floor");
    b.add_mesh(floor, &plane(24.0, 14.0), Mat4::IDENTITY, floor_material);
    for row in [-1.5f32, 1.5] {
        for k in 0..6 {
            let id = b.begin_object(format!("column-{row}-{k}"));
            let x = (k as f32 - 2.5) * 2.0;
            b.add_mesh(id, &cylinder(0.28, 3.0, 32), Mat4::from_translation(Vec3::new(x, 0.0, row)), stone);
        }
        let id = b.begin_object(format!("lintel-{row}"));
        b.add_mesh(id, &cuboid(Vec3::new(11.6, 0.35, 0.7)), Mat4::from_translation(Vec3::new(0.0, 3.175, row)), stone);
    }
    b.finish(|_, _| {
        defaults(Vec3::new(2.0, 6.0, 13.0), Vec3::new(0.0, 1.0, 0.0), Vec3::new(-8.0, 12.0, 6.0), Vec3::ZERO, Vec2::new(2.0, 1.2), 180.0)
    })
}

/// A fractal landscape of about `triangles` triangles on 24 m × 24 m: cost that grows with
/// geometry, shadows that fall on curved receivers.
fn terrain_scene(triangles: u64, seed: u32) -> Scene {
    let n = (((triangles as f64) / 2.0).sqrt().round() as u32).max(1);
    let size = 24.0;
    let height = |x: f32, z: f32| 3.5 * fbm(x * 0.12, z * 0.12, seed) - 0.5;
    let mut mesh = MeshData::default();
    let step = size / n as f32;
    for j in 0..=n {
        for i in 0..=n {
            let (x, z) = (-size / 2.0 + i as f32 * step, -size / 2.0 + j as f32 * step);
            mesh.positions.push(Vec3::new(x, height(x, z), z));
            // Central differences of the height field give smooth normals.
            let e = step.min(0.05);
            let dx = (height(x + e, z) - height(x - e, z)) / (2.0 * e);
            let dz = (height(x, z + e) - height(x, z - e)) / (2.0 * e);
            mesh.normals.push(Vec3::new(-dx, 1.0, -dz).normalize());
            mesh.uvs.push(Vec2::new(i as f32 / n as f32, j as f32 / n as f32));
        }
    }
    let row = n + 1;
    for j in 0..n {
        for i in 0..n {
            let a = j * row + i;
            mesh.indices.extend([a, a + row, a + 1, a + 1, a + row, a + row + 1]);
        }
    }
    let mut b = SceneBuilder::default();
    let ground = b.color([0.55, 0.6, 0.45]);
    let id = b.begin_object("terrain");
    b.add_mesh(id, &mesh, Mat4::IDENTITY, ground);
    b.finish(|_, _| {
        defaults(Vec3::new(0.0, 14.0, 20.0), Vec3::new(0.0, 0.0, 0.0), Vec3::new(-18.0, 8.0, -6.0), Vec3::ZERO, Vec2::splat(4.0), 250.0)
    })
}

/// Default height and side of the `occluder` scene's square, for closed-form checks.
pub const OCCLUDER_HEIGHT_M: f32 = 1.0;
pub const OCCLUDER_SIDE_M: f32 = 1.5;

/// A square occluder parallel to the floor under a parallel square light: the one scene
/// whose true visibility has a closed form (the visible part of the light is the light minus
/// the occluder projected from the receiver point), used to check `reference` and others.
fn occluder_scene(height: f32) -> Scene {
    let mut b = SceneBuilder::default();
    let floor_material = b.color([0.75, 0.75, 0.75]);
    let occluder_material = b.color([0.3, 0.5, 0.8]);
    let floor = b.begin_object("floor");
    b.add_mesh(floor, &plane(10.0, 10.0), Mat4::IDENTITY, floor_material);
    let occluder = b.begin_object("occluder");
    b.add_mesh(occluder, &plane(OCCLUDER_SIDE_M, OCCLUDER_SIDE_M), Mat4::from_translation(Vec3::Y * height), occluder_material);
    b.finish(|_, _| defaults(Vec3::new(0.0, 7.0, 5.0), Vec3::ZERO, Vec3::new(0.0, 3.0, 0.0), Vec3::ZERO, Vec2::ONE, 30.0))
}

/// A tiny deterministic generator (numerical recipes LCG); scenes must not depend on a
/// crate's RNG stream, which may change between versions.
struct Lcg(u32);

impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32
    }
}

fn lattice(i: i32, j: i32, seed: u32) -> f32 {
    let mut h = (i as u32).wrapping_mul(0x8da6_b343) ^ (j as u32).wrapping_mul(0xd816_3841) ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0xffff) as f32 / 65535.0
}

/// Value noise with a quintic fade, summed over octaves (fractional Brownian motion).
fn fbm(x: f32, z: f32, seed: u32) -> f32 {
    let mut sum = 0.0;
    let (mut amplitude, mut frequency) = (0.5, 1.0);
    for octave in 0..6 {
        let (px, pz) = (x * frequency, z * frequency);
        let (i, j) = (px.floor() as i32, pz.floor() as i32);
        let (fx, fz) = (px - px.floor(), pz - pz.floor());
        let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (sx, sz) = (fade(fx), fade(fz));
        let s = seed.wrapping_add(octave);
        let a = lattice(i, j, s) + (lattice(i + 1, j, s) - lattice(i, j, s)) * sx;
        let c = lattice(i, j + 1, s) + (lattice(i + 1, j + 1, s) - lattice(i, j + 1, s)) * sx;
        sum += amplitude * (a + (c - a) * sz);
        amplitude *= 0.5;
        frequency *= 2.0;
    }
    sum
}

/// A horizontal square at y = 0 facing +y.
pub fn plane(width: f32, depth: f32) -> MeshData {
    let (w, d) = (width / 2.0, depth / 2.0);
    MeshData {
        positions: vec![Vec3::new(-w, 0.0, -d), Vec3::new(-w, 0.0, d), Vec3::new(w, 0.0, d), Vec3::new(w, 0.0, -d)],
        normals: vec![Vec3::Y; 4],
        uvs: vec![Vec2::new(0.0, 0.0), Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0)],
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// A box centred at the origin with flat faces.
pub fn cuboid(size: Vec3) -> MeshData {
    let h = size / 2.0;
    let mut mesh = MeshData::default();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            let t = Vec3::new(n.y.abs() + n.z.abs(), n.x.abs(), 0.0).normalize(); // ⟂ n
            let (t, s) = (t, n.cross(t));
            let base = mesh.positions.len() as u32;
            for (a, c) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                mesh.positions.push((n + t * a + s * c) * h);
                mesh.normals.push(n);
            }
            mesh.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    mesh
}

/// sin and cos of `TAU · k / n`, exact at the seam (k = n gives k = 0's values): seam and pole
/// vertices repeat bit for bit, so adjacency sees a closed mesh (f32 `TAU.sin()` is not 0).
fn turn(k: u32, n: u32) -> (f32, f32) {
    let angle = TAU * (k % n) as f32 / n as f32;
    angle.sin_cos()
}

pub fn uv_sphere(radius: f32, segments: u32, rings: u32) -> MeshData {
    let mut mesh = MeshData::default();
    for j in 0..=rings {
        // Half turns: the poles come out exact (sin 0 and sin π as 0).
        let (sin_theta, cos_theta) = if j == 0 || j == rings { (0.0, if j == 0 { 1.0 } else { -1.0 }) } else { turn(j, 2 * rings) };
        for i in 0..=segments {
            let (sin_phi, cos_phi) = turn(i, segments);
            let n = Vec3::new(sin_theta * cos_phi, cos_theta, sin_theta * sin_phi);
            mesh.positions.push(n * radius);
            mesh.normals.push(n);
        }
    }
    grid_indices(&mut mesh, segments, rings);
    mesh
}

pub fn torus(major: f32, minor: f32, segments: u32, sides: u32) -> MeshData {
    let mut mesh = MeshData::default();
    for j in 0..=sides {
        let (sin_v, cos_v) = turn(j, sides);
        for i in 0..=segments {
            let (sin_u, cos_u) = turn(i, segments);
            let ring = Vec3::new(cos_u, 0.0, sin_u);
            let n = ring * cos_v + Vec3::Y * sin_v;
            mesh.positions.push(ring * major + n * minor);
            mesh.normals.push(n);
        }
    }
    grid_indices(&mut mesh, segments, sides);
    mesh
}

/// A capped cylinder standing on y = 0.
pub fn cylinder(radius: f32, height: f32, segments: u32) -> MeshData {
    let mut mesh = MeshData::default();
    for j in 0..=1 {
        for i in 0..=segments {
            let (sin_a, cos_a) = turn(i, segments);
            let n = Vec3::new(cos_a, 0.0, sin_a);
            mesh.positions.push(n * radius + Vec3::Y * height * j as f32);
            mesh.normals.push(n);
        }
    }
    grid_indices(&mut mesh, segments, 1);
    for (y, n, top) in [(0.0, -Vec3::Y, false), (height, Vec3::Y, true)] {
        let center = mesh.positions.len() as u32;
        mesh.positions.push(Vec3::Y * y);
        mesh.normals.push(n);
        for i in 0..=segments {
            let (sin_a, cos_a) = turn(i, segments);
            mesh.positions.push(Vec3::new(cos_a * radius, y, sin_a * radius));
            mesh.normals.push(n);
        }
        // Counter-clockwise seen from outside: the bottom cap runs with the angle (normal −y),
        // the top one against it.
        for i in 0..segments {
            if top {
                mesh.indices.extend([center, center + 2 + i, center + 1 + i]);
            } else {
                mesh.indices.extend([center, center + 1 + i, center + 2 + i]);
            }
        }
    }
    mesh
}

/// Two triangles per cell of a (columns+1) × (rows+1) vertex grid.
fn grid_indices(mesh: &mut MeshData, columns: u32, rows: u32) {
    let stride = columns + 1;
    for j in 0..rows {
        for i in 0..columns {
            let a = j * stride + i;
            mesh.indices.extend([a, a + stride, a + 1, a + 1, a + stride, a + stride + 1]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtins_build_with_ids_and_bounds() {
        let limits = Limits::default();
        for name in BUILTIN_SCENES {
            let params = if *name == "terrain" { Map::from_iter([("triangles".to_owned(), Value::from(5000))]) } else { Map::new() };
            let scene = build(name, &params, "scene", &limits).unwrap();
            assert!(scene.triangle_count() > 0, "{name}");
            let max_id = scene.vertices.iter().map(|v| v.object_id).max().unwrap();
            assert_eq!(max_id as usize + 1, scene.objects.len(), "{name}");
            assert!(scene.bounds_max.y > scene.bounds_min.y, "{name}");
        }
    }

    #[test]
    fn terrain_triangle_count_follows_the_parameter() {
        let limits = Limits::default();
        let params = Map::from_iter([("triangles".to_owned(), Value::from(20_000))]);
        let scene = build("terrain", &params, "scene", &limits).unwrap();
        let count = scene.triangle_count() as f64;
        assert!((count / 20_000.0 - 1.0).abs() < 0.05, "{count}");
        assert_eq!(build("terrain", &Map::new(), "scene", &limits).unwrap().triangle_count() / 1000, 100);
    }

    #[test]
    fn bad_parameters_name_the_field() {
        let limits = Limits { max_triangles: 1000, ..Limits::default() };
        let params = Map::from_iter([("triangles".to_owned(), Value::from(5000))]);
        let err = build("terrain", &params, "scene", &limits).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("scene.triangles"));
        assert_eq!(err.code, ErrorCode::LimitExceeded);
        let err = build("torus", &params, "scene", &limits).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("scene.triangles"));
        let err = build("teapot", &Map::new(), "scene", &limits).unwrap_err();
        assert_eq!(err.code, ErrorCode::UnknownBuiltin);
    }
}
