// Method `wedges` (Assarsson & Akenine-Möller 2003 §3–§6): rasterising the work list — each
// workgroup takes one (primitive, tile) pair that survived culling and runs over the tile's
// pixels, reading the pixel's surface point once (the "depth read") and adding to the LI
// buffer (an "LI write") where the primitive touches it. The entry points
// (`rasterize_umbra.wgsl`, `rasterize_penumbra.wgsl`, `rasterize_both.wgsl`) each hold only
// the code their items need: on a CPU rasteriser (lavapipe) the wedge code alone, even never
// taken, makes the umbra loop many times slower. The two contributions:
// - a shadow-volume polygon of the light centre's hard shadow (`rasterizeUmbra`): ∓full for a
//   crossing of the eye ray in front of the point (z-pass) or, with the signs reversed, beyond
//   it (z-fail, §5 — with the volume's caps, correct with the eye inside a shadow);
// - a penumbra wedge (`rasterizePenumbra`): where the silhouette edge, projected from the
//   point onto the light, cuts the light rectangle, the light's share beyond it — per channel
//   of the light image's emission for a coloured light (`colored_share`).
// The single-pass variant (§6.2) gives one item both halves of an edge.

#import methods/wedges/common.wgsl

// `CHANNELS` and `COLOR_ANGLES` as pipeline constants (`methods::wedges` makes a
// pipeline per value): on lavapipe a branch no lane takes still runs its code, so a uniform
// light's passes hold no colour code at all, and the colour loop runs a fixed count.
override CHANNELS: u32 = 1u;
override COLOR_ANGLES: u32 = 8u;
// The tile's side in pixels (`params.tile`) as a pipeline constant: a pixel's place in its
// tile is then a shift and a mask, where a division by a uniform was a scalar division per
// lane on lavapipe, twice per pixel.
override TILE: u32 = 8u;
// Invocations per work item, each taking every LANES-th pixel of the tile. lavapipe runs a
// workgroup as a loop over SIMD groups of 8 lanes, each paying again for what every lane of
// the item shares (its work item, its primitive), so there 8 lanes each take 8 of an 8×8
// tile's pixels (`methods::wedges` sets it). A GPU keeps 64, two warps.
override LANES: u32 = 64u;

fn cross2(a: vec2<f32>, b: vec2<f32>) -> f32 {
    return a.x * b.y - a.y * b.x;
}

// A fixed order of points: lexicographic in x, y, z.
fn before(u: vec3<f32>, w: vec3<f32>) -> bool {
    if u.x != w.x {
        return u.x < w.x;
    }
    if u.y != w.y {
        return u.y < w.y;
    }
    return u.z < w.z;
}

// Which side of the edge u → w the ray from `eye` along `ray` passes: the sign of
// ray · ((u − eye) × (w − eye)), with a fixed owner for an exact 0.
fn edge_side(ray: vec3<f32>, eye: vec3<f32>, u: vec3<f32>, w: vec3<f32>) -> f32 {
    let s = dot(ray, cross(u - eye, w - eye));
    if s == 0.0 {
        // The ray meets the edge's line exactly (a symmetric view does, along whole rows):
        // the edge's owner is the polygon running it in the canonical direction.
        return select(-1.0, 1.0, before(u, w));
    }
    return s;
}

// The signed number of times the eye ray to p crosses `poly` where it counts: in front of p
// (z-pass: entering +, leaving −) or beyond it (z-fail: the reverse), times the multiplicity.
fn volume_crossing(poly: VolumePolygon, eye: vec3<f32>, p: vec3<f32>) -> i32 {
    let ray = p - eye;
    let n = cross(poly.v1.xyz - poly.v0.xyz, poly.v2.xyz - poly.v0.xyz);
    let facing = dot(n, ray);
    if abs(facing) <= 1e-12 * length(n) * length(ray) {
        return 0; // the ray runs along the polygon's plane
    }
    let t = dot(n, poly.v0.xyz - eye) / facing;
    // Where p lies on the polygon, it counts as outside. That only needs a tolerance for caps:
    // a top cap is the caster's own lit surface, which z-fail must count at p (the ray enters
    // there and leaves through the bottom cap). A side quad is compared with p exactly: a ray
    // grazing a caster can leave its volume through a quad just in front of p, and a
    // tolerance would drop that exit and shadow a lit point.
    let cap = all(poly.v3.xyz == poly.v2.xyz);
    let at_p = select(1.0, 1.0 - 1e-4, cap);
    if (params.zfail == 0u && (t <= 0.0 || t >= at_p)) || (params.zfail == 1u && t < at_p) {
        return 0;
    }
    // Whether the ray passes through the polygon: on the same side of every edge, by the sign
    // of ray · ((u − eye) × (v − eye)). Two polygons sharing an edge run it in opposite
    // directions, which negates that product exactly, so a ray through a shared edge (the
    // corner ray of a volume) is counted by exactly one of them — testing the hit point
    // against each polygon's own edges would count it by both or neither.
    let s0 = edge_side(ray, eye, poly.v0.xyz, poly.v1.xyz);
    let s1 = edge_side(ray, eye, poly.v1.xyz, poly.v2.xyz);
    let s2 = edge_side(ray, eye, poly.v2.xyz, poly.v3.xyz);
    let s3 = edge_side(ray, eye, poly.v3.xyz, poly.v0.xyz);
    let sides = vec4<f32>(s0, s1, s2, s3);
    // A triangle's repeated vertex makes a null edge, on both sides at once.
    let null_edge = vec4<bool>(false, false, cap, false);
    let positive = all((sides > vec4<f32>(0.0)) | null_edge);
    let negative = all((sides < vec4<f32>(0.0)) | null_edge);
    if !(positive || negative) {
        return 0;
    }
    let entering = facing < 0.0;
    let m = i32(poly.v0.w);
    return select(m, -m, entering == (params.zfail == 1u));
}

// The item this workgroup runs, and the first pixel of its tile; counts the tile's on-screen
// pixels as depth reads once per item (an atomic per pixel would cost more than the test).
struct TileItem {
    job: WorkItem,
    origin: vec2<u32>,
    valid: bool,
}

// The work item of a workgroup: items go in rows of `groups.x` workgroups, as even as the
// grid allows (`item_grid` in `wedges/mod.rs`), so that few workgroups past the list's end are
// launched — on lavapipe one that returns at once still pays for most of its code.
fn item_index(group: vec3<u32>, groups: vec3<u32>) -> u32 {
    return group.y * groups.x + group.x;
}

// A work item's tile's first pixel, from its packed `origin`.
fn tile_origin(origin: u32) -> vec2<u32> {
    return vec2<u32>(origin & 0xffffu, origin >> 16u);
}

fn tile_item(group: vec3<u32>, groups: vec3<u32>, local: u32) -> TileItem {
    var item: TileItem;
    let index = item_index(group, groups);
    item.valid = index < arrayLength(&work);
    if !item.valid {
        return item;
    }
    item.job = work[index];
    item.origin = tile_origin(item.job.origin);
    if local == 0u {
        let span = min(item.origin + TILE, frame.sizes.xy) - item.origin;
        atomicAdd(&counters[0], span.x * span.y);
    }
    return item;
}

// The k-th pixel of a tile: its index into per-pixel buffers and its receiver record (the
// surface point; w, the object it ignores), loaded once for every test of the pixel. Not
// valid off screen or on the background.
struct TilePixel {
    at: u32,
    receiver: vec4<f32>,
    valid: bool,
}

fn tile_pixel(origin: vec2<u32>, k: u32) -> TilePixel {
    let pixel = tile_pixel_at(origin, k);
    var px: TilePixel;
    if any(pixel >= frame.sizes.xy) {
        return px;
    }
    px.at = pixel_index(pixel);
    px.receiver = receivers[2u * px.at];
    px.valid = px.receiver.w != NOT_COVERED;
    return px;
}

// The k-th pixel of the tile whose first pixel is `origin`.
fn tile_pixel_at(origin: vec2<u32>, k: u32) -> vec2<u32> {
    return origin + vec2<u32>(k % TILE, k / TILE);
}

fn add_light(at: u32, delta: vec3<i32>) {
    if any(delta != vec3<i32>(0)) {
        for (var k = 0u; k < CHANNELS; k++) {
            atomicAdd(&li[at * CHANNELS + k], delta[k]);
        }
        atomicAdd(&counters[1], 1u);
    }
}

// The primitives are loaded once per work item, before the loop over its tile's pixels, and
// passed by value: on lavapipe a storage load inside the loop is a gather, lane by lane, on
// every pass through it, though every lane reads the same primitive.

// The umbra term at a receiver for a volume polygon.
fn umbra_delta(poly: VolumePolygon, receiver: vec4<f32>) -> i32 {
    if poly.v1.w == receiver.w {
        return 0; // its own object, facing away from the light centre
    }
    return -params.full * volume_crossing(poly, frame.eye.xyz, receiver.xyz);
}
