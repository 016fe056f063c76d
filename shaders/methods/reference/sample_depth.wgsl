// Method `reference`, per light sample: the distance from the sample point to the nearest
// surface in every direction of its frustum (a shadow map from that point), as depth. Distances are
// computed per fragment from the interpolated world position: radial distance is not affine,
// so interpolating it per vertex would be wrong.

#import methods/reference/sample.wgsl

@group(0) @binding(0) var<uniform> light_sample: LightSample;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
}

@vertex
fn vs_main(@location(0) position: vec3<f32>) -> VsOut {
    return VsOut(light_sample.view_proj * vec4<f32>(position, 1.0), position);
}

// The distance goes to the depth buffer itself, in units of `position.w` (every point of the
// frustum is nearer): the depth test keeps the nearest along each texel's ray, and the map
// needs no colour target — on lavapipe a second full-size attachment, cleared and written per
// sample, cost more than the triangles.
@fragment
fn fs_main(in: VsOut) -> @builtin(frag_depth) f32 {
    return length(in.world - light_sample.position.xyz) / light_sample.position.w;
}
