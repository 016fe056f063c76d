// Group 0 of every screen-space compute pass (E0, methods, composite): the frame constants,
// the eye-space G-buffer and the light-space shadow map. Declared once here so that every
// pass reads the same targets with the same bindings (`render::FrameInputs`).

#import common/frame.wgsl
#import common/light.wgsl

@group(0) @binding(0) var<uniform> frame_uniform: Frame;
// The frame constants as every function reads them: each entry point copies them here first
// (`frame = frame_uniform;`). llvmpipe (Mesa 22.3) loads a uniform float lane by lane, ~20
// instructions, and loads it again after each texture fetch, which it makes by a call (read
// in its generated code); a private copy holds only the fields a pass reads, loaded once per
// invocation and kept across the calls.
var<private> frame: Frame;
@group(0) @binding(1) var gbuf_position: texture_2d<f32>; // xyz world position, w view depth (0: background)
@group(0) @binding(2) var gbuf_normal: texture_2d<f32>;   // xyz unit geometric normal facing the eye, w 1 where covered
@group(0) @binding(3) var gbuf_albedo: texture_2d<f32>;   // rgb linear albedo
@group(0) @binding(4) var gbuf_id: texture_2d<u32>;       // object id
@group(0) @binding(5) var shadow_depth: texture_2d<f32>;  // linear depth along the light normal
@group(0) @binding(6) var shadow_id: texture_2d<u32>;     // object id seen from the light centre
@group(0) @binding(7) var<uniform> light_cells: array<LightCell, 64>; // frame.sizes.w of them (light::E0_GRID²)
@group(0) @binding(8) var gbuf_shading: texture_2d<f32>;  // xyz unit shading normal on the seen side, w 1 where covered (E0 only)

// Cell `cell`'s corners in world space, counter-clockwise seen from the lit side: bottom-left,
// bottom-right, top-right, top-left (`light::irradiance::light_cells`).
fn cell_corners(cell: LightCell) -> array<vec4<f32>, 4> {
    let c = frame.light_center.xyz;
    let r = frame.light_r.xyz;
    let u = frame.light_u.xyz;
    let left = c + cell.rect.x * r;
    let right = c + cell.rect.y * r;
    let bottom = cell.rect.z * u;
    let top = cell.rect.w * u;
    return array<vec4<f32>, 4>(vec4<f32>(left + bottom, 1.0), vec4<f32>(right + bottom, 1.0), vec4<f32>(right + top, 1.0), vec4<f32>(left + top, 1.0));
}

// Cell `cell`'s edge vectors, corner i to corner i + 1 of `cell_corners`: its width along r,
// its height along u, then both back — from its rectangle, exact to a rounding of the
// lengths, rather than as differences of corners metres from the origin (each edge term is
// made along its edge: `edge_along` in common/light.wgsl).
fn cell_edges(cell: LightCell) -> array<vec3<f32>, 4> {
    let across = (cell.rect.y - cell.rect.x) * frame.light_r.xyz;
    let up = (cell.rect.w - cell.rect.z) * frame.light_u.xyz;
    return array<vec3<f32>, 4>(across, up, -across, -up);
}

// Distance from the light's centre to its rectangle's edge along unit direction `e` (light
// coordinates: x along r, y along u).
fn light_reach(e: vec2<f32>) -> f32 {
    let half = 0.5 * vec2<f32>(frame.light_n.w, frame.light_u.w);
    return min(half.x / max(abs(e.x), 1e-9), half.y / max(abs(e.y), 1e-9));
}

// Where the ray from receiver p through point o (between p and the light plane) meets the
// light plane, in light coordinates (c at the origin); z = 1 when it does, 0 when o does not
// lie strictly between p and the plane.
fn light_plane_hit(p: vec3<f32>, o: vec3<f32>) -> vec3<f32> {
    let c = frame.light_center.xyz;
    let n = frame.light_n.xyz;
    let height_p = dot(p - c, n);
    let height_o = dot(o - p, n); // negative when o lies between p and the light plane
    if height_p <= 0.0 || height_o >= -1e-5 * height_p || -height_o >= height_p {
        return vec3<f32>(0.0);
    }
    let q = p + (o - p) * (height_p / -height_o) - c;
    return vec3<f32>(dot(q, frame.light_r.xyz), dot(q, frame.light_u.xyz), 1.0);
}

// True where the G-buffer holds a surface (not background) and the pixel is on screen.
fn covered(pixel: vec2<u32>) -> bool {
    return all(pixel < frame.sizes.xy) && covers(textureLoad(gbuf_normal, pixel, 0));
}

// `covered` for a pixel on screen whose normal texel the caller has read already (w: the
// G-buffer's coverage), so that a pass needing the normal too reads the texel once.
fn covers(normal: vec4<f32>) -> bool {
    return normal.w > 0.5;
}

// The element of a screen-space image (E0, visibility, colour: `render::targets`, storage
// buffers rather than storage textures) that holds pixel (x, y): rows from the top.
fn pixel_index(pixel: vec2<u32>) -> u32 {
    return pixel.y * frame.sizes.x + pixel.x;
}
