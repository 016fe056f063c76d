// Method `jfa-e`, §5.1 "Generating Final Image": a pixel the flood reached takes the
// intensity of the occluder it holds (recomputed from the record, the value flooding chose
// it by); otherwise hard shadow → 0, else 1.

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
        let record = src[2u * (pixel.y * frame.sizes.x + pixel.x)];
        let inside = (flag & HARD) != 0u;
        let angle = src[2u * (pixel.y * frame.sizes.x + pixel.x) + 1u].w;
        let normal = select(vec2<f32>(cos(angle), sin(angle)), vec2<f32>(0.0), angle == NO_NORMAL);
        let i = final_intensity(textureLoad(gbuf_position, pixel, 0).xyz, record.xyz, inside, normal);
        if in_penumbra(record) && i.w > 0.0 {
            v = i.rgb;
            atomicAdd(&counters[1], 1u);
        } else if inside {
            v = vec3<f32>(0.0);
        }
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}
