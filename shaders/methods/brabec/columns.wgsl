// Method `brabec`, pass 3 (§4.3): along every 4th column (and the last), groups of 5 pixels
// between lattice pixels are interpolated or refined.

#import methods/brabec/common.wgsl

fn refine_group(id: vec3<u32>, marking: bool) {
    let size = frame.sizes.xy;
    // Lattice columns: every 4th, plus the last one when it is not already among them.
    let columns = (size.x - 1u) / 4u + 1u + select(0u, 1u, (size.x - 1u) % 4u != 0u);
    let groups = (size.y + 2u) / 4u;
    let column = id.x % columns;
    let group = id.x / columns;
    if group >= groups {
        return;
    }
    let x = min(column * 4u, size.x - 1u);
    let y0 = group * 4u;
    let y1 = min(y0 + 4u, size.y - 1u);
    if y1 <= y0 {
        return;
    }
    refine(vec2<u32>(x, y0), vec2<u32>(0u, 1u), y1 - y0, marking);
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
