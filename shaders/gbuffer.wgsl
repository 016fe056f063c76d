// Eye-space G-buffer: world position and view depth, the geometric normal turned towards the
// eye (every triangle receives light on the side we see), linear albedo, the shading normal on
// that same side, object id.
//
// Two normals, because a mesh's vertex normals need not be its surface's: an exporter smooths
// a cube's eight corners, a low-poly sphere's facets bend away from their normals. E0's cosine
// takes the shading normal (contract §1: the surface as authored); whatever asks where the
// surface really is — a shadow map's bias, a receiver's plane, whether the light lies in front
// of it — takes the plane of the triangle seen, or it shadows itself where the two disagree.

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
    @location(3) shading: vec4<f32>,
    @location(4) object_id: u32,
}

// The G-buffer of a fragment whose linear albedo is `albedo` and whose world position changes
// by `dx` and `dy` from one pixel to the next: both lie in the triangle's plane (the quad's
// helper lanes extend the same triangle), so their cross product is its normal, whatever the
// winding. Seen edge-on they are parallel; the shading normal stands in there.
fn gbuffer(in: VsOut, albedo: vec4<f32>, dx: vec3<f32>, dy: vec3<f32>) -> GBuffer {
    let to_eye = frame.eye.xyz - in.world;
    var n = normalize(in.normal);
    let across = cross(dx, dy);
    var g = select(n, normalize(across), dot(across, across) > 1e-30);
    if dot(g, to_eye) < 0.0 {
        g = -g;
    }
    // The shading normal on the side seen: glTF flips it with the face (a double-sided
    // material's back); judged against the plane, not the eye, so that a vertex normal bent
    // past the silhouette stays as authored.
    if dot(n, g) < 0.0 {
        n = -n;
    }
    var out: GBuffer;
    out.position = vec4<f32>(in.world, dot(-to_eye, frame.view_dir.xyz));
    out.normal = vec4<f32>(g, 1.0);
    out.albedo = vec4<f32>(albedo.rgb, 1.0);
    out.shading = vec4<f32>(n, 1.0);
    out.object_id = in.object_id;
    return out;
}

// A material with a base-colour texture.
@fragment
fn fs_main(in: VsOut) -> GBuffer {
    let albedo = in.base_color * textureSample(base_color_texture, base_color_sampler, in.uv);
    return gbuffer(in, albedo, dpdx(in.world), dpdy(in.world));
}

// A material without one: its colour alone. The same value `fs_main` gives with the 1×1
// white texture bound in its place (every sample exactly 1), without the sample — on
// lavapipe a fifth of the pass on a 100k-triangle landscape.
@fragment
fn fs_untextured(in: VsOut) -> GBuffer {
    return gbuffer(in, in.base_color, dpdx(in.world), dpdy(in.world));
}
