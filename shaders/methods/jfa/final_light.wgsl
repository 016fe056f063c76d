// Method `jfa-l`, §4.1 "Generating Final Image": hard shadow → 0; a penumbra-map hit →
// the intensity recomputed from this eye pixel's own point and the stored occluder (not the
// stored intensity, which would be blocky at the shadow map's resolution); else 1. With
// `inner` on, a pixel in hard shadow takes the inner-penumbra intensity of the silhouette
// point its texel holds (`flood_light.wgsl`), 0 where the ray through it misses the light.

#import methods/jfa/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var v = vec3<f32>(1.0);
    if covered(pixel) {
        let p = textureLoad(gbuf_position, pixel, 0).xyz;
        let ls = to_light_space(p);
        if ls.inside {
            let texel = shadow_texel(ls.uv);
            let record = src[u32(texel.y) * frame.sizes.z + u32(texel.x)];
            if hard_shadowed(pixel) {
                v = vec3<f32>(0.0);
                if params.inner == 1u && !is_empty(record) {
                    let i = final_intensity(p, record.xyz, true, silhouette_normal(record.xyz, 2, params.silhouette_relative));
                    if i.w > 0.0 {
                        v = i.rgb;
                        atomicAdd(&counters[1], 1u);
                    }
                }
            } else {
                if in_penumbra(record) {
                    let i = final_intensity(p, record.xyz, false, silhouette_normal(record.xyz, 2, params.silhouette_relative));
                    if i.w > 0.0 {
                        v = i.rgb;
                        atomicAdd(&counters[1], 1u);
                    }
                }
            }
        }
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}
