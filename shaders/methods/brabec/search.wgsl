// Method `brabec`: the search (§3.2, §3.3) of every pixel the lattice and the marking passes
// listed, in one compacted dispatch sized on the GPU.

#import methods/brabec/common.wgsl

@compute @workgroup_size(1)
fn listed_size() {
    frame = frame_uniform;
    params = params_uniform;
    search_groups = list_dispatch(atomicLoad(&to_search.count));
}

// The search without jitter (`jitter_texels` 0, the default) and with it: two entry points,
// so the constant compiles the jitter out of the first (see `search`).
@compute @workgroup_size(64)
fn search_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    search_list_position(list_position(group, lane), false);
}

@compute @workgroup_size(64)
fn search_listed_jittered(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    search_list_position(list_position(group, lane), true);
}

fn search_list_position(i: u32, jittered: bool) {
    if i < atomicLoad(&to_search.count) {
        search_into(listed_pixel(to_search.pixels[i]), jittered);
    }
}
