// Method `brabec`, last pass: visibility from the penumbra coordinate t, through the chosen
// fall-off — linear (the paper) or the sinusoid its §6 suggests for straight edges — coloured
// by the direction of what the search found (`colored_visibility`).

#import methods/brabec/common.wgsl
#import methods/brabec/colour.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    let i = state_index(pixel);
    // The lattice, the search and the interpolation give every pixel its t; one without is
    // counted (the renderer logs it) and shown lit.
    if state[i].t < 0.0 {
        atomicAdd(&counters.unresolved, 1u);
        state[i].t = 1.0;
    }
    let t = state[i].t;
    var v = clamp(t, 0.0, 1.0);
    if params.falloff == 1u {
        v = 0.5 - 0.5 * cos(3.14159265 * v);
    }
    visibility_out[pixel_index(pixel)] = vec4<f32>(colored_visibility(v, t, state[i].normal, state[i].edge), 1.0);
}
