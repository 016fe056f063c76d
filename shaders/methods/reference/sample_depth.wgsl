// Method `reference`, per light sample: a depth map of the scene from the sample point (a
// shadow map from that point) — the rasteriser's own depth, with no fragment shader: a
// reversed-Z perspective with the far plane at infinity stores near / (view depth), as exact
// relative to the depth near the sample as far from it (float depth). A fragment shader
// writing a radial distance per fragment (frag_depth) turned lavapipe's early depth test off.

// The sample's projection (`reversed_projection` × its view, in `methods::reference`); one
// slot per sample, bound with a dynamic offset.
@group(0) @binding(0) var<uniform> view_proj: mat4x4<f32>;

@vertex
fn vs_main(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return view_proj * vec4<f32>(position, 1.0);
}
