// Method `reference`, last pass: visibility per channel as the ratio of the two sums,
// V = Σ L·G·V / Σ L·G. Using the same samples in numerator and denominator makes fully lit
// points exactly 1 and umbrae exactly 0 (a ratio estimator). A channel the light does not
// emit at all takes the ratio of the channel sums; a point no sample reaches is lit (1).

#import common/frame_inputs.wgsl

@group(1) @binding(0) var<storage, read> sums: array<vec4<f32>>;
@group(1) @binding(1) var<storage, read_write> visibility_out: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    let shadowed = sums[index].rgb;
    let unshadowed = sums[index + 1u].rgb;
    let total = unshadowed.r + unshadowed.g + unshadowed.b;
    let gray = select(1.0, (shadowed.r + shadowed.g + shadowed.b) / total, total > 0.0);
    let v = select(vec3<f32>(gray), shadowed / unshadowed, unshadowed > vec3<f32>(0.0));
    visibility_out[pixel_index(pixel)] = vec4<f32>(clamp(v, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}
