// Method `wedges`, single-pass variant (§6.2): an item may carry an edge's volume polygon and
// its wedge over one tile, so the pixel is read once and the LI buffer written once for both
// (`rasterize.wgsl`). Items with only one half (a cap, or a tile only one half reaches) are in
// the same list.

#import methods/wedges/rasterize.wgsl
#import methods/wedges/share.wgsl

@compute @workgroup_size(LANES)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let item = tile_item(group, groups, local);
    if !item.valid {
        return;
    }
    let job = item.job;
    let polygon = job.primitive < params.polygon_count;
    let wedge = select(job.both, job.primitive - params.polygon_count + 1u, !polygon);
    // Loaded once (rasterize.wgsl says why); the half an item lacks is never read.
    let poly = polygons[select(0u, job.primitive, polygon)];
    let w = wedges[select(0u, wedge - 1u, wedge > 0u)];
    for (var k = local; k < TILE * TILE; k += LANES) {
        let px = tile_pixel(item.origin, k);
        if !px.valid {
            continue;
        }
        var delta = vec3<i32>(0);
        if polygon {
            delta += vec3<i32>(umbra_delta(poly, px.receiver));
        }
        if wedge > 0u {
            delta += penumbra_delta(w, px);
        }
        add_light(px.at, delta);
    }
}
