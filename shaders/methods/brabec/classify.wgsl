// Method `brabec`, pass 1: per pixel the hard-shadow test and object id that the adaptive
// sampling compares (§4.3); t starts unknown. With `adaptive` off the search runs here for
// every pixel instead.

#import methods/brabec/common.wgsl

// The covered pixels, tallied per workgroup and added to `counters.shaded` once: on lavapipe
// an atomic is a loop over the lanes, and both cores adding to one counter for every pixel
// passed its cache line back and forth.
var<workgroup> shaded: atomic<u32>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let pixel = id.xy;
    if all(pixel < frame.sizes.xy) {
        let i = state_index(pixel);
        let key = pixel_key(pixel);
        state[i].key = key;
        state[i].t = UNKNOWN;
        state[i].normal = vec2<f32>(0.0);
        state[i].edge = 0.0;
        // Every covered pixel has an object's key (`pixel_key`): no second coverage fetch.
        if key != BACKGROUND_KEY {
            atomicAdd(&shaded, 1u);
        }
    }
    workgroupBarrier();
    if lane == 0u {
        atomicAdd(&counters.shaded, atomicLoad(&shaded));
    }
}
