// Method `jfa-e`, §5.1 "Generating Penumbra Regions": one round of flooding over the screen.
// A pixel in hard shadow keeps the occluder giving it the highest intensity (inner penumbra),
// a lit pixel the lowest (outer); the key minimised is 1 − luminance or luminance. The two
// remedies of §5.2 against "jump too far" are switchable: flood only to pixels of the
// boundary pixel's object, and require the midpoint between the boundary pixel and this one
// to be in a penumbra of the same occluder.

#import methods/jfa/common.wgsl

// A key no candidate can take.
const NO_KEY: f32 = 1e30;

// What a pixel needs to weigh its neighbours' records.
struct Receiver {
    p: vec2<i32>,
    here: vec3<f32>,
    object: f32,
    inside: bool,
    own: vec4<f32>, // the record the pixel holds already
}

// The jump neighbour k's record index (2 vec4s a record), or −1 where there is none.
fn neighbour_record(r: Receiver, k: u32) -> i32 {
    let n = jump_neighbour(r.p, k, params.step, vec2<i32>(frame.sizes.xy));
    return select(i32(2u * (u32(n.y) * frame.sizes.x + u32(n.x))), -1, n.x < 0);
}

// The jump neighbours whose records this pixel may take, as bits k: a record is there and,
// with `same_object`, it came from a boundary pixel of this pixel's object. Read from each
// record's w alone: a round weighs only these (below), and finding them costs a load each
// where weighing a record costs its whole vec4 and a key from the table.
fn offered(r: Receiver) -> u32 {
    var bits = 0u;
    for (var k = 0u; k < JUMP_NEIGHBOURS; k++) {
        let at = neighbour_record(r, k);
        if at >= 0 {
            let w = src[at].w;
            if w != 0.0 && (params.same_object == 0u || w - 1.0 == r.object) {
                bits |= 1u << k;
            }
        }
    }
    return bits;
}

// The key offered neighbour k's occluder gives this pixel, or NO_KEY where it cannot be
// taken: the occluder the pixel holds already (whose key it has), or one whose ray misses
// the light.
fn candidate_key(r: Receiver, k: u32) -> f32 {
    let candidate = src[neighbour_record(r, k)];
    if all(candidate.xyz == r.own.xyz) {
        return NO_KEY;
    }
    let key = intensity_key(r.here, candidate.xyz);
    return select(key.x, NO_KEY, key.y == 0.0);
}

// §5.2's continuity check, read as: the midpoint between the boundary pixel and this one must
// itself be in a penumbra of the same occluder. Asking instead whether the midpoint already
// holds a record would depend on the order jump flooding reaches pixels (far ones first) and
// cut real penumbrae.
fn midpoint_holds(r: Receiver, k: u32) -> bool {
    let at = neighbour_record(r, k);
    let mid = vec2<u32>((vec2<i32>(src[at + 1].xy) + r.p) / 2);
    let mid_flag = flags[mid.y * frame.sizes.x + mid.x];
    if (mid_flag & COVERED) == 0u {
        return false;
    }
    return light_hit(textureLoad(gbuf_position, mid, 0).xyz, src[at].xyz).w > 0.0;
}

// One workgroup per listed tile (`list_tiles` in common.wgsl).
@compute @workgroup_size(8, 8)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let cell = listed_cell(group, local);
    if cell.x < 0 || any(vec2<u32>(cell) >= frame.sizes.xy) {
        return;
    }
    let pixel = vec2<u32>(cell);
    let index = 2u * (pixel.y * frame.sizes.x + pixel.x);
    var best = src[index];
    var best_origin = src[index + 1u];
    let flag = flags[pixel.y * frame.sizes.x + pixel.x];
    if (flag & COVERED) != 0u {
        let r = Receiver(vec2<i32>(pixel), textureLoad(gbuf_position, pixel, 0).xyz, f32(textureLoad(gbuf_id, pixel, 0).r), (flag & HARD) != 0u, best);
        // The neighbour taken is the one of least key below the pixel's own (the first of
        // equal keys) whose midpoint holds: what a scan keeping a running minimum would keep,
        // but with the midpoint checked for that neighbour alone — and, should it fail, for
        // the next in (key, neighbour) order — instead of for every better candidate met on
        // the way (on a CPU rasteriser every lane pays for every check any lane makes).
        // Only the offered neighbours are weighed, in neighbour order: lanes run in lockstep
        // and a loop runs as many times as its busiest lane needs, so a SIMD group of pixels
        // offered few records — most of the early rounds' tiles, far from a boundary — weighs
        // few, where a loop over all eight would weigh eight.
        let offers = offered(r);
        var after_key = -NO_KEY; // the (key, neighbour) order's lower bound, exclusive
        var after_k = -1;
        loop {
            var chosen = -1;
            var chosen_key = eye_key(best, best_origin);
            var rest = offers;
            while rest != 0u {
                let k = firstTrailingBit(rest);
                rest &= rest - 1u;
                let key = candidate_key(r, k);
                let after = key > after_key || (key == after_key && i32(k) > after_k);
                if after && key < chosen_key {
                    chosen = i32(k);
                    chosen_key = key;
                }
            }
            if chosen < 0 {
                break;
            }
            if params.midpoint == 0u || midpoint_holds(r, u32(chosen)) {
                let at = neighbour_record(r, u32(chosen));
                best = src[at];
                best_origin = vec4<f32>(src[at + 1].xy, chosen_key, src[at + 1].w);
                break;
            }
            after_key = chosen_key;
            after_k = chosen;
        }
    }
    dst[index] = best;
    dst[index + 1u] = best_origin;
    if !is_empty(best) {
        mark_tile(vec2<i32>(pixel));
    }
}
