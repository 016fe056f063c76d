// Method `jfa-l`, §4.1 "Generating Final Image": hard shadow → 0; a penumbra-map hit →
// the intensity recomputed from this eye pixel's own point and the stored occluder (not the
// stored intensity, which would be blocky at the shadow map's resolution); else 1. With
// `inner` on, a pixel in hard shadow takes the inner-penumbra intensity of the silhouette
// point its texel holds (`flood_light.wgsl`), 0 where the ray through it misses the light.
//
// The pixels that need the intensity are listed and shaded by an indirect dispatch of their
// own (shading.wgsl says why).

#import methods/jfa/shading.wgsl

// The record the flood left at the shadow-map texel of point p (empty outside the map).
fn texel_record(p: vec3<f32>) -> vec4<f32> {
    let ls = to_light_space(p);
    if !ls.inside {
        return vec4<f32>(0.0);
    }
    return record_at(ls);
}

// The record at the texel of a point inside the map, already in light space.
fn record_at(ls: LightSpace) -> vec4<f32> {
    let texel = shadow_texel(ls.uv);
    return src[u32(texel.y) * frame.sizes.z + u32(texel.x)];
}

// Every pixel, a run of `ROW_PIXELS` of a row per invocation: 1, 0 in hard shadow, or listed
// when the flood left it an occluder to shade by.
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
        // The normal texel once, for the coverage and the bias's normal (`covers`).
        let normal = textureLoad(gbuf_normal, pixel, 0);
        if covers(normal) {
            let p = textureLoad(gbuf_position, pixel, 0).xyz;
            let ls = to_light_space(p);
            if ls.inside {
                let record = record_at(ls);
                let hard = hard_shadowed_in_map(p, normal.xyz, ls);
                let needed = select(in_penumbra(record), params.inner == 1u && !is_empty(record), hard);
                if needed {
                    listing |= 1u << k;
                    hard_bits |= u32(hard) << k;
                    continue;
                }
                v = select(v, vec3<f32>(0.0), hard);
            }
        }
        visibility_out[pixel_index(pixel)] = vec4<f32>(v, 1.0);
    }
    list_run_for_shading(first, listing, hard_bits);
}

// The listed pixels: the intensity for the occluder their texel holds (inner penumbra where in
// hard shadow).
@compute @workgroup_size(64)
fn shade_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let listed = listed_for_shading(group, lane);
    if listed.z > 1u {
        return;
    }
    let p = textureLoad(gbuf_position, listed.xy, 0).xyz;
    let record = texel_record(p);
    let hard = listed.z == 1u;
    store_shaded(listed.xy, hard, final_intensity(p, record.xyz, hard, silhouette_normal(record.xyz, 2, params.silhouette_relative)));
}
