// Method `wedges` (Assarsson & Akenine-Möller 2003 §4): the per-tile depth range occlusion
// culling tests wedges against — zmin and zmax of the view depth of the tile's covered pixels
// (+∞ / −∞ for a tile of background only), and past the paper the world-space box of their
// points, the slab they span along the centre pixel's normal and the object they all ignore
// (`culling.rs` says why) — and, while reading every pixel, the receiver
// record the rasteriser reads instead of the G-buffer (one storage read, not four texture
// loads, per pixel and primitive).

#import methods/wedges/common.wgsl

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let tiles = tile_grid();
    if id.x >= tiles.x * tiles.y {
        return;
    }
    let origin = vec2<u32>(id.x % tiles.x, id.x / tiles.x) * params.tile;
    var lo = vec4<f32>(1e30);
    var hi = vec4<f32>(-1e30);
    // Past the paper: the slab the tile's points span along the normal at its centre pixel
    // (where that pixel is covered): on a landscape seen at a grazing angle the points lie
    // close to a plane steep in depth, whose slab is far thinner than either box.
    let centre = min(origin + params.tile / 2u, frame.sizes.xy - 1u);
    let axis = select(vec3<f32>(0.0), textureLoad(gbuf_normal, centre, 0).xyz, covered(centre));
    var slab = vec2<f32>(1e30, -1e30);
    // The object every covered pixel of the tile ignores (below), or NO_OBJECT: where all of
    // them ignore one, that object's volume polygons and wedges change none of them.
    var ignored = NOT_COVERED;
    for (var y = origin.y; y < min(origin.y + params.tile, frame.sizes.y); y++) {
        for (var x = origin.x; x < min(origin.x + params.tile, frame.sizes.x); x++) {
            let pixel = vec2<u32>(x, y);
            let at = 2u * (y * frame.sizes.x + x);
            if !covered(pixel) {
                receivers[at] = vec4<f32>(0.0, 0.0, 0.0, NOT_COVERED);
                continue;
            }
            let position = textureLoad(gbuf_position, pixel, 0);
            let normal = textureLoad(gbuf_normal, pixel, 0).xyz;
            lo = min(lo, position);
            hi = max(hi, position);
            let along = dot(axis, position.xyz);
            slab = vec2<f32>(min(slab.x, along), max(slab.y, along));
            // A point facing away from the light centre lies in its own object's volume — the
            // segment to the centre runs through the object — yet the part of the light above
            // its horizon may well reach it, and E0 already leaves out the part below. So its
            // own object's volume and wedges do not count for it (as with Brabec & Seidel's
            // ids); other objects' still do. "Away" is judged by the plane of the triangle seen
            // (the G-buffer's geometric normal), not its smoothed normal, which can face the
            // light on a facet that does not.
            let grazing = dot(normal, normalize(frame.light_center.xyz - position.xyz)) < SELF_SHADOW_COS;
            let own_object = select(NO_OBJECT, f32(textureLoad(gbuf_id, pixel, 0).r), params.object_ids == 1u && grazing);
            receivers[at] = vec4<f32>(position.xyz, own_object);
            ignored = select(NO_OBJECT, own_object, ignored == NOT_COVERED || ignored == own_object);
            receivers[at + 1u] = vec4<f32>(normal, 0.0);
        }
    }
    tile_ranges[id.x] = TileRange(lo, hi, vec4<f32>(axis, slab.x), vec4<f32>(slab.y, select(ignored, NO_OBJECT, ignored == NOT_COVERED), 0.0, 0.0));
}
