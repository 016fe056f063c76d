// Method `jfa-l`, §4.1 "Locating Occluders": a shadow-map texel is a silhouette pixel when one
// of its 8 neighbours is deeper by more than a threshold (or empty); silhouette pixels seed
// the flood with their own light-space (world) position. Only the seeds are stored, over
// records a buffer fill has emptied (`methods::jfa`): on lavapipe a store runs lane by lane,
// and storing an empty record for every other texel of the map costs more than the fill.

#import methods/jfa/common.wgsl

// Texels per invocation, side by side along a row: neighbouring texels share most of their
// neighbours, so four of them load 3 × 6 depths instead of 4 × 9 (on lavapipe a storage
// load is a gather, lane by lane, and the loads were most of this pass).
const ROW_TEXELS: i32 = 4;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let res = i32(frame.sizes.z);
    let first = vec2<i32>(i32(id.x) * ROW_TEXELS, i32(id.y));
    if any(first >= vec2<i32>(res)) {
        return;
    }
    // The deepest of each texel's 3 × 3 neighbourhood, itself included. A neighbour past the
    // map's edge is clamped onto it: onto the texel itself (never deeper) or another of its
    // neighbours, so the answer is the same without a branch per load. Column j of the window
    // is texel first.x − 1 + j; texel k sees columns k … k + 2.
    var deepest = vec4<f32>(-3.4e38);
    var depth = vec4<f32>(0.0);
    for (var b = -1; b <= 1; b++) {
        let y = clamp(first.y + b, 0, res - 1);
        var c: array<f32, 6>;
        for (var j = 0; j < 6; j++) {
            c[j] = map_depth_at(vec2<i32>(clamp(first.x - 1 + j, 0, res - 1), y));
        }
        let row = max(max(vec4<f32>(c[0], c[1], c[2], c[3]), vec4<f32>(c[1], c[2], c[3], c[4])), vec4<f32>(c[2], c[3], c[4], c[5]));
        deepest = max(deepest, row);
        if b == 0 {
            depth = vec4<f32>(c[1], c[2], c[3], c[4]);
        }
    }
    for (var k = 0; k < ROW_TEXELS; k++) {
        let p = first + vec2<i32>(k, 0);
        if p.x >= res {
            break;
        }
        let here = shadow_point_at(p, depth[k]);
        if here.w > 0.0 && deepest[k] > depth[k] * (1.0 + params.silhouette_relative) {
            dst[u32(p.y * res + p.x)] = packed(here.xyz, SEED_KEY);
            mark_tile(p);
            atomicAdd(&counters[0], 1u);
        }
    }
}
