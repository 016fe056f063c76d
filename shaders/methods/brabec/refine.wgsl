// Method `brabec`, passes 3 and 4 (§4.3): groups of 5 pixels between lattice pixels are
// interpolated or refined, along every 4th column (and the last) first, then along every row
// between the columns that filled: the 4×4 blocks are complete. One shader for both
// directions; `ALONG_ROWS` picks one per pipeline, so neither carries the other's code.

#import methods/brabec/common.wgsl

// false: pass 3, along the lattice's columns; true: pass 4, along every row.
override ALONG_ROWS: bool = false;

fn refine_group(id: vec3<u32>, marking: bool) {
    let size = frame.sizes.xy;
    if ALONG_ROWS {
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
    } else {
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
