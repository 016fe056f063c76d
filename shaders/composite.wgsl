// Composite: Lo = ρ/π · (E0 ⊙ V + ambient) per pixel (contract §1), alpha 1 where a surface
// was hit, and the view depth (+∞ for background) for the EXR `depth` channel.

#import common/frame_inputs.wgsl

@group(1) @binding(0) var e0_in: texture_2d<f32>;
@group(1) @binding(1) var visibility_in: texture_2d<f32>;
@group(1) @binding(2) var color_out: texture_storage_2d<rgba32float, write>;
@group(1) @binding(3) var depth_out: texture_storage_2d<r32float, write>;

const INV_PI: f32 = 0.31830988618;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    if !covered(pixel) {
        textureStore(color_out, pixel, vec4<f32>(0.0));
        textureStore(depth_out, pixel, vec4<f32>(bitcast<f32>(0x7f800000u)));
        return;
    }
    let albedo = textureLoad(gbuf_albedo, pixel, 0).rgb;
    let e0 = textureLoad(e0_in, pixel, 0).rgb;
    let v = textureLoad(visibility_in, pixel, 0).rgb;
    let radiance = albedo * INV_PI * (e0 * v + frame.ambient.rgb);
    textureStore(color_out, pixel, vec4<f32>(radiance, 1.0));
    textureStore(depth_out, pixel, vec4<f32>(textureLoad(gbuf_position, pixel, 0).w));
}
