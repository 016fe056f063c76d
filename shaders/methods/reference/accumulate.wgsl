// Method `reference`, per batch of light samples: adds the batch's contributions to the two
// sums of the ratio estimator, per pixel: Σ L·G·V (shadowed) and Σ L·G (unshadowed), with
// G = cosθx·cosθy/|x−y|² and V from each sample's distance map (contract §1).
//
// Why batches, and why the samples are spelled out one by one: on lavapipe a per-pixel pass
// per sample paid for the G-buffer reads and the sums' update every sample, and a sample's
// uniforms indexed by a loop counter were loaded lane by lane (a gather per field). A batch
// reads and updates each pixel once, and constant indices make every sample's fields plain
// scalar loads.

#import common/frame_inputs.wgsl
#import methods/reference/sample.wgsl

// Samples per batch; mirrors `methods::reference::BATCH_SAMPLES`.
const BATCH: u32 = 8u;

struct Batch {
    count: u32,      // samples in the batch (1..=BATCH); sample k has layer k of `distances`
    row_texels: u32, // texels per row of a layer (rows padded for the copy)
    samples: array<LightSample, BATCH>,
}

@group(1) @binding(0) var<uniform> batch: Batch;
// The batch's distance maps, one after the other, each `resolution` rows of `row_texels`.
@group(1) @binding(1) var<storage, read> distances: array<f32>;
@group(1) @binding(2) var<storage, read_write> sums: array<vec4<f32>>; // 2 per pixel

struct Sums {
    shadowed: vec3<f32>,
    unshadowed: vec3<f32>,
}

// Sample `layer`'s L·G·V and L·G at x (normal n).
fn add_sample(sums: ptr<function, Sums>, x: vec3<f32>, n: vec3<f32>, layer: u32, light_sample: LightSample) {
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
        let texel = min(vec2<u32>(uv * res), vec2<u32>(u32(res) - 1u));
        let nearest = distances[(layer * u32(res) + texel.y) * batch.row_texels + texel.x] * light_sample.position.w;
        // Bias in texels of this sample's map at the receiver, constant plus slope-scaled:
        // it shrinks with resolution, so the estimate converges to true visibility.
        let texel_m = 2.0 * dist * cos_y * light_sample.params.x / res;
        let tan_x = min(sqrt(max(1.0 - cos_x * cos_x, 0.0)) / max(cos_x, 0.05), 10.0);
        let bias = texel_m * (light_sample.params.z + light_sample.params.w * tan_x);
        visible = select(0.0, 1.0, dist - bias <= nearest);
    }
    (*sums).shadowed += contribution * visible;
    (*sums).unshadowed += contribution;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if !covered(pixel) {
        return;
    }
    let x = textureLoad(gbuf_position, pixel, 0).xyz;
    let n = textureLoad(gbuf_normal, pixel, 0).xyz;
    var s = Sums(vec3<f32>(0.0), vec3<f32>(0.0));
    add_sample(&s, x, n, 0u, batch.samples[0]);
    if batch.count > 1u { add_sample(&s, x, n, 1u, batch.samples[1]); }
    if batch.count > 2u { add_sample(&s, x, n, 2u, batch.samples[2]); }
    if batch.count > 3u { add_sample(&s, x, n, 3u, batch.samples[3]); }
    if batch.count > 4u { add_sample(&s, x, n, 4u, batch.samples[4]); }
    if batch.count > 5u { add_sample(&s, x, n, 5u, batch.samples[5]); }
    if batch.count > 6u { add_sample(&s, x, n, 6u, batch.samples[6]); }
    if batch.count > 7u { add_sample(&s, x, n, 7u, batch.samples[7]); }
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    sums[index] += vec4<f32>(s.shadowed, 0.0);
    sums[index + 1u] += vec4<f32>(s.unshadowed, 0.0);
}
