// Method `wedges`, three-pass variant (§6.1), the penumbra pass: wedges over their tiles
// (`rasterize.wgsl`). Most points of a tile a wedge reaches lie outside it, and lavapipe runs
// the whole share computation for all 8 lanes of a SIMD group if one lane needs it; so the
// pass first lists the (item, pixel) pairs inside their wedge (`mark_inside`), then shades
// only those (`shade_listed`, an indirect dispatch sized on the GPU), a chunk of items at a
// time. `main` shades every pixel of each item, as the paper's pass does.

#import methods/wedges/rasterize.wgsl
#import methods/wedges/share.wgsl
#import common/pixel_list.wgsl

@compute @workgroup_size(LANES)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let item = tile_item(group, groups, local);
    if !item.valid {
        return;
    }
    let w = wedges[item.job.primitive - params.polygon_count];
    for (var k = local; k < TILE * TILE; k += LANES) {
        let px = tile_pixel(item.origin, k);
        if px.valid {
            add_light(px.at, penumbra_delta(w, px));
        }
    }
}

// Lists the pixels of each item's tile that lie inside its wedge and whose projected edge
// crosses the light (`projected_edge`): a quarter of the pixels inside a wedge are not, and
// in the shading pass they would idle beside lanes that integrate (lavapipe runs a SIMD
// group's code for all of its lanes).
@compute @workgroup_size(LANES)
fn mark_inside(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let item = tile_item(group, groups, local);
    if !item.valid {
        return;
    }
    let index = item_index(group, groups);
    let w = wedges[item.job.primitive - params.polygon_count];
    // A lane's pixels are collected in a mask and appended with one atomic for up to 32 of
    // them (on lavapipe an atomic is a loop over the lanes). The pairs' order in the list
    // changes; the shading adds fixed-point shares, whose sum does not depend on it.
    var mask = 0u;
    var bit = 0u;
    var first = local;
    for (var k = local; k < TILE * TILE; k += LANES) {
        let px = tile_pixel(item.origin, k);
        if px.valid && inside_wedge(w, px.receiver) && projected_edge(w.edge, px.receiver.xyz).crosses {
            mask |= 1u << bit;
        }
        bit++;
        if bit == 32u || k + LANES >= TILE * TILE {
            append_pairs(index, first, mask);
            mask = 0u;
            bit = 0u;
            first = k + LANES;
        }
    }
}

// Appends the pairs of item `index` with the pixels first + LANES × b of its tile for each bit
// b set in `mask`, with one atomic for the lot — the append of E0's `append_rows` and `jfa`'s
// `list_run_for_shading`, each written for its own list: WGSL passes no pointer to a storage
// buffer into a function.
fn append_pairs(index: u32, first: u32, mask: u32) {
    if mask == 0u {
        return;
    }
    var at = atomicAdd(&inside.count, countOneBits(mask));
    var rest = mask;
    while rest != 0u {
        inside.pairs[at] = vec2<u32>(index, first + LANES * next_in_run(&rest));
        at++;
    }
}

// The size of `shade_listed`'s dispatch; counts the pairs it shades.
@compute @workgroup_size(1)
fn inside_size() {
    frame = frame_uniform;
    params = params_uniform;
    let count = atomicLoad(&inside.count);
    inside_groups = list_dispatch(count);
    atomicAdd(&counters[2], count);
}

// The listed pairs: each one's share of the light.
@compute @workgroup_size(64)
fn shade_listed(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let i = list_position(group, lane);
    if i < atomicLoad(&inside.count) {
        // Only the fields the share reads, each float a load lane by lane on lavapipe: the
        // item's primitive and tile, the wedge's edge (its planes were `mark_inside`'s), the
        // pixel's index without its receiver record (listed pixels lie on screen and are
        // covered; `penumbra_delta_inside` reads the record) — the pass −3 % on `terrain`.
        let pair = inside.pairs[i];
        let at = pixel_index(tile_pixel_at(tile_origin(work[pair.x].origin), pair.y));
        let edge = wedges[work[pair.x].primitive - params.polygon_count].edge;
        add_light(at, penumbra_delta_inside(edge, at));
    }
}

// Empties the list for the next chunk.
@compute @workgroup_size(1)
fn inside_reset() {
    frame = frame_uniform;
    params = params_uniform;
    atomicStore(&inside.count, 0u);
}
