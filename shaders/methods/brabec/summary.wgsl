// Method `brabec`, pass 0: per 8×8 block of the light depth map, its nearest and farthest
// depth and its object id (or MIXED), which let a search prove that no texel of its square
// can be a hit before visiting any (`may_hit` in common.wgsl); and the map's depths and ids
// copied into the buffer the search reads (`map_texels`).

#import methods/brabec/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let blocks = summary_blocks();
    if any(id.xy >= vec2<u32>(u32(blocks))) {
        return;
    }
    let res = i32(frame.sizes.z);
    let origin = vec2<i32>(id.xy) * SUMMARY_BLOCK;
    let end = min(origin + SUMMARY_BLOCK, vec2<i32>(res));
    var near = 3.4e38;
    var far = -3.4e38;
    let first = textureLoad(shadow_id, origin, 0).r;
    var object = first;
    for (var y = origin.y; y < end.y; y++) {
        for (var x = origin.x; x < end.x; x++) {
            let t = vec2<i32>(x, y);
            let d = textureLoad(shadow_depth, t, 0).r;
            let texel_id = textureLoad(shadow_id, t, 0).r;
            map_texels[y * res + x] = vec2<u32>(bitcast<u32>(d), texel_id);
            near = min(near, d);
            far = max(far, d);
            object = select(MIXED, object, texel_id == first && object != MIXED);
        }
    }
    summary[u32(id.y) * u32(blocks) + u32(id.x)] = BlockSummary(near, far, object, 0u);
}
