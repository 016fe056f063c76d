// Method `brabec`, last pass: visibility from the penumbra coordinate t, through the chosen
// fall-off — linear (the paper) or the sinusoid its §6 suggests for straight edges.

#import methods/brabec/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var t = state[state_index(pixel)].t;
    if t < 0.0 {
        t = search(pixel); // not reached by the lattice or the interpolation passes
    }
    var v = clamp(t, 0.0, 1.0);
    if params.falloff == 1u {
        v = 0.5 - 0.5 * cos(3.14159265 * v);
    }
    textureStore(visibility_out, pixel, vec4<f32>(v, v, v, 1.0));
}
