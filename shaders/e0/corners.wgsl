// E0's first interpolated pass: Φ and the exact sum at every block corner (shaders/e0/common.wgsl
// says what E0 is and how the passes share it out).

#import e0/common.wgsl

// Pass 1: Φ per channel and the exact E0 at every block corner — where the light straddles
// the corner's horizon, only where a block beside it may blend E0 (`beside_agreeing`).
@compute @workgroup_size(8, 8)
fn block_corners(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let count = corner_count();
    if any(id.xy >= count) {
        return;
    }
    let pixel = corner_pixel(id.xy);
    let normal = textureLoad(gbuf_shading, pixel, 0);
    corners[id.y * count.x + id.x] = surface_terms(pixel, normal, beside_agreeing(id.xy, count, normal.xyz));
}

// |a − b|², the squared distance between two unit normals: how far apart the corners' and

// the one use of a corner's clipped sum: such a block's corners lie within BENT of its first
// (`agrees`), so within 2 BENT of each other, and it holds c and one of c's two
// neighbours along the row. Where neither neighbour's normal lies that near c's (2.5 BENT:
// room for rounding), no block takes c's clipped sum, and it is not made (a corner at the
// row's end counts as its own neighbour, and always makes it).
// `n`: c's own normal.
fn beside_agreeing(c: vec2<u32>, count: vec2<u32>, n: vec3<f32>) -> bool {
    let left = textureLoad(gbuf_shading, corner_pixel(vec2<u32>(max(c.x, 1u) - 1u, c.y)), 0).xyz;
    let right = textureLoad(gbuf_shading, corner_pixel(vec2<u32>(min(c.x + 1u, count.x - 1u), c.y)), 0).xyz;
    let limit = (2.5 * BENT) * (2.5 * BENT);
    return normal_gap2(left, n) <= limit || normal_gap2(right, n) <= limit;
}

// A block's four corner records.
