// E0's second interpolated pass: each block's pixels blended from its corners where the
// check allows, the others listed for the exact passes (shaders/e0/common.wgsl).

#import e0/common.wgsl
#import e0/blend.wgsl
#import e0/check.wgsl

// E0 at one pixel interpolated from its block's corners, corrected along the view ray
// (`ray_offset`): xyz, and w = 1 where the estimate accepts it (or the pixel receives no
// light); where it must be summed exactly, w = 0 if every cell lies above its horizon
// (`exact_above`), else −1 (`exact_clipped`). `normal` is the pixel's G-buffer normal texel
// (w: coverage); `mixed`, the blend of the block's corners at the pixel (`blend_in_row`).
fn interpolated_e0(x: vec3<f32>, normal: vec4<f32>, b: Block, mixed: Corner, check: Check) -> vec4<f32> {
    let nx = normal.xyz;
    if !covers(normal) || !lit_side(x) {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    let t = ray_offset(x, mixed);
    // The centre's error with a margin; what the derivative's error adds where the pixel lies
    // farther along its ray than the centre did; and the second order in t.
    let dist = light_distance(x);
    let reach = t / dist;
    let beyond = abs(t - check.ray) / dist;
    let first_order = check.first * beyond;
    let second_order = RAY_SECOND * reach * reach;
    let relative = ERROR_MARGIN * check.error + first_order + second_order;
    let phi = phi_of(mixed) + check.d_phi * t;
    // Both cases in straight-line code (lavapipe runs both sides of a branch its SIMD group
    // splits on, and a landscape splits most groups): with every cell above the horizon
    // E0 is |nx · Φ|; where the light straddles it, on a flat face (the corners' normal the
    // pixel's) E0 is still smooth in the position and is blended itself; with every cell
    // below it E0 is 0, exactly the sum (`cells_horizon`).
    let horizon = cells_horizon(x, nx);
    let above = horizon.above;
    let below = horizon.below;
    let e0 = select(select(e0_of(mixed) + check.d_e0 * t, abs(nx * phi), above), vec3<f32>(0.0), below);
    let size2 = vec3<f32>(dot(phi[0], phi[0]), dot(phi[1], phi[1]), dot(phi[2], phi[2]));
    let bound = E0_TOLERANCE * e0;
    // Every cell above: relative × |Φ| ≤ E0_TOLERANCE × E0, compared squared (no square root
    // per channel); both sides' signs kept (relative ≥ 0, E0 may not be).
    let fits_above = all(relative * relative * size2 <= bound * abs(bound));
    // Straddled, on a flat face: E0's own error over the block with the margin, plus what
    // lies off the centre in units of |Φ| — the ray terms and the pixel's bend from the
    // corners' normals (E0 moves by up to |Φ| per unit of normal) — at most E0_TOLERANCE × E0:
    // what the first leaves, squared, against the second's square (no square root either).
    // UNCHECKED fails it.
    let off_centre = first_order + second_order + bend(b, nx);
    let room = bound - ERROR_MARGIN * check.e0_error;
    let fits_straddled = all(room >= vec3<f32>(0.0)) && all(off_centre * off_centre * size2 <= room * room);
    let done = (select(fits_straddled, fits_above, above) && check.error < UNCHECKED) || below;
    return vec4<f32>(e0, select(select(-1.0, 0.0, above), 1.0, done));
}

// Appends the pixels of a block whose bits are set in `mask` — bit 8r + x: column x of row
// `first_row` + r — to `above` or to `clipped`, with one atomic for the lot. (WGSL passes no
// pointer to a storage buffer into a function, so the list is chosen by a flag.)
fn append_rows(to_above: bool, origin: vec2<u32>, first_row: u32, mask: u32) {
    if mask == 0u {
        return;
    }
    var at: u32;
    if to_above {
        at = atomicAdd(&above.count, countOneBits(mask));
    } else {
        at = atomicAdd(&clipped.count, countOneBits(mask));
    }
    var rest = mask;
    while rest != 0u {
        let bit = next_in_run(&rest);
        let entry = pixel_index(origin + vec2<u32>(bit % BLOCK, first_row + bit / BLOCK));
        if to_above {
            above.pixels[at] = entry;
        } else {
            clipped.pixels[at] = entry;
        }
        at++;
    }
}

// Pass 2, one invocation per block (a row of blocks per workgroup row): the centre checks
// the interpolation, then each of the block's pixels is interpolated where the estimate
// allows and listed otherwise for the exact sum — in `above` where every cell lies above
// its horizon, else in `clipped` — four rows at a time (an atomic append per pixel is a loop
// over the lanes on lavapipe). One invocation loads the block's 20
// corner vectors for its 64 pixels: on lavapipe a storage load is a gather lane by lane
// whatever the lanes read, so loading them per pixel cost more than the interpolation itself.
@compute @workgroup_size(64)
fn interpolate_blocks(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let block = id.xy;
    if any(block >= corner_count() - 1u) {
        return;
    }
    let b = load_block(block);
    let check = block_check(block, b);
    let origin = block * BLOCK;
    let step = pixel_step(block);
    // The pixels to list, four rows at a time: 4 × BLOCK (8) bits.
    var to_above = 0u;
    var to_clip = 0u;
    for (var y = 0u; y < BLOCK; y++) {
        let row = row_blend(b, f32(y) * step.y);
        for (var x = 0u; x < BLOCK; x++) {
            let bit = 1u << ((y % 4u) * BLOCK + x);
            let pixel = origin + vec2<u32>(x, y);
            if all(pixel < frame.sizes.xy) {
                // Loaded once here: lavapipe runs the listing branch's code for every pixel.
                let position = textureLoad(gbuf_position, pixel, 0).xyz;
                let normal = textureLoad(gbuf_shading, pixel, 0);
                let e0 = interpolated_e0(position, normal, b, blend_in_row(row, f32(x) * step.x), check);
                // Stored whether or not the estimate holds: a refused pixel's value is
                // overwritten by its exact pass, and lavapipe stores a whole SIMD group for
                // less than it stores a masked part of one (the pass −7 % on `terrain`).
                e0_out[pixel_index(pixel)] = vec4<f32>(e0.xyz, 1.0);
                if e0.w == 0.0 {
                    // Every cell above the horizon: summed without clipping.
                    to_above |= bit;
                } else if e0.w < 0.0 {
                    to_clip |= bit;
                }
            }
        }
        if y % 4u == 3u {
            append_rows(true, origin, y - 3u, to_above);
            append_rows(false, origin, y - 3u, to_clip);
            to_above = 0u;
            to_clip = 0u;
        }
    }
}
