// Test probe for `chun-oh`'s quadtree (`quadtree.wgsl`): runs the shader's own subdivision on
// synthetic 4×4 tiles of lit-test counts, so the tests check the variance formula and the
// split decisions on the GPU code itself (`chun_oh::quadtree_probe`).

#import methods/chun_oh/quadtree.wgsl

@group(0) @binding(0) var<storage, read> tiles: array<array<u32, 16>>;
@group(0) @binding(1) var<storage, read> regions: array<vec4<f32>, 21>;
@group(0) @binding(2) var<uniform> probe: QuadtreeParams;
// Per tile: rgb the coloured visibility, w level + 4 × forced splits.
@group(0) @binding(3) var<storage, read_write> results: array<vec4<f32>>;

var<private> cells: array<u32, 16>;

fn light_region(i: u32) -> vec4<f32> {
    return regions[i];
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= arrayLength(&tiles) {
        return;
    }
    cells = tiles[id.x];
    var lit = 0u;
    for (var i = 0u; i < 16u; i++) {
        lit += cells[i];
    }
    let e0 = f32(lit) / f32(16u * probe.cell_taps * probe.cell_taps);
    let s = subdivide(e0, probe);
    results[id.x] = vec4<f32>(coloured_visibility(s, e0), f32(s.level + 4u * s.forced));
}
