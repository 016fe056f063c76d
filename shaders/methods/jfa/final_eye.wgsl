// Method `jfa-e`, §5.1 "Generating Final Image": a pixel the flood reached takes the
// intensity it stored; otherwise hard shadow → 0, else 1.

#import methods/jfa/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var v = vec3<f32>(1.0);
    let flag = flags[pixel.y * frame.sizes.x + pixel.x];
    if (flag & COVERED) != 0u {
        let record = src[pixel.y * frame.sizes.x + pixel.x];
        if record.occluder.w > 0.0 && record.intensity.w <= 1.0 {
            v = record.intensity.rgb;
            atomicAdd(&counters[1], 1u);
        } else if (flag & HARD) != 0u {
            v = vec3<f32>(0.0);
        }
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}
