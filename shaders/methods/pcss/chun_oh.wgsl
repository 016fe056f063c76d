// Method `chun-oh` (Chun & Oh 2016 §3): the PCSS filter (`filter.wgsl`), then the adaptive
// quadtree over its tests (`quadtree.wgsl`): sub-region visibility × the colour of the
// matching part of the light image, for coloured penumbrae.

#import methods/pcss/filter.wgsl
#import methods/pcss/quadtree.wgsl

fn light_region(i: u32) -> vec4<f32> {
    return light_regions[i];
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var v = vec3<f32>(1.0);
    if covered(pixel) {
        let f = run_filter(pixel);
        let e0 = f32(f.lit) / f32(f.taps);
        var s = Subdivision(e0 * light_region(WHOLE).rgb, 0u, 0u);
        // No blocker found: fully lit, nothing to split.
        if f.found_blocker {
            s = subdivide(e0, QuadtreeParams(params.mode, params.threshold, params.light_threshold, params.lattice / 4u));
            atomicAdd(&counters[4], 1u);
            atomicAdd(&counters[3], s.forced);
        }
        atomicAdd(&counters[s.level], 1u);
        atomicAdd(&counters[5], 1u);
        v = coloured_visibility(s, e0);
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, 1.0));
}
