// Method `brabec`, pass 1: per pixel the hard-shadow test and object id that the adaptive
// sampling compares (§4.3); t starts unknown. With `adaptive` off the search runs here for
// every pixel instead.

#import methods/brabec/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    let i = state_index(pixel);
    state[i].key = pixel_key(pixel);
    state[i].t = UNKNOWN;
    state[i].normal = vec2<f32>(0.0);
    state[i].edge = 0.0;
    if covered(pixel) {
        atomicAdd(&counters.shaded, 1u);
    }
}
