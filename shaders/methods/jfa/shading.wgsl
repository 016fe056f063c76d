// Methods `jfa-l`, `jfa-e`, final passes: the pixels shaded by the occluder the flood left
// them, listed by `main` below (each final pass classifies a pixel: its `final_class`) and
// shaded by the final pass's `shade_listed`, an indirect
// dispatch of their own: lavapipe runs a branch's code — the intensity, and for `jfa-l` a 5×5
// silhouette window — for all 8 lanes of a SIMD group if one lane takes it, and these pixels
// are a few percent of a frame.

#import methods/jfa/common.wgsl
#import common/pixel_list.wgsl

// The pixels to shade: list index << 1 | 1 where the pixel is in hard shadow.
@group(1) @binding(10) var<storage, read_write> shaded: PixelList;
@group(1) @binding(11) var<storage, read_write> shaded_groups: array<u32, 3>; // indirect dispatch

// Pixels per invocation of the final passes' `main`: a run of a row, listed with one atomic
// append for the run. An append per pixel is an atomic per lane on lavapipe, both cores'
// threads contending for one counter (`jfa-l`'s list holds every hard-shadowed pixel its
// flood reached).
const ROW_PIXELS: u32 = 8u;

// Lists the pixels first + (k, 0) of a run for shading, k the bits set in `listing`, each in
// hard shadow where bit k of `hard` is set.
fn list_run_for_shading(first: vec2<u32>, listing: u32, hard: u32) {
    if listing == 0u {
        return;
    }
    var at = atomicAdd(&shaded.count, countOneBits(listing));
    var rest = listing;
    while rest != 0u {
        let k = next_in_run(&rest);
        shaded.pixels[at] = pixel_index(first + vec2<u32>(k, 0u)) << 1u | ((hard >> k) & 1u);
        at++;
    }
}

// The size of `shade_listed`'s dispatch.
@compute @workgroup_size(1)
fn shaded_size() {
    frame = frame_uniform;
    params = params_uniform;
    shaded_groups = list_dispatch(atomicLoad(&shaded.count));
}

// What a final pass decides for one pixel (its `final_class`, which the importer defines):
// listed to be shaded by its occluder (in hard shadow or not), or its visibility at once.
struct FinalClass {
    listed: bool,
    hard: bool,
    visibility: vec3<f32>,
}

// Every pixel, a run of `ROW_PIXELS` of a row per invocation: its visibility stored, or the
// pixel listed for `shade_listed`.
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let first = vec2<u32>(id.x * ROW_PIXELS, id.y);
    if any(first >= frame.sizes.xy) {
        return;
    }
    // Bit k: pixel first + (k, 0) is listed (in `listing`), in hard shadow (in `hard`).
    var listing = 0u;
    var hard = 0u;
    for (var k = 0u; k < ROW_PIXELS; k++) {
        let pixel = first + vec2<u32>(k, 0u);
        if pixel.x >= frame.sizes.x {
            break;
        }
        let decided = final_class(pixel);
        if decided.listed {
            listing |= 1u << k;
            hard |= u32(decided.hard) << k;
        } else {
            visibility_out[pixel_index(pixel)] = vec4<f32>(decided.visibility, 1.0);
        }
    }
    list_run_for_shading(first, listing, hard);
}

// A listed pixel (xy) and whether it is in hard shadow (z), for lane `lane` of workgroup
// `group` of `shade_listed`; z = 2 past the list's end.
fn listed_for_shading(group: vec3<u32>, lane: u32) -> vec3<u32> {
    let i = list_position(group, lane);
    if i >= atomicLoad(&shaded.count) {
        return vec3<u32>(0u, 0u, 2u);
    }
    let entry = shaded.pixels[i];
    return vec3<u32>(listed_pixel(entry >> 1u), entry & 1u);
}

// A shaded pixel's visibility: the intensity where the ray through its occluder meets the
// light, else 0 in hard shadow and 1 outside.
fn store_shaded(pixel: vec2<u32>, hard: bool, intensity: vec4<f32>) {
    var v = select(vec3<f32>(1.0), vec3<f32>(0.0), hard);
    if intensity.w > 0.0 {
        v = intensity.rgb;
        atomicAdd(&counters[1], 1u);
    }
    visibility_out[pixel_index(pixel)] = vec4<f32>(v, 1.0);
}
