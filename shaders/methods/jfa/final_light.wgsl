// Method `jfa-l`, §4.1 "Generating Final Image": hard shadow → 0; a penumbra-map hit →
// the intensity recomputed from this eye pixel's own point and the stored occluder (not the
// stored intensity, which would be blocky at the shadow map's resolution); else 1. With
// `inner` on, a pixel in hard shadow takes the inner-penumbra intensity of the silhouette
// point its texel holds (`flood_light.wgsl`), 0 where the ray through it misses the light.
//
// The pixels that need the intensity (a few percent of a frame) are listed and shaded by an
// indirect dispatch of their own: lavapipe runs a branch's code — here the intensity and a
// 5×5 silhouette window — for all 8 lanes of a SIMD group if one lane takes it.

#import methods/jfa/common.wgsl
#import common/pixel_list.wgsl

// The pixels to shade: list index << 1 | 1 where the pixel is in hard shadow.
@group(1) @binding(10) var<storage, read_write> shaded: PixelList;
@group(1) @binding(11) var<storage, read_write> shaded_groups: array<u32, 3>; // indirect dispatch

// The record the flood left at pixel `pixel`'s texel, and whether it lies in the shadow map.
fn texel_record(p: vec3<f32>) -> vec4<f32> {
    let ls = to_light_space(p);
    if !ls.inside {
        return vec4<f32>(0.0);
    }
    let texel = shadow_texel(ls.uv);
    return src[u32(texel.y) * frame.sizes.z + u32(texel.x)];
}

// Every pixel: 1, 0 in hard shadow, or listed when the flood left it an occluder to shade by.
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var v = vec3<f32>(1.0);
    if covered(pixel) {
        let p = textureLoad(gbuf_position, pixel, 0).xyz;
        if to_light_space(p).inside {
            let record = texel_record(p);
            let hard = hard_shadowed(pixel);
            let needed = select(in_penumbra(record), params.inner == 1u && !is_empty(record), hard);
            if needed {
                shaded.pixels[atomicAdd(&shaded.count, 1u)] = list_index(pixel) << 1u | u32(hard);
                return;
            }
            v = select(v, vec3<f32>(0.0), hard);
        }
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}

// The size of `shade_listed`'s dispatch.
@compute @workgroup_size(1)
fn shaded_size() {
    shaded_groups = list_dispatch(atomicLoad(&shaded.count));
}

// The listed pixels: the intensity for the occluder their texel holds (inner penumbra where in
// hard shadow), or 0 / 1 where the ray through it misses the light.
@compute @workgroup_size(64)
fn shade_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let i = list_position(group, lane);
    if i >= atomicLoad(&shaded.count) {
        return;
    }
    let entry = shaded.pixels[i];
    let pixel = listed_pixel(entry >> 1u);
    let hard = (entry & 1u) == 1u;
    let p = textureLoad(gbuf_position, pixel, 0).xyz;
    let record = texel_record(p);
    let intensity = final_intensity(p, record.xyz, hard, silhouette_normal(record.xyz, 2, params.silhouette_relative));
    var v = select(vec3<f32>(1.0), vec3<f32>(0.0), hard);
    if intensity.w > 0.0 {
        v = intensity.rgb;
        atomicAdd(&counters[1], 1u);
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}
