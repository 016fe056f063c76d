// Method `wedges`: the LI buffer as visibility. The buffer holds what the volumes and wedges
// took away from full light (it starts cleared: 0 = full light), so V = 1 + LI / full,
// clamped to [0, 1] — overlapping volumes can take it past either end, as in the paper (§2) —
// per channel for a coloured light.

#import methods/wedges/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    let at = (pixel.y * frame.sizes.x + pixel.x) * params.channels;
    var v = vec3<f32>(0.0);
    for (var k = 0u; k < 3u; k++) {
        let c = min(k, params.channels - 1u); // a uniform light's one value serves all three
        v[k] = clamp(1.0 + f32(atomicLoad(&li[at + c])) / f32(params.full), 0.0, 1.0);
    }
    visibility_out[pixel_index(pixel)] = vec4<f32>(v, 1.0);
}
