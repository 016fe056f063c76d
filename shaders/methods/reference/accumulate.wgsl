// Method `reference`, per light sample: adds this sample's contribution to the two sums of
// the ratio estimator, per pixel: Σ L·G·V (shadowed) and Σ L·G (unshadowed), with
// G = cosθx·cosθy/|x−y|² and V from the sample's distance map (contract §1).

#import common/frame_inputs.wgsl
#import methods/reference/sample.wgsl

@group(1) @binding(0) var<uniform> light_sample: LightSample;
@group(1) @binding(1) var sample_distance: texture_2d<f32>;
@group(1) @binding(2) var<storage, read_write> sums: array<vec4<f32>>; // 2 per pixel

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if !covered(pixel) {
        return;
    }
    let x = textureLoad(gbuf_position, pixel, 0).xyz;
    let n = textureLoad(gbuf_normal, pixel, 0).xyz;
    let to_light = light_sample.position.xyz - x;
    let dist = length(to_light);
    let w = to_light / dist;
    let cos_x = dot(n, w);
    let cos_y = -dot(frame.light_n.xyz, w);
    if cos_x <= 0.0 || cos_y <= 0.0 {
        return;
    }
    let contribution = light_sample.radiance.rgb * (cos_x * cos_y / (dist * dist));
    var visible = 1.0;
    let clip = light_sample.view_proj * vec4<f32>(x, 1.0);
    let ndc = clip.xy / clip.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    // Outside the sample's frustum (beyond its widest angle) nothing is recorded: lit.
    if clip.w > 0.0 && all(uv >= vec2<f32>(0.0)) && all(uv < vec2<f32>(1.0)) {
        let res = light_sample.params.y;
        let texel = clamp(vec2<i32>(floor(uv * res)), vec2<i32>(0), vec2<i32>(i32(res) - 1));
        let nearest = textureLoad(sample_distance, texel, 0).r;
        // Bias in texels of this sample's map at the receiver, constant plus slope-scaled:
        // it shrinks with resolution, so the estimate converges to true visibility.
        let texel_m = 2.0 * dist * cos_y * light_sample.params.x / res;
        let tan_x = min(sqrt(max(1.0 - cos_x * cos_x, 0.0)) / max(cos_x, 0.05), 10.0);
        let bias = texel_m * (light_sample.params.z + light_sample.params.w * tan_x);
        visible = select(0.0, 1.0, dist - bias <= nearest);
    }
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    sums[index] += vec4<f32>(contribution * visible, 0.0);
    sums[index + 1u] += vec4<f32>(contribution, 0.0);
}
