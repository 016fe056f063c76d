// Method `jfa-e`, §5.1 "Generating Final Image": a pixel the flood reached takes the
// intensity of the occluder it holds (recomputed from the record, the value flooding chose
// it by); otherwise hard shadow → 0, else 1.
//
// The pixels the flood reached are listed and shaded by an indirect dispatch of their own
// (shading.wgsl says why).

#import methods/jfa/shading.wgsl

// A pixel (`main` in shading.wgsl): listed when it holds a penumbra record, else 0 in hard
// shadow and 1 outside.
fn final_class(pixel: vec2<u32>) -> FinalClass {
    let flag = flags[pixel.y * frame.sizes.x + pixel.x];
    if (flag & COVERED) == 0u {
        return FinalClass(false, false, vec3<f32>(1.0));
    }
    let inside = (flag & HARD) != 0u;
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    let listed = eye_in_penumbra(src[index], src[index + 1u]);
    return FinalClass(listed, inside, select(vec3<f32>(1.0), vec3<f32>(0.0), inside));
}

// The listed pixels: the intensity of their occluder.
@compute @workgroup_size(64)
fn shade_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let listed = listed_for_shading(group, lane);
    if listed.z > 1u {
        return;
    }
    let pixel = listed.xy;
    let inside = listed.z == 1u;
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    let angle = src[index + 1u].w;
    let normal = select(vec2<f32>(cos(angle), sin(angle)), vec2<f32>(0.0), angle == NO_NORMAL);
    store_shaded(pixel, inside, final_intensity(textureLoad(gbuf_position, pixel, 0).xyz, src[index].xyz, inside, normal));
}
