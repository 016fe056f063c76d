// Method `jfa-e`, §5.1 "Generating Final Image": a pixel the flood reached takes the
// intensity of the occluder it holds (recomputed from the record, the value flooding chose
// it by); otherwise hard shadow → 0, else 1.
//
// The pixels the flood reached are listed and shaded by an indirect dispatch of their own
// (final_light.wgsl says why).

#import methods/jfa/common.wgsl
#import common/pixel_list.wgsl

// The pixels to shade: list index << 1 | 1 where the pixel is in hard shadow.
@group(1) @binding(10) var<storage, read_write> shaded: PixelList;
@group(1) @binding(11) var<storage, read_write> shaded_groups: array<u32, 3>; // indirect dispatch

// Every pixel: 1, 0 in hard shadow, or listed when it holds a penumbra record.
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var v = vec3<f32>(1.0);
    let flag = flags[pixel.y * frame.sizes.x + pixel.x];
    if (flag & COVERED) != 0u {
        let inside = (flag & HARD) != 0u;
        if in_penumbra(src[2u * (pixel.y * frame.sizes.x + pixel.x)]) {
            shaded.pixels[atomicAdd(&shaded.count, 1u)] = list_index(pixel) << 1u | u32(inside);
            return;
        }
        v = select(v, vec3<f32>(0.0), inside);
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}

// The size of `shade_listed`'s dispatch.
@compute @workgroup_size(1)
fn shaded_size() {
    shaded_groups = list_dispatch(atomicLoad(&shaded.count));
}

// The listed pixels: the intensity of their occluder, or 0 / 1 where its ray misses the light.
@compute @workgroup_size(64)
fn shade_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let i = list_position(group, lane);
    if i >= atomicLoad(&shaded.count) {
        return;
    }
    let entry = shaded.pixels[i];
    let pixel = listed_pixel(entry >> 1u);
    let inside = (entry & 1u) == 1u;
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    let record = src[index];
    let angle = src[index + 1u].w;
    let normal = select(vec2<f32>(cos(angle), sin(angle)), vec2<f32>(0.0), angle == NO_NORMAL);
    let intensity = final_intensity(textureLoad(gbuf_position, pixel, 0).xyz, record.xyz, inside, normal);
    var v = select(vec3<f32>(1.0), vec3<f32>(0.0), inside);
    if intensity.w > 0.0 {
        v = intensity.rgb;
        atomicAdd(&counters[1], 1u);
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}
