// Per-frame constants shared by every pass: the eye camera, the area light's frame
// (contract §1) and the light-space projection of the shadow map. Mirrors
// `render::FrameUniforms` field for field.

struct Frame {
    view_proj: mat4x4<f32>,
    light_view_proj: mat4x4<f32>,
    eye: vec4<f32>,          // xyz: eye position
    view_dir: vec4<f32>,     // xyz: unit camera forward (view depth = dot(p - eye, view_dir))
    light_center: vec4<f32>, // xyz: light centre, w: intensity
    light_n: vec4<f32>,      // xyz: unit normal of the emitting side, w: width (along r) in m
    light_u: vec4<f32>,      // xyz: unit image-up, w: height (along u) in m
    light_r: vec4<f32>,      // xyz: unit image-right = cross(u, n)
    light_proj: vec4<f32>,   // x: tan of the shadow frustum's half angle, y: unused, z: near, w: far
    ambient: vec4<f32>,      // rgb: ambient irradiance asked for by the job; w: 2^exposure (PNG)
    sizes: vec4<u32>,        // x, y: output size; z: shadow-map resolution; w: light cell count
    cells_bounds: vec4<f32>, // rectangle bounding the light's cells: xy centre (along r, u from the light's), zw half sizes, m
}
