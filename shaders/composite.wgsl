// Composite: Lo = ρ/π · (E0 ⊙ V + ambient) per pixel (contract §1), alpha 1 where a surface
// was hit, and the view depth (+∞ for background) for the EXR `depth` channel — or, for a
// PNG alone, its 8-bit sRGB pixels directly.

#import common/frame_inputs.wgsl

@group(1) @binding(0) var<storage, read> e0_in: array<vec4<f32>>;
@group(1) @binding(1) var<storage, read> visibility_in: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read_write> color_out: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> depth_out: array<f32>;
@group(1) @binding(4) var<storage, read_write> srgb8_out: array<u32>; // RGBA8, row-major

const INV_PI: f32 = 0.31830988618;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    let albedo = textureLoad(gbuf_albedo, pixel, 0);
    if albedo.a <= 0.5 {
        color_out[pixel_index(pixel)] = vec4<f32>(0.0);
        depth_out[pixel_index(pixel)] = bitcast<f32>(0x7f800000u);
        return;
    }
    color_out[pixel_index(pixel)] = vec4<f32>(radiance(pixel, albedo.rgb), 1.0);
    depth_out[pixel_index(pixel)] = textureLoad(gbuf_position, pixel, 0).w;
}

// The G-buffer's albedo is cleared to 0 and drawn with alpha 1, so its alpha is the pixel's
// coverage (what `covered` reads from the normal): one texture fetch per pixel fewer.
fn radiance(pixel: vec2<u32>, albedo: vec3<f32>) -> vec3<f32> {
    let e0 = e0_in[pixel_index(pixel)].rgb;
    let v = visibility_in[pixel_index(pixel)].rgb;
    return albedo * INV_PI * (e0 * v + frame.ambient.rgb);
}

// The sRGB transfer function (IEC 61966-2-1), the GPU twin of `color::linear_to_srgb`.
fn linear_to_srgb(c: vec3<f32>) -> vec3<f32> {
    let x = clamp(c, vec3<f32>(0.0), vec3<f32>(1.0));
    return select(1.055 * pow(x, vec3<f32>(1.0 / 2.4)) - 0.055, x * 12.92, x <= vec3<f32>(0.0031308));
}

// The PNG's pixels: radiance × 2^exposure (frame.ambient.w), sRGB-encoded, alpha = coverage;
// what `output::encode` would make from the linear colour, without reading that back.
@compute @workgroup_size(8, 8)
fn srgb8(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var rgba = vec4<f32>(0.0);
    let albedo = textureLoad(gbuf_albedo, pixel, 0);
    if albedo.a > 0.5 {
        rgba = vec4<f32>(linear_to_srgb(radiance(pixel, albedo.rgb) * frame.ambient.w), 1.0);
    }
    srgb8_out[pixel.y * frame.sizes.x + pixel.x] = pack4x8unorm(rgba);
}
