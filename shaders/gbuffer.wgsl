// Eye-space G-buffer: world position and view depth, the normal turned towards the eye
// (every triangle receives light on the side we see), linear albedo, object id.

#import common/frame.wgsl

struct Material {
    base_color: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> materials: array<Material>;
@group(1) @binding(0) var base_color_texture: texture_2d<f32>;
@group(1) @binding(1) var base_color_sampler: sampler;

struct VsIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) object_id: u32,
    @location(4) material: u32,
}

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) @interpolate(flat) object_id: u32,
    // The material's base colour, loaded once per vertex rather than once per fragment: a
    // storage-buffer load per fragment was a tenth of the pass on lavapipe (flat, so every
    // fragment gets the provoking vertex's value, the one `material` named before).
    @location(4) @interpolate(flat) base_color: vec4<f32>,
}

@vertex
fn vs_main(in: VsIn) -> VsOut {
    var out: VsOut;
    out.clip = frame.view_proj * vec4<f32>(in.position, 1.0);
    out.world = in.position;
    out.normal = in.normal;
    out.uv = in.uv;
    out.object_id = in.object_id;
    out.base_color = materials[in.material].base_color;
    return out;
}

struct GBuffer {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) albedo: vec4<f32>,
    @location(3) object_id: u32,
}

// The G-buffer of a fragment whose linear albedo is `albedo`.
fn gbuffer(in: VsOut, albedo: vec4<f32>) -> GBuffer {
    var n = normalize(in.normal);
    if dot(n, frame.eye.xyz - in.world) < 0.0 {
        n = -n;
    }
    var out: GBuffer;
    out.position = vec4<f32>(in.world, dot(in.world - frame.eye.xyz, frame.view_dir.xyz));
    out.normal = vec4<f32>(n, 1.0);
    out.albedo = vec4<f32>(albedo.rgb, 1.0);
    out.object_id = in.object_id;
    return out;
}

// A material with a base-colour texture.
@fragment
fn fs_main(in: VsOut) -> GBuffer {
    return gbuffer(in, in.base_color * textureSample(base_color_texture, base_color_sampler, in.uv));
}

// A material without one: its colour alone. The same value `fs_main` gives with the 1×1
// white texture bound in its place (every sample exactly 1), without the sample — on
// lavapipe a fifth of the pass on a 100k-triangle landscape.
@fragment
fn fs_untextured(in: VsOut) -> GBuffer {
    return gbuffer(in, in.base_color);
}
