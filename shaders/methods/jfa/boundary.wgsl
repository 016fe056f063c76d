// Method `jfa-e`, §5.1 "Locating Occluders": an eye pixel in hard shadow with a lit neighbour
// whose surface point is close in 3D (not a depth discontinuity) is a boundary pixel; it seeds
// the flood with the occluding silhouette point — what the light centre sees at its light-space
// position — its own inner-penumbra intensity, and the silhouette's direction there.

#import methods/jfa/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    let size = frame.sizes.xy;
    if any(pixel >= size) {
        return;
    }
    var record = vec4<f32>(0.0);
    var origin = vec4<f32>(0.0);
    let is_covered = covered(pixel);
    let hard = is_covered && hard_shadowed(pixel);
    flags[pixel.y * size.x + pixel.x] = select(0u, COVERED, is_covered) | select(0u, HARD, hard);
    if hard {
        let here = textureLoad(gbuf_position, pixel, 0);
        let reach = here.w * params.boundary_relative;
        var boundary = false;
        var lit = here.xyz;
        for (var b = -1; b <= 1; b++) {
            for (var a = -1; a <= 1; a++) {
                let n = vec2<i32>(pixel) + vec2<i32>(a, b);
                if any(n < vec2<i32>(0)) || any(n >= vec2<i32>(size)) {
                    continue;
                }
                let m = vec2<u32>(n);
                let there = textureLoad(gbuf_position, m, 0).xyz;
                if covered(m) && !hard_shadowed(m) && distance(there, here.xyz) < reach {
                    boundary = true;
                    lit = there;
                }
            }
        }
        if boundary {
            let texel = shadow_texel(to_light_space(here.xyz).uv);
            let occluder = textureLoad(shadow_position, texel, 0).xyz;
            let i = intensity(here.xyz, occluder, true);
            // A seed whose own ray misses the light still passes its occluder on.
            let key = select(SEED_KEY, 1.0 - luminance(i.rgb), i.w > 0.0);
            let id_bits = f32(textureLoad(gbuf_id, pixel, 0).r);
            record = packed(occluder, key);
            // The silhouette's direction at the occluder point, once per seed: the lit
            // neighbour's texel lies beyond the silhouette, so a window reaching it finds it.
            let reach_texels = distance(to_light_space(lit).uv, to_light_space(here.xyz).uv) * f32(frame.sizes.z);
            let normal = silhouette_normal(occluder, clamp(i32(ceil(reach_texels)) + 1, 2, 8), params.silhouette_relative);
            let angle = select(atan2(normal.y, normal.x), NO_NORMAL, dot(normal, normal) == 0.0);
            origin = vec4<f32>(vec2<f32>(pixel), id_bits, angle);
            mark_tile(vec2<i32>(pixel));
            atomicAdd(&counters[0], 1u);
        }
    }
    let index = 2u * (pixel.y * size.x + pixel.x);
    dst[index] = record;
    dst[index + 1u] = origin;
}
