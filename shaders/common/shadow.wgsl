// Light-space lookups shared by the shadow methods: where a world point falls in the shadow
// map, its linear depth from the light, and the depth bias that keeps lit surfaces from
// shadowing themselves. Needs `frame` (common/frame_inputs.wgsl).

struct LightSpace {
    uv: vec2<f32>,   // [0,1]² in the shadow map, v down (texel row 0 at the top)
    depth: f32,      // distance from the light plane along n, in metres
    inside: bool,    // in front of the light and inside the shadow frustum
}

fn to_light_space(p: vec3<f32>) -> LightSpace {
    var out: LightSpace;
    let clip = frame.light_view_proj * vec4<f32>(p, 1.0);
    out.depth = dot(p - frame.light_center.xyz, frame.light_n.xyz);
    let ndc = clip.xy / clip.w;
    out.uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    out.inside = clip.w > 0.0 && out.depth > frame.light_proj.z && all(out.uv >= vec2<f32>(0.0)) && all(out.uv < vec2<f32>(1.0));
    return out;
}

// World-space size of one shadow-map texel at linear depth `depth`.
fn texel_size_m(depth: f32) -> f32 {
    return 2.0 * depth * frame.light_proj.x / f32(frame.sizes.z);
}

// Constant plus slope-scaled bias, both in texels: a surface tilted by θ from the light
// direction spans tanθ texel-depths across one texel, so that much must be forgiven.
fn depth_bias(p: vec3<f32>, n: vec3<f32>, depth: f32, constant_texels: f32, slope_texels: f32) -> f32 {
    let to_light = normalize(frame.light_center.xyz - p);
    let cos_theta = clamp(abs(dot(n, to_light)), 0.05, 1.0);
    let tan_theta = min(sqrt(1.0 - cos_theta * cos_theta) / cos_theta, 10.0);
    return texel_size_m(depth) * (constant_texels + slope_texels * tan_theta);
}

// The surface point the shadow map holds at texel t (xyz, world), w 1 where it holds one. The
// map stores the linear depth along the light normal, and the rasteriser sampled it at the
// texel's centre, on that texel's ray from the light centre (the inverse of `to_light_space`:
// the frustum looks along n with up u, so its right is −r), so the point is the ray at that
// depth: the world position to rounding, for a quarter of the bytes a stored position
// would cost the shadow pass.
fn shadow_point(t: vec2<i32>) -> vec4<f32> {
    return shadow_point_at(t, textureLoad(shadow_depth, t, 0).r);
}

// `shadow_point` where texel t's depth is at hand (`jfa-*` read their copy of the map).
fn shadow_point_at(t: vec2<i32>, depth: f32) -> vec4<f32> {
    let uv = (vec2<f32>(t) + 0.5) / f32(frame.sizes.z);
    let ndc = vec2<f32>(2.0 * uv.x - 1.0, 1.0 - 2.0 * uv.y) * frame.light_proj.x;
    let ray = frame.light_n.xyz - ndc.x * frame.light_r.xyz + ndc.y * frame.light_u.xyz;
    // The map is cleared to f32::MAX where nothing was drawn.
    let covered = depth < EMPTY_DEPTH;
    return vec4<f32>(frame.light_center.xyz + ray * select(0.0, depth, covered), select(0.0, 1.0, covered));
}

// Depths at or beyond this are texels the shadow pass drew nothing into (cleared to f32::MAX).
const EMPTY_DEPTH: f32 = 1e38;

fn shadow_texel(uv: vec2<f32>) -> vec2<i32> {
    return vec2<i32>(shadow_texel_axis(uv.x), shadow_texel_axis(uv.y));
}

// One coordinate of `shadow_texel`, for loops that walk the map's rows and columns apart.
fn shadow_texel_axis(x: f32) -> i32 {
    let res = i32(frame.sizes.z);
    return clamp(i32(floor(x * f32(res))), 0, res - 1);
}

// The direction, in light coordinates, in which the silhouette next to occluder point o
// faces away from its occluder: from the shadow-map texels within `radius` of o's, those
// deeper than o (by more than `relative` of its depth, or empty) against those that are not,
// mapped from the map's axes to the light's. (0, 0) where they show no silhouette.
fn silhouette_normal(o: vec3<f32>, radius: i32, relative: f32) -> vec2<f32> {
    let ls = to_light_space(o);
    let res = i32(frame.sizes.z);
    let centre = shadow_texel(ls.uv);
    let limit = ls.depth * (1.0 + max(relative, 1e-3));
    var beyond = vec2<f32>(0.0);
    for (var b = -radius; b <= radius; b++) {
        for (var a = -radius; a <= radius; a++) {
            let t = centre + vec2<i32>(a, b);
            if (a == 0 && b == 0) || any(t < vec2<i32>(0)) || any(t >= vec2<i32>(res)) {
                continue;
            }
            // An empty texel holds f32::MAX: deeper than any limit.
            let deeper = textureLoad(shadow_depth, t, 0).r > limit;
            let offset = normalize(vec2<f32>(f32(a), f32(b)));
            beyond += select(-offset, offset, deeper);
        }
    }
    if dot(beyond, beyond) < 1e-6 {
        return vec2<f32>(0.0);
    }
    // Texel offsets to light coordinates: how the map's uv moves along r and along u at o.
    let step = texel_size_m(ls.depth);
    let du = (to_light_space(o + frame.light_r.xyz * step).uv - ls.uv) * f32(res);
    let dv = (to_light_space(o + frame.light_u.xyz * step).uv - ls.uv) * f32(res);
    // A normal maps through the transpose of the map (r, u) → texels.
    return normalize(vec2<f32>(dot(du, beyond), dot(dv, beyond)));
}
