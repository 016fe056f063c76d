// Method `wedges`, three-pass variant (§6.1), the umbra pass: volume polygons of the light
// centre's hard shadow over their tiles (`rasterize.wgsl`).

#import methods/wedges/rasterize.wgsl

@compute @workgroup_size(LANES)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    frame = frame_uniform;
    params = params_uniform;
    let item = tile_item(group, groups, local);
    if !item.valid {
        return;
    }
    let poly = polygons[item.job.primitive];
    for (var k = local; k < TILE * TILE; k += LANES) {
        let px = tile_pixel(item.origin, k);
        if px.valid {
            add_light(px.at, vec3<i32>(umbra_delta(poly, px.receiver)));
        }
    }
}
