// A list of pixels for a compacted pass, and the indirect dispatch that walks it. On lavapipe
// a branch costs its code in every pixel of an 8-wide SIMD group that any of them takes, so
// work only a few pixels need is not branched to inside a per-pixel pass: those pixels are
// appended here and a dispatch sized on the GPU runs over them alone. Needs `frame`
// (common/frame_inputs.wgsl).

struct PixelList {
    count: atomic<u32>,
    pixels: array<u32>, // pixel_index(pixel)
}

// Lanes per workgroup of a listed dispatch, and the grid's width in workgroups (Vulkan's
// guaranteed minimum per dimension).
const LIST_GROUP: u32 = 64u;
const LIST_MAX_GROUPS: u32 = 65535u;

fn listed_pixel(index: u32) -> vec2<u32> {
    return vec2<u32>(index % frame.sizes.x, index / frame.sizes.x);
}

// Appending a run. A pass that lists pixels tests a run of them (a row's few pixels, a block's
// rows) in one invocation, sets a bit of a mask per pixel to list, and appends the run with
// one atomic — on lavapipe an atomic is a loop over the lanes, and one per pixel on one
// counter passes its cache line between the cores:
//     var at = atomicAdd(&LIST.count, countOneBits(mask));
//     var rest = mask;
//     while rest != 0u {
//         LIST.pixels[at] = pixel_index(first + vec2<u32>(next_in_run(&rest), 0u));
//         at++;
//     }
// (WGSL passes no pointer to a storage buffer into a function, so each list's append is
// written where the list is bound.) Sizing: a one-invocation entry point writes the list's
// grid, `LIST_groups = list_dispatch(atomicLoad(&LIST.count))`; walking: the indirect
// dispatch's lanes take `list_position(group, lane)` while it is below the count
// (`render::PixelListBuffers` records the two).

// The lowest set bit of a run's mask, cleared from it: the next listed pixel of the run.
fn next_in_run(rest: ptr<function, u32>) -> u32 {
    let k = firstTrailingBit(*rest);
    *rest &= *rest - 1u;
    return k;
}

// The workgroup grid of a dispatch over `count` listed pixels.
fn list_dispatch(count: u32) -> array<u32, 3> {
    let groups = (count + LIST_GROUP - 1u) / LIST_GROUP;
    return array<u32, 3>(min(groups, LIST_MAX_GROUPS), (groups + LIST_MAX_GROUPS - 1u) / LIST_MAX_GROUPS, 1u);
}

// The list position a lane of a listed dispatch works on (may be past the count).
fn list_position(group: vec3<u32>, lane: u32) -> u32 {
    return (group.y * LIST_MAX_GROUPS + group.x) * LIST_GROUP + lane;
}
