// Method `pcss` (Fernando 2005): blocker search, penumbra estimate from the light's size and
// the blocker/receiver depths, percentage-closer filtering — the plain average of the filter's
// shadow tests, gray. The baseline Chun & Oh 2016 improve on (their Table 1's "average
// visibility" method).

#import methods/pcss/filter.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var v = 1.0;
    if covered(pixel) {
        let f = run_filter(pixel);
        v = f32(f.lit) / f32(f.taps);
        atomicAdd(&counters[0], 1u);
        atomicAdd(&counters[4], u32(f.found_blocker));
        atomicAdd(&counters[5], 1u);
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, v, v, 1.0));
}
