// Method `reference`: one point sample on the area light, as the per-sample passes read it
// (`methods::reference::SampleUniforms`). Bound with a dynamic offset, one per sample.

struct LightSample {
    view_proj: mat4x4<f32>, // perspective frustum from the sample point along the light normal
    position: vec4<f32>,    // xyz: the sample point on the light; w: the distance map's unit (depth 1), metres
    radiance: vec4<f32>,    // rgb: L(y) × stratum area, the sample's weight in the estimator
    params: vec4<f32>,      // x: tan of the frustum half angle, y: resolution, z: bias texels, w: slope bias texels
}
