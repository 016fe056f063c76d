// Method `reference`, last pass: visibility per channel as the ratio of the two sums,
// V = Σ L·G·V / Σ L·G. Using the same samples in numerator and denominator makes fully lit
// points exactly 1 and umbrae exactly 0 (a ratio estimator). A channel the light does not
// emit at all takes the ratio of the channel sums; a point no sample reaches is lit (1).

#import common/frame_inputs.wgsl

// As in `accumulate.wgsl`: 1 where every sample's weight is gray, else 3.
override CHANNELS: u32 = 3u;

// Per covered pixel, 2·CHANNELS floats: Σ L·G·V, then Σ L·G.
@group(1) @binding(0) var<storage, read> sums: array<f32>;
@group(1) @binding(1) var<storage, read_write> visibility_out: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    // The accumulate pass leaves the sums of pixels without a surface unwritten.
    var v = vec3<f32>(1.0);
    if covered(pixel) {
        let base = 2u * CHANNELS * (pixel.y * frame.sizes.x + pixel.x);
        var shadowed: vec3<f32>;
        var unshadowed: vec3<f32>;
        if CHANNELS == 1u {
            shadowed = vec3<f32>(sums[base]);
            unshadowed = vec3<f32>(sums[base + 1u]);
        } else {
            shadowed = vec3<f32>(sums[base], sums[base + 1u], sums[base + 2u]);
            unshadowed = vec3<f32>(sums[base + 3u], sums[base + 4u], sums[base + 5u]);
        }
        let total = unshadowed.r + unshadowed.g + unshadowed.b;
        let gray = select(1.0, (shadowed.r + shadowed.g + shadowed.b) / total, total > 0.0);
        v = select(vec3<f32>(gray), shadowed / unshadowed, unshadowed > vec3<f32>(0.0));
    }
    visibility_out[pixel_index(pixel)] = vec4<f32>(clamp(v, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}
