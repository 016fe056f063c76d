// Methods `jfa-l` / `jfa-e` (Rong & Tan 2006): the flooded record, the per-round parameters,
// and the intensity of a receiver for an occluder point through the look-up texture (§3).
// See `src/methods/jfa.rs`.

#import common/frame_inputs.wgsl
#import common/shadow.wgsl

struct JfaParams {
    step: i32,                // this round's step length: 2^(k−1) … 1 (jump) or 1 (standard)
    silhouette_relative: f32, // jfa-l: a neighbour deeper by more than depth × this marks a silhouette
    bias_texels: f32,
    slope_bias_texels: f32,
    boundary_relative: f32,   // jfa-e: a lit neighbour within view depth × this makes a boundary pixel
    same_object: u32,         // jfa-e §5.2 remedy 1: flood only to pixels of the boundary's object
    midpoint: u32,            // jfa-e §5.2 remedy 2: the midpoint must already be in a penumbra
    _pad: u32,
}

// What flooding carries (§4.1, §5.1): an occluder point, the intensity it gives the holder,
// and (jfa-e) where it came from.
struct Record {
    occluder: vec4<f32>,  // xyz world position of a silhouette point, w 1 when set
    intensity: vec4<f32>, // rgb visible fraction of the light; w the key kept minimal
    origin: vec4<f32>,    // jfa-e: xy the boundary pixel, z its object id
}

@group(1) @binding(0) var<uniform> params: JfaParams;
@group(1) @binding(1) var lut: texture_2d<f32>;
@group(1) @binding(2) var<storage, read> src: array<Record>;
@group(1) @binding(3) var<storage, read_write> dst: array<Record>;
@group(1) @binding(4) var visibility_out: texture_storage_2d<rgba32float, write>;
@group(1) @binding(5) var<storage, read_write> counters: array<atomic<u32>, 4>;
// jfa-e: per eye pixel, bit 0 covered, bit 1 in hard shadow — computed once by the boundary
// pass so that flooding rounds read a flag instead of redoing the shadow test per neighbour.
@group(1) @binding(6) var<storage, read_write> flags: array<u32>;

const COVERED: u32 = 1u;
const HARD: u32 = 2u;

// A seed's key: larger than any intensity, so a seed never counts as penumbra itself.
const SEED_KEY: f32 = 2.0;

fn empty_record() -> Record {
    return Record(vec4<f32>(0.0), vec4<f32>(1.0, 1.0, 1.0, 3.0), vec4<f32>(0.0));
}

// The hard-shadow test of an eye pixel (the same test as method `hard`).
fn hard_shadowed(pixel: vec2<u32>) -> bool {
    let p = textureLoad(gbuf_position, pixel, 0).xyz;
    let n = textureLoad(gbuf_normal, pixel, 0).xyz;
    let ls = to_light_space(p);
    if !ls.inside {
        return false;
    }
    let blocker = textureLoad(shadow_depth, shadow_texel(ls.uv), 0).r;
    return ls.depth - depth_bias(p, n, ls.depth, params.bias_texels, params.slope_bias_texels) > blocker;
}

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// Bilinear look-up of the intensity texture at light coordinates uv ∈ [0,1]² (row 0 = +u).
fn lut_sample(uv: vec2<f32>) -> vec3<f32> {
    let size = vec2<f32>(textureDimensions(lut));
    let x = clamp(uv * size - 0.5, vec2<f32>(0.0), size - 1.0);
    let i = vec2<i32>(floor(x));
    let f = x - floor(x);
    let j = min(i + 1, vec2<i32>(size) - 1);
    let a = mix(textureLoad(lut, i, 0).rgb, textureLoad(lut, vec2<i32>(j.x, i.y), 0).rgb, f.x);
    let b = mix(textureLoad(lut, vec2<i32>(i.x, j.y), 0).rgb, textureLoad(lut, j, 0).rgb, f.x);
    return mix(a, b, f.y);
}

// §3: shoot a ray from receiver p through occluder point o to the light plane. If it meets
// the light at q, the visible part is the light on the centre's side of the line through q
// orthogonal to c→q (for a receiver outside hard shadow), or the other side (inside). Returns
// rgb intensity and w = 1 when the ray meets the light (p is in a penumbra), else w = 0.
fn intensity(p: vec3<f32>, o: vec3<f32>, inside: bool) -> vec4<f32> {
    let c = frame.light_center.xyz;
    let n = frame.light_n.xyz;
    let height_p = dot(p - c, n);
    let height_o = dot(o - p, n); // negative when o lies between p and the light plane
    if height_p <= 0.0 || height_o >= -1e-5 * height_p || -height_o >= height_p {
        return vec4<f32>(0.0);
    }
    let q = p + (o - p) * (height_p / -height_o);
    let x = dot(q - c, frame.light_r.xyz);
    let y = dot(q - c, frame.light_u.xyz);
    let w = frame.light_n.w;
    let h = frame.light_u.w;
    if abs(x) > 0.5 * w || abs(y) > 0.5 * h {
        return vec4<f32>(0.0);
    }
    let f = lut_sample(vec2<f32>(x / w + 0.5, 0.5 - y / h));
    return vec4<f32>(select(f, 1.0 - f, inside), 1.0);
}
