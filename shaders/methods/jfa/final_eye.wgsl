// Method `jfa-e`, §5.1 "Generating Final Image": a pixel the flood reached takes the
// intensity of the occluder it holds (recomputed from the record, the value flooding chose
// it by); otherwise hard shadow → 0, else 1.
//
// The pixels the flood reached are listed and shaded by an indirect dispatch of their own
// (shading.wgsl says why).

#import methods/jfa/shading.wgsl

// Every pixel, a run of `ROW_PIXELS` of a row per invocation: 1, 0 in hard shadow, or listed
// when it holds a penumbra record.
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let first = vec2<u32>(id.x * ROW_PIXELS, id.y);
    if any(first >= frame.sizes.xy) {
        return;
    }
    // Bit k: pixel first + (k, 0) is listed (in `listing`), in hard shadow (in `hard_bits`).
    var listing = 0u;
    var hard_bits = 0u;
    for (var k = 0u; k < ROW_PIXELS; k++) {
        let pixel = first + vec2<u32>(k, 0u);
        if pixel.x >= frame.sizes.x {
            break;
        }
        var v = vec3<f32>(1.0);
        let flag = flags[pixel.y * frame.sizes.x + pixel.x];
        if (flag & COVERED) != 0u {
            let inside = (flag & HARD) != 0u;
            let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
            if eye_in_penumbra(src[index], src[index + 1u]) {
                listing |= 1u << k;
                hard_bits |= u32(inside) << k;
                continue;
            }
            v = select(v, vec3<f32>(0.0), inside);
        }
        visibility_out[pixel_index(pixel)] = vec4<f32>(v, 1.0);
    }
    list_run_for_shading(first, listing, hard_bits);
}

// The listed pixels: the intensity of their occluder.
@compute @workgroup_size(64)
fn shade_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
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
