// Method `reference`, per batch of light samples: adds the batch's contributions to the two
// sums of the ratio estimator, per pixel: Σ L·G·V (shadowed) and Σ L·G (unshadowed), with
// G = cosθx·cosθy/|x−y|² and V from each sample's depth map (contract §1); the last batch
// writes their ratio, the visibility, instead (`LAST`). Method `filtered`'s GPU engine tests
// the same way with its own entry point (`filtered_main`), which keeps the halves' sums and
// the blockers met for the CPU's filter.
//
// Why it is written this way (each measured on lavapipe at 1080p): a pass per sample paid for
// the G-buffer reads and the sums' update every sample, so a batch reads and updates each
// pixel once; a branch no lane takes still runs its code, so the number of samples is a
// pipeline constant (`SAMPLES`) and the unused slots compile away instead of being skipped by
// a test; a loop over the samples ran slower than the samples spelled out one by one (constant
// indices). llvmpipe (Mesa 22.3) loads every float of a uniform lane by lane, ~20 instructions
// each whatever its index, and fetches a texel by a call, after which it loads every uniform
// again (read in its generated code with perf and gdb): so a sample carries as few floats as
// it can — its point, its weight and its map's scale (4 with one channel, 6 with three), its
// crop's origin (both texels in one word) only where the maps are cropped (`CROPPED`) — and
// what the batch shares (one near plane for every map, the map's size) is loaded once per
// pixel into `Receiver`. Every sample's
// frustum looks along the light normal with the image's up, so they share one rotation: the
// pixel is rotated into it once per batch and each sample costs a subtraction, not a matrix.
// The batches run only over row segments that hold a receiver (`list_segments`): the sky
// would cost as much as the ground.
// And every sample lies on the light's plane, so a pixel's depth along the normal is the same
// from each: its reciprocal, square and bias are taken once per pixel too.

#import common/frame_inputs.wgsl
#import common/pixel_list.wgsl

// The most samples a batch holds; mirrors `methods::reference::BATCH_SAMPLES`.
const MAX_SAMPLES: u32 = 32u;
// The samples in this pipeline's batches: one pipeline per batch size.
override SAMPLES: u32 = MAX_SAMPLES;
// Channels of the sums: 1 where every sample's weight is gray (a uniform or shaped white
// light: its channels' sums would be equal), else 3. Fewer bytes per pixel to read and write
// each batch, and a third of the additions.
override CHANNELS: u32 = 3u;
// The first batch writes the sums instead of adding to them (nothing to clear or read).
override FIRST: bool = false;
// The last batch writes the visibility instead of the sums: on lavapipe each float a pixel
// stores costs about as much as a sample's test, so the sums are stored once fewer and
// never read back by a pass of their own.
override LAST: bool = false;
// Whether the maps are crops (`BatchSample::origin.z`); whole maps begin at texel 0.
override CROPPED: bool = true;
// `filtered_main` only: the blockers each test meets are counted and their depths summed
// (what sizes `filtered`'s filter), and the half of the samples this batch holds (0: the
// even ones, 1: the odd ones; `samples::half_of_index`), whose sums it adds to.
override BLOCKERS: bool = false;
override HALF: u32 = 0u;

struct BatchSample {
    origin: vec4<f32>,   // xy: the sample point y in view coordinates (rotation · y; its z is `Batch::plane`); z: the whole-map texel where its layer's crop begins, x | y << 16 (one float fewer to load); w: unused
    radiance: vec4<f32>, // rgb: L(y) × stratum area, the sample's weight in the estimator; w: its map's texels per unit of tan from the centre (resolution / (2·tan of its half angle))
}

struct Batch {
    // Rows of the rotation into view coordinates (x right, y up, z away from the light normal).
    rotation: array<vec4<f32>, 3>,
    resolution: u32,         // texels per side of a whole map
    bias_texels: f32,        // constant bias of the visibility test, texels
    slope_bias_texels: f32,  // slope-scaled bias, texels × tanθ at the receiver
    plane: f32,              // the light's plane in view coordinates: z of every sample point
    near: f32,               // every map's near plane, metres
    pad0: u32,
    pad1: u32,
    pad2: u32,
    samples: array<BatchSample, MAX_SAMPLES>, // sample k has layer k of `depths`
}

@group(1) @binding(0) var<uniform> batch: Batch;
// The batch's depth maps, a layer each: near / (view depth of the nearest surface), 0 where
// the map holds nothing. A layer holds the crop of its map where the frame's receivers fall.
// Read where they were drawn: a texel fetch costs more than a buffer load on lavapipe, but
// less than copying every map into a buffer.
@group(1) @binding(1) var depths: texture_depth_2d_array;
// Per covered pixel, 2·CHANNELS floats: Σ L·G·V, then Σ L·G (what the batches so far added).
@group(1) @binding(2) var<storage, read_write> sums: array<f32>;
// The method's output, written by the last batch.
@group(1) @binding(3) var<storage, read_write> visibility_out: array<vec4<f32>>;
// The row segments of `SEGMENT` pixels holding a covered pixel (`list_segments`), each by its
// first pixel, and the grid of the dispatch over them (`segments_size`).
@group(1) @binding(4) var<storage, read_write> segments: PixelList;
@group(1) @binding(5) var<storage, read_write> segment_groups: array<u32, 3>;
// `filtered_main`'s records, one per lane of a listed segment (list position × `SEGMENT` +
// lane), 4·CHANNELS + 2 floats each: each half's Σ L·G·V and Σ L·G per channel, then the blockers
// met (count, summed depth from the light's plane). Cleared before a round's first batch.
@group(1) @binding(6) var<storage, read_write> records: array<f32>;

// Pixels of a row per listed segment: one SIMD group of llvmpipe's (8 lanes of 32 bits on a
// 256-bit machine), the lanes that run as one whatever branches they take.
const SEGMENT: u32 = 8u;

struct Sums {
    shadowed: vec3<f32>,
    unshadowed: vec3<f32>,
    blocked: vec2<f32>, // `BLOCKERS`: blocked tests, and the blockers' summed depth
}

// What every sample's test needs of a receiver x (normal n), both in view coordinates, taken
// once per pixel: every sample lies on the light's plane, so its depth along the light normal
// is the same from each.
struct Receiver {
    xy: vec2<f32>,
    n: vec3<f32>,
    depth: f32,          // along the light normal, from the light's plane
    inv_depth: f32,
    depth2: f32,
    n_dot_z: f32,        // n·v's part along the normal, the same from every sample: n.z·(−depth)
    g_depth: f32,        // cosθy·|v| = depth, 0 behind the light's plane
    bias_depth2: f32,    // depth² × the test's bias in texels
    // The batch's own uniforms, loaded once here: llvmpipe calls a function for each texel
    // fetch, and loads a uniform read after it again, lane by lane, for every sample.
    half: f32,           // half a whole map's side, texels
    near: f32,           // every map's near plane
}

// Sample `layer`'s L·G·V and L·G at receiver `r`; `last` is the last texel of a layer.
fn add_sample(sums: ptr<function, Sums>, r: Receiver, last: vec2<f32>, layer: u32, s: BatchSample) {
    let d = r.xy - s.origin.xy; // v = x − y: this across the plane, −depth along its normal
    let inv_dist = inverseSqrt(fma(d.x, d.x, fma(d.y, d.y, r.depth2)));
    let inv_dist2 = inv_dist * inv_dist;
    // G = cosθx·cosθy/|v|² with cosθx = −n·v/|v|, cosθy = depth/|v|; 0 behind either surface.
    let g = max(-fma(r.n.x, d.x, fma(r.n.y, d.y, r.n_dot_z)), 0.0) * r.g_depth * inv_dist2 * inv_dist2;
    // The map's texel coordinates (x right, y down from its top-left corner), less its crop's
    // origin; `f` is from the map's centre, `k` its texels per unit of tan.
    let k = s.radiance.w;
    let f = d * (k * r.inv_depth);
    var t = vec2<f32>(r.half + f.x, r.half - f.y);
    if CROPPED {
        let crop = bitcast<u32>(s.origin.z);
        t -= vec2<f32>(f32(crop & 0xffffu), f32(crop >> 16u));
    }
    let stored = textureLoad(depths, vec2<u32>(clamp(t, vec2<f32>(0.0), last)), layer, 0);
    // The bias in metres at the receiver (texels of this map there × `bias`: depth·bias/k)
    // shrinks with the resolution, so the estimate converges to true visibility. Lit when the
    // receiver, brought that much nearer along its ray (its depth less bias_m·cosθy), is no
    // deeper than the nearest surface, near/stored: multiplied out (and by k) so that an
    // empty texel (0) is lit without a division. Outside the frustum nothing is recorded: lit.
    // (Behind the sample, G is 0 whatever the test says.)
    let inside = all(abs(f) < vec2<f32>(r.half));
    let lit = (r.depth * k - r.bias_depth2 * inv_dist) * stored <= r.near * k;
    let visible = !inside || lit;
    // A blocked test of a receiver that faces the sample met a blocker at depth near / stored
    // from the light's plane (the CPU engine's `BLOCKERS`).
    if BLOCKERS && inside && !lit && g > 0.0 {
        (*sums).blocked += vec2<f32>(1.0, r.near / stored);
    }
    if CHANNELS == 1u {
        (*sums).shadowed.x += s.radiance.r * select(0.0, g, visible);
        (*sums).unshadowed.x += s.radiance.r * g;
    } else {
        (*sums).shadowed += s.radiance.rgb * select(0.0, g, visible);
        (*sums).unshadowed += s.radiance.rgb * g;
    }
}

// Once per frame, before the batches, per row segment of `SEGMENT` pixels: lists the segment
// if it holds a covered pixel, else writes its pixels' visibility (lit, as the last batch
// writes an uncovered pixel's). On lavapipe an uncovered pixel's early return skips nothing —
// every sample's test still runs — so the
// batches run over the listed segments alone, and the sky costs a texel read a pixel.
@compute @workgroup_size(8, 8)
fn list_segments(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let first = vec2<u32>(id.x * SEGMENT, id.y);
    if any(first >= frame.sizes.xy) {
        return;
    }
    var any_covered = false;
    for (var k = 0u; k < SEGMENT; k++) {
        any_covered = any_covered || covered(first + vec2<u32>(k, 0u));
    }
    if any_covered {
        segments.pixels[atomicAdd(&segments.count, 1u)] = pixel_index(first);
        return;
    }
    for (var k = 0u; k < SEGMENT; k++) {
        let pixel = first + vec2<u32>(k, 0u);
        if pixel.x < frame.sizes.x {
            visibility_out[pixel_index(pixel)] = vec4<f32>(1.0);
        }
    }
}

// The grid of the batches' dispatch: `SEGMENT` lanes per listed segment.
@compute @workgroup_size(1)
fn segments_size() {
    segment_groups = list_dispatch(atomicLoad(&segments.count) * SEGMENT);
}

// Per batch, per pixel of a listed segment (`SEGMENT` lanes each, eight segments a workgroup).
@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    let at = listed_lane(group, lane);
    if !at.listed {
        return;
    }
    let pixel = at.pixel;
    if !covers(at.normal) {
        if LAST {
            visibility_out[pixel_index(pixel)] = vec4<f32>(1.0);
        }
        return;
    }
    var s = batch_sums(pixel, at.normal.xyz);
    let base = 2u * CHANNELS * (pixel.y * frame.sizes.x + pixel.x);
    if !FIRST {
        for (var c = 0u; c < CHANNELS; c++) {
            s.shadowed[c] += sums[base + c];
            s.unshadowed[c] += sums[base + CHANNELS + c];
        }
    }
    if LAST {
        visibility_out[pixel_index(pixel)] = vec4<f32>(ratio(s), 1.0);
    } else {
        for (var c = 0u; c < CHANNELS; c++) {
            sums[base + c] = s.shadowed[c];
            sums[base + CHANNELS + c] = s.unshadowed[c];
        }
    }
}

// A lane of a dispatch over the listed segments: its list position (`index`: segment ×
// `SEGMENT` + lane), its pixel, whether it is one (within the list and the frame), and the
// normal texel there, read once for the coverage and the normal (`covers`).
struct Lane {
    index: u32,
    pixel: vec2<u32>,
    listed: bool,
    normal: vec4<f32>,
}

fn listed_lane(group: vec3<u32>, lane: u32) -> Lane {
    let i = list_position(group, lane);
    if i >= atomicLoad(&segments.count) * SEGMENT {
        return Lane(i, vec2<u32>(0u), false, vec4<f32>(0.0));
    }
    let pixel = listed_pixel(segments.pixels[i / SEGMENT]) + vec2<u32>(i % SEGMENT, 0u);
    if pixel.x >= frame.sizes.x {
        return Lane(i, pixel, false, vec4<f32>(0.0));
    }
    return Lane(i, pixel, true, textureLoad(gbuf_normal, pixel, 0));
}

// The batch's L·G·V and L·G (and, with `BLOCKERS`, the blockers met) at the covered `pixel`
// of unit normal `normal`.
fn batch_sums(pixel: vec2<u32>, normal: vec3<f32>) -> Sums {
    let receiver = receiver_at(pixel, normal);
    // The last texel of a layer: each holds its map's crop (`MapCrop`), all the same size.
    let last = vec2<f32>(textureDimensions(depths)) - 1.0;
    var s = Sums(vec3<f32>(0.0), vec3<f32>(0.0), vec2<f32>(0.0));
    // Spelled out by `#unroll` (a loop over them ran slower: constant indices); a slot past
    // `SAMPLES` compiles away.
    #unroll k in 0..32 {
        if SAMPLES > k {
            add_sample(&s, receiver, last, k, batch.samples[k]);
        }
    }
    return s;
}

// What every test of the batch needs of the receiver at `pixel` (`normal`: its unit normal).
fn receiver_at(pixel: vec2<u32>, normal: vec3<f32>) -> Receiver {
    let world = textureLoad(gbuf_position, pixel, 0).xyz;
    let r = batch.rotation;
    let x = vec3<f32>(dot(r[0].xyz, world), dot(r[1].xyz, world), dot(r[2].xyz, world));
    let n = vec3<f32>(dot(r[0].xyz, normal), dot(r[1].xyz, normal), dot(r[2].xyz, normal));
    // The bias of the visibility test in texels, constant plus slope-scaled by tanθ between
    // the normal and the direction to the light's centre (the same for every sample: it
    // takes a square root and a division out of each).
    let cos_c = clamp(dot(normal, normalize(frame.light_center.xyz - world)), 0.0, 1.0);
    let tan_c = min(sqrt(1.0 - cos_c * cos_c) / max(cos_c, 0.05), 10.0);
    let bias = batch.bias_texels + batch.slope_bias_texels * tan_c;
    let depth = batch.plane - x.z;
    return Receiver(x.xy, n, depth, 1.0 / depth, depth * depth, -n.z * depth, max(depth, 0.0), depth * depth * bias, 0.5 * f32(batch.resolution), batch.near);
}

// Method `filtered`'s GPU engine (`methods/reference/filtered/gpu.rs`), per batch of one
// half's samples, per lane of a segment the CPU listed (its probes: every covered one; its
// refinement: those the probes' tiles send there): the tests of `main`, added to the lane's
// record with the blockers they met. The CPU reads the records back, classifies and filters.
@compute @workgroup_size(64)
fn filtered_main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    let at = listed_lane(group, lane);
    if !at.listed || !covers(at.normal) {
        return;
    }
    let s = batch_sums(at.pixel, at.normal.xyz);
    let i = at.index;
    // A record: the two halves' 2·CHANNELS sums, then the blockers' two floats.
    let base = i * (4u * CHANNELS + 2u);
    let half = base + 2u * CHANNELS * HALF;
    for (var c = 0u; c < CHANNELS; c++) {
        records[half + c] += s.shadowed[c];
        records[half + CHANNELS + c] += s.unshadowed[c];
    }
    records[base + 4u * CHANNELS] += s.blocked.x;
    records[base + 4u * CHANNELS + 1u] += s.blocked.y;
}

// Visibility per channel as the ratio of the two sums, V = Σ L·G·V / Σ L·G. Using the same
// samples in numerator and denominator makes fully lit points exactly 1 and umbrae exactly 0
// (a ratio estimator). A channel the light does not emit at all takes the ratio of the
// channel sums; a point no sample reaches is lit (1).
fn ratio(s: Sums) -> vec3<f32> {
    var shadowed = s.shadowed;
    var unshadowed = s.unshadowed;
    if CHANNELS == 1u {
        shadowed = vec3<f32>(shadowed.x);
        unshadowed = vec3<f32>(unshadowed.x);
    }
    let total = unshadowed.r + unshadowed.g + unshadowed.b;
    let gray = select(1.0, (shadowed.r + shadowed.g + shadowed.b) / total, total > 0.0);
    let v = select(vec3<f32>(gray), shadowed / unshadowed, unshadowed > vec3<f32>(0.0));
    return clamp(v, vec3<f32>(0.0), vec3<f32>(1.0));
}
