// Method `brabec`, pass 4 (§4.3): along every row, groups of 5 pixels between the columns
// filled by pass 3 are interpolated or refined: the 4×4 blocks are complete.

#import methods/brabec/common.wgsl

fn refine_group(id: vec3<u32>, marking: bool) {
    let size = frame.sizes.xy;
    let groups = (size.x + 2u) / 4u;
    let y = id.x / groups;
    let group = id.x % groups;
    if y >= size.y {
        return;
    }
    let x0 = group * 4u;
    let x1 = min(x0 + 4u, size.x - 1u);
    if x1 <= x0 {
        return;
    }
    refine(vec2<u32>(x0, y), vec2<u32>(1u, 0u), x1 - x0, marking);
}

// Before the search pass: lists the pixels the refinement will need searched.
@compute @workgroup_size(64)
fn mark_searches(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    refine_group(id, true);
}

// After it: interpolates.
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    refine_group(id, false);
}
