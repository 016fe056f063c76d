// Method `hard`: one shadow-map test from the light centre, binary visibility. The baseline
// every soft method is compared with (classic shadow mapping, Williams 1978).

#import common/frame_inputs.wgsl
#import common/shadow.wgsl

struct HardParams {
    bias_texels: f32,
    slope_bias_texels: f32,
}

@group(1) @binding(0) var<storage, read_write> visibility_out: array<vec4<f32>>;
@group(1) @binding(1) var<uniform> params_uniform: HardParams;
// Read through a private copy, as `frame` is (`common/frame_inputs.wgsl`).
var<private> params: HardParams;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var v = 1.0;
    // The normal texel once, for the coverage and the bias's normal (`covers`).
    let normal = textureLoad(gbuf_normal, pixel, 0);
    if covers(normal) {
        let p = textureLoad(gbuf_position, pixel, 0).xyz;
        let n = normal.xyz;
        let ls = to_light_space(p);
        if ls.inside {
            let blocker = textureLoad(shadow_depth, shadow_texel(ls.uv), 0).r;
            let bias = depth_bias(p, n, ls.depth, params.bias_texels, params.slope_bias_texels);
            v = select(0.0, 1.0, ls.depth - bias <= blocker);
        }
    }
    visibility_out[pixel_index(pixel)] = vec4<f32>(v, v, v, 1.0);
}
