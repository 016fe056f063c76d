// E0 summed exactly: every pixel in one pass (lights of a cell or two, and `E0Mode::Exact`),
// or the pixels the interpolation listed, four at a time (shaders/e0/common.wgsl).

#import e0/common.wgsl

// Every pixel summed exactly, in one pass: lights of a cell or two, where the corners and
// the check cost more than they save (and listing the lit pixels costs more than the cells'
// sums: an atomic append per lane), and `E0Mode::Exact`, the yardstick the interpolation is
// measured against.
@compute @workgroup_size(8, 8)
fn exact(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    let origin = 2u * id.xy;
    if any(origin >= frame.sizes.xy) {
        return;
    }
    let last = frame.sizes.xy - 1u;
    let p = array<vec2<u32>, 4>(origin, min(origin + vec2<u32>(1u, 0u), last), min(origin + vec2<u32>(0u, 1u), last), min(origin + 1u, last));
    let q = Quad(screen_surface(p[0]), screen_surface(p[1]), screen_surface(p[2]), screen_surface(p[3]));
    store_quad(q, clipped_quad(q));
}

// A pixel's surface, its normal zero where it receives no light (E0 = 0 then).
fn screen_surface(pixel: vec2<u32>) -> Surface {
    let x = textureLoad(gbuf_position, pixel, 0).xyz;
    let normal = textureLoad(gbuf_shading, pixel, 0);
    let lit = covers(normal) && lit_side(x);
    return Surface(pixel_index(pixel), x, select(vec3<f32>(0.0), normal.xyz, lit));
}

// The sizes of the two exact passes' dispatches.
@compute @workgroup_size(1)
fn exact_sizes() {
    frame = frame_uniform;
    above_groups = list_dispatch((atomicLoad(&above.count) + QUAD - 1u) / QUAD);
    clipped_groups = list_dispatch((atomicLoad(&clipped.count) + QUAD - 1u) / QUAD);
}

// A listed pixel's surface: its element of the screen-space images, position and normal.
struct Surface {
    at: u32,
    x: vec3<f32>,
    nx: vec3<f32>,
}

fn listed_surface(entry: u32) -> Surface {
    let pixel = listed_pixel(entry);
    return Surface(entry, textureLoad(gbuf_position, pixel, 0).xyz, textureLoad(gbuf_shading, pixel, 0).xyz);
}

// Listed pixels per invocation of the exact passes. On lavapipe a uniform-buffer load indexed
// by the loop over cells is a gather, lane by lane, and loading a cell cost more than summing
// it for one pixel: four pixels per invocation load each cell once for all four.
const QUAD: u32 = 4u;

// The four listed pixels of one invocation.
struct Quad {
    a: Surface,
    b: Surface,
    c: Surface,
    d: Surface,
}

fn listed_quad(pixels: vec4<u32>) -> Quad {
    return Quad(listed_surface(pixels.x), listed_surface(pixels.y), listed_surface(pixels.z), listed_surface(pixels.w));
}

fn store_quad(q: Quad, e0: mat4x3<f32>) {
    e0_out[q.a.at] = vec4<f32>(e0[0], 1.0);
    e0_out[q.b.at] = vec4<f32>(e0[1], 1.0);
    e0_out[q.c.at] = vec4<f32>(e0[2], 1.0);
    e0_out[q.d.at] = vec4<f32>(e0[3], 1.0);
}

// The list positions of an invocation's quad, clamped to the list: where it ends, the last
// pixel is summed again and written twice with the same value.
fn quad_positions(group: vec3<u32>, lane: u32, count: u32) -> vec4<u32> {
    let first = QUAD * list_position(group, lane);
    return min(vec4<u32>(first) + vec4<u32>(0u, 1u, 2u, 3u), vec4<u32>(count - 1u));
}

// The pixels of `above`, summed exactly without clipping: where the whole light lies above
// x's horizon, |nx · Φ| of each cell (`polygon_vector`, its own four edges) is the value
// `polygon_irradiance` computes there, in the same order, at about half the cost.
@compute @workgroup_size(64)
fn exact_above(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    let count = atomicLoad(&above.count);
    if QUAD * list_position(group, lane) >= count {
        return;
    }
    let at = quad_positions(group, lane, count);
    let q = listed_quad(vec4<u32>(above.pixels[at.x], above.pixels[at.y], above.pixels[at.z], above.pixels[at.w]));
    if GRID {
        store_quad(q, grid_above_quad(q));
        return;
    }
    var e0 = mat4x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var k = 0u; k < frame.sizes.w; k++) {
        let cell = light_cells[k];
        let corners = cell_corners(cell);
        let edges = cell_edges(cell);
        e0[0] += cell.radiance.rgb * abs(dot(q.a.nx, polygon_vector(q.a.x, corners, edges)));
        e0[1] += cell.radiance.rgb * abs(dot(q.b.nx, polygon_vector(q.b.x, corners, edges)));
        e0[2] += cell.radiance.rgb * abs(dot(q.c.nx, polygon_vector(q.c.x, corners, edges)));
        e0[3] += cell.radiance.rgb * abs(dot(q.d.nx, polygon_vector(q.d.x, corners, edges)));
    }
    store_quad(q, e0);
}

// The exact sum at each of a quad's pixels (columns), every cell clipped to its hemisphere.
fn clipped_quad(q: Quad) -> mat4x3<f32> {
    if GRID {
        // Pixel by pixel: the walk's carried state is twice the unclipped one's, and four
        // walks side by side (the row's cells loaded once for all) spill more than they save.
        return mat4x3<f32>(grid_clipped(q.a.x, q.a.nx), grid_clipped(q.b.x, q.b.nx), grid_clipped(q.c.x, q.c.nx), grid_clipped(q.d.x, q.d.nx));
    }
    var e0 = mat4x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var k = 0u; k < frame.sizes.w; k++) {
        let cell = light_cells[k];
        let corners = cell_corners(cell);
        let edges = cell_edges(cell);
        e0[0] += cell.radiance.rgb * polygon_irradiance(q.a.x, q.a.nx, corners, edges);
        e0[1] += cell.radiance.rgb * polygon_irradiance(q.b.x, q.b.nx, corners, edges);
        e0[2] += cell.radiance.rgb * polygon_irradiance(q.c.x, q.c.nx, corners, edges);
        e0[3] += cell.radiance.rgb * polygon_irradiance(q.d.x, q.d.nx, corners, edges);
    }
    return e0;
}

// The pixels of `clipped`, summed exactly with each cell clipped to the hemisphere.
@compute @workgroup_size(64)
fn exact_clipped(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    frame = frame_uniform;
    let count = atomicLoad(&clipped.count);
    if QUAD * list_position(group, lane) >= count {
        return;
    }
    let at = quad_positions(group, lane, count);
    let q = listed_quad(vec4<u32>(clipped.pixels[at.x], clipped.pixels[at.y], clipped.pixels[at.z], clipped.pixels[at.w]));
    store_quad(q, clipped_quad(q));
}

// The unclipped sums of a quad's pixels over the grid (`GRID`), a row of cells at a time for
// all four: the row's cells are loaded once for the quad (`QUAD`), cheaper than a pixel at
// a time.
fn grid_above_quad(q: Quad) -> mat4x3<f32> {
    let columns = grid_columns();
    let top = light_cells[0u].rect.w;
    var a = above_start(q.a.x, q.a.nx, columns, top);
    var b = above_start(q.b.x, q.b.nx, columns, top);
    var c = above_start(q.c.x, q.c.nx, columns, top);
    var d = above_start(q.d.x, q.d.nx, columns, top);
    for (var r = 0u; r < SIDE; r++) {
        let row = grid_row(r);
        above_row(&a, q.a.x, columns, row);
        above_row(&b, q.b.x, columns, row);
        above_row(&c, q.c.x, columns, row);
        above_row(&d, q.d.x, columns, row);
    }
    return mat4x3<f32>(a.e0, b.e0, c.e0, d.e0);
}
