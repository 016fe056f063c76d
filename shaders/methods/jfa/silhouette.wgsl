// Method `jfa-l`, §4.1 "Locating Occluders": a shadow-map texel is a silhouette pixel when one
// of its 8 neighbours is deeper by more than a threshold (or empty); silhouette pixels seed
// the flood with their own light-space (world) position.

#import methods/jfa/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let res = frame.sizes.z;
    if any(id.xy >= vec2<u32>(res)) {
        return;
    }
    let p = vec2<i32>(id.xy);
    var record = vec4<f32>(0.0);
    let depth = map_depth_at(p);
    let here = shadow_point_at(p, depth);
    if here.w > 0.0 {
        // A neighbour past the map's edge is clamped onto it: onto p itself (never deeper) or
        // another of p's neighbours, so the answer is the same without a branch per load.
        var deepest = depth;
        for (var b = -1; b <= 1; b++) {
            for (var a = -1; a <= 1; a++) {
                deepest = max(deepest, map_depth_at(clamp(p + vec2<i32>(a, b), vec2<i32>(0), vec2<i32>(i32(res) - 1))));
            }
        }
        if deepest > depth * (1.0 + params.silhouette_relative) {
            record = packed(here.xyz, SEED_KEY);
            mark_tile(p);
            atomicAdd(&counters[0], 1u);
        }
    }
    dst[id.y * res + id.x] = record;
}
