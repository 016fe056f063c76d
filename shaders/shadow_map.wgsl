// Light-space shadow map, rendered from the centre of the area light: linear depth along the
// light normal and the object id of the nearest surface (for `brabec`, the one method that
// reads the ids: `ShadowMethod::reads_light_surfaces`). Its world position (the "light space
// coordinate" Rong–Tan §4.1 floods) is the texel's ray at that depth (`shadow_point`,
// common/shadow.wgsl).
// No culling: back faces cast shadows too (contract §1).

#import common/frame.wgsl

@group(0) @binding(0) var<uniform> frame: Frame;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) depth: f32,
    @location(1) @interpolate(flat) object_id: u32,
}

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(3) object_id: u32) -> VsOut {
    var out: VsOut;
    out.clip = frame.light_view_proj * vec4<f32>(position, 1.0);
    // Affine in world space, so perspective-correct interpolation makes it exact per pixel.
    out.depth = dot(position - frame.light_center.xyz, frame.light_n.xyz);
    out.object_id = object_id;
    return out;
}

struct FsOut {
    @location(0) depth: f32,
    @location(1) object_id: u32,
}

@fragment
fn fs_main(in: VsOut) -> FsOut {
    return FsOut(in.depth, in.object_id);
}

// Depth alone, for methods that read nothing else of the shadow map.
@fragment
fn fs_depth(in: VsOut) -> @location(0) f32 {
    return in.depth;
}
