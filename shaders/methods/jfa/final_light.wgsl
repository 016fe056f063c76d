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

// A pixel (`main` in shading.wgsl): listed when the flood left it an occluder to shade by,
// else 0 in hard shadow and 1 outside. The normal texel is read once, for the coverage and
// the bias's normal (`covers`).
fn final_class(pixel: vec2<u32>) -> FinalClass {
    let normal = textureLoad(gbuf_normal, pixel, 0);
    if !covers(normal) {
        return FinalClass(false, false, vec3<f32>(1.0));
    }
    let p = textureLoad(gbuf_position, pixel, 0).xyz;
    let ls = to_light_space(p);
    if !ls.inside {
        return FinalClass(false, false, vec3<f32>(1.0));
    }
    let record = record_at(ls);
    let hard = hard_shadowed_in_map(p, normal.xyz, ls);
    let listed = select(in_penumbra(record), params.inner == 1u && !is_empty(record), hard);
    return FinalClass(listed, hard, select(vec3<f32>(1.0), vec3<f32>(0.0), hard));
}

// The listed pixels: the intensity for the occluder their texel holds (inner penumbra where in
// hard shadow).
@compute @workgroup_size(64)
fn shade_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let listed = listed_for_shading(group, lane);
    if listed.z > 1u {
        return;
    }
    let p = textureLoad(gbuf_position, listed.xy, 0).xyz;
    let record = texel_record(p);
    let hard = listed.z == 1u;
    store_shaded(listed.xy, hard, final_intensity(p, record.xyz, hard, silhouette_normal(record.xyz, 2, params.silhouette_relative)));
}
