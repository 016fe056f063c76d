// Method `jfa-e`, §5.1 "Locating Occluders": an eye pixel in hard shadow with a lit neighbour
// whose surface point is close in 3D (not a depth discontinuity) is a boundary pixel; it seeds
// the flood with the occluding silhouette point — what the light centre sees at its light-space
// position — its own inner-penumbra intensity, and the silhouette's direction there.
//
// Three steps rather than one pass: every pixel's flags (covered, hard shadow) first, so that
// the boundary test reads its neighbours' flags instead of repeating their hard-shadow tests;
// then the boundary pixels are listed, and only they compute their seed (lavapipe runs a
// branch's code for all 8 lanes of a SIMD group if one lane takes it). Same seeds.

#import methods/jfa/common.wgsl
#import common/pixel_list.wgsl

// The boundary pixels: list index << 4 | the lit neighbour (3·(b + 1) + a + 1) that made it one.
@group(1) @binding(8) var<storage, read_write> boundary: PixelList;
@group(1) @binding(9) var<storage, read_write> boundary_groups: array<u32, 3>; // indirect dispatch

// Step 1, every pixel: its flags. The records start empty by a buffer fill in `flood`, not by
// this pass storing an empty record per pixel (lavapipe stores them lane by lane: about a
// quarter of the pass). The normal texel is read once, for the coverage and the bias both
// (`covers`).
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let pixel = id.xy;
    let size = frame.sizes.xy;
    if any(pixel >= size) {
        return;
    }
    let normal = textureLoad(gbuf_normal, pixel, 0);
    let is_covered = covers(normal);
    var hard = false;
    if is_covered {
        let p = textureLoad(gbuf_position, pixel, 0).xyz;
        let ls = to_light_space(p);
        hard = ls.inside && hard_shadowed_in_map(p, normal.xyz, ls);
    }
    flags[pixel.y * size.x + pixel.x] = select(0u, COVERED, is_covered) | select(0u, HARD, hard);
}

// Step 2, every pixel: lists those in hard shadow with a lit, covered neighbour close in 3D
// (the last such neighbour in scan order is the one remembered: the bits are visited in
// that order).
@compute @workgroup_size(8, 8)
fn mark_boundary(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let pixel = id.xy;
    let size = frame.sizes.xy;
    if any(pixel >= size) || (flags[pixel.y * size.x + pixel.x] & HARD) == 0u {
        return;
    }
    // The neighbours that are lit and covered, as bits 3·(b + 1) + a + 1, from their flags
    // alone: inside a shadow there are none, and the positions need not be read (on lavapipe
    // a SIMD group of 8 such pixels skips the second loop).
    var candidates = 0u;
    for (var b = -1; b <= 1; b++) {
        for (var a = -1; a <= 1; a++) {
            let n = vec2<i32>(pixel) + vec2<i32>(a, b);
            if any(n < vec2<i32>(0)) || any(n >= vec2<i32>(size)) {
                continue;
            }
            let m = vec2<u32>(n);
            if (flags[m.y * size.x + m.x] & (COVERED | HARD)) == COVERED {
                candidates |= 1u << u32(3 * (b + 1) + a + 1);
            }
        }
    }
    if candidates == 0u {
        return;
    }
    let here = textureLoad(gbuf_position, pixel, 0);
    let reach = here.w * params.boundary_relative;
    var lit = 16u;
    var rest = candidates;
    while rest != 0u {
        let k = firstTrailingBit(rest);
        rest &= rest - 1u;
        let m = vec2<u32>(vec2<i32>(pixel) + vec2<i32>(i32(k % 3u) - 1, i32(k / 3u) - 1));
        if distance(textureLoad(gbuf_position, m, 0).xyz, here.xyz) < reach {
            lit = k;
        }
    }
    if lit < 16u {
        boundary.pixels[atomicAdd(&boundary.count, 1u)] = pixel_index(pixel) << 4u | lit;
    }
}

// Step 3a: the size of step 3's dispatch.
@compute @workgroup_size(1)
fn boundary_size() {
    frame = frame_uniform;
    params = params_uniform;
    boundary_groups = list_dispatch(atomicLoad(&boundary.count));
}

// Step 3, the listed boundary pixels: their seeds.
@compute @workgroup_size(64)
fn seed_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let i = list_position(group, lane);
    if i >= atomicLoad(&boundary.count) {
        return;
    }
    let entry = boundary.pixels[i];
    let pixel = listed_pixel(entry >> 4u);
    let neighbour = vec2<i32>(i32(entry & 15u) % 3 - 1, i32(entry & 15u) / 3 - 1);
    let here = textureLoad(gbuf_position, pixel, 0);
    let lit = textureLoad(gbuf_position, vec2<u32>(vec2<i32>(pixel) + neighbour), 0).xyz;
    let texel = shadow_texel(to_light_space(here.xyz).uv);
    let occluder = shadow_point(texel).xyz;
    let intensity_here = intensity_key(here.xyz, occluder);
    // A seed whose own ray misses the light still passes its occluder on.
    let key = select(SEED_KEY, intensity_here.x, intensity_here.y > 0.0);
    let id_bits = f32(textureLoad(gbuf_id, pixel, 0).r);
    // The silhouette's direction at the occluder point, once per seed: the lit neighbour's
    // texel lies beyond the silhouette, so a window reaching it finds it.
    let reach_texels = distance(to_light_space(lit).uv, to_light_space(here.xyz).uv) * f32(frame.sizes.z);
    let normal = silhouette_normal(occluder, clamp(i32(ceil(reach_texels)) + 1, 2, 8), params.silhouette_relative);
    let angle = select(atan2(normal.y, normal.x), NO_NORMAL, dot(normal, normal) == 0.0);
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    dst[index] = eye_packed(occluder, id_bits);
    dst[index + 1u] = vec4<f32>(vec2<f32>(pixel), key, angle);
    mark_tile(vec2<i32>(pixel));
    atomicAdd(&counters[0], 1u);
}
