// Method `wedges` (Assarsson & Akenine-Möller 2003 §4): the per-tile depth range occlusion
// culling tests wedges against — zmin and zmax of the view depth of the tile's covered pixels
// (+∞ / −∞ for a tile of background only).

#import methods/wedges/common.wgsl

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let tiles = tile_grid();
    if id.x >= tiles.x * tiles.y {
        return;
    }
    let origin = vec2<u32>(id.x % tiles.x, id.x / tiles.x) * params.tile;
    var zmin = 1e30;
    var zmax = -1e30;
    for (var y = origin.y; y < min(origin.y + params.tile, frame.sizes.y); y++) {
        for (var x = origin.x; x < min(origin.x + params.tile, frame.sizes.x); x++) {
            if covered(vec2<u32>(x, y)) {
                let depth = textureLoad(gbuf_position, vec2<u32>(x, y), 0).w;
                zmin = min(zmin, depth);
                zmax = max(zmax, depth);
            }
        }
    }
    tile_ranges[id.x] = vec2<f32>(zmin, zmax);
}
