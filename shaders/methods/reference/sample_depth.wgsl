// Method `reference`, per light sample: the distance from the sample point to the nearest
// surface in every direction of its frustum (a shadow map from that point). Distances are
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

@fragment
fn fs_main(in: VsOut) -> @location(0) f32 {
    return length(in.world - light_sample.position.xyz);
}
