// E0's interpolation inside a block: the block's corners loaded once, blended row by row
// with perspective-correct weights (shaders/e0/interpolate.wgsl).

struct Block {
    c00: Corner,
    c10: Corner,
    c01: Corner,
    c11: Corner,
}

fn load_block(block: vec2<u32>) -> Block {
    let row = block.y * corner_count().x + block.x;
    let below = row + corner_count().x;
    return Block(corners[row], corners[row + 1u], corners[below], corners[below + 1u]);
}

// The blend of a block's corners at a pixel is perspective-correct (bilinear over view
// depth): on a plane it puts the blend of the corners' positions on the pixel's own position
// up to second order, where plain screen-space weights would be off by the projection's
// curvature. It is Σ bᵢ cᵢ/dᵢ over Σ bᵢ/dᵢ, bᵢ the bilinear weights and dᵢ the corners' view
// depths, and both sums are linear along a row of the block: so a row holds them at its two
// ends (`RowBlend`), and a pixel takes a linear step and one division instead of four
// weights and four divisions.
struct RowBlend {
    left_r: vec4<f32>,
    left_g: vec4<f32>,
    left_b: vec4<f32>,
    left_position: vec4<f32>,
    right_r: vec4<f32>,
    right_g: vec4<f32>,
    right_b: vec4<f32>,
    right_position: vec4<f32>,
    weight: vec2<f32>, // Σ bᵢ/dᵢ at the left and right ends
}

// Row `fy` (0 at the block's top corners, 1 at its bottom ones).
fn row_blend(b: Block, fy: f32) -> RowBlend {
    let inv = 1.0 / max(vec4<f32>(b.c00.normal.w, b.c10.normal.w, b.c01.normal.w, b.c11.normal.w), vec4<f32>(1e-20));
    let w = vec4<f32>(inv.x * (1.0 - fy), inv.y * (1.0 - fy), inv.z * fy, inv.w * fy);
    return RowBlend(
        w.x * b.c00.phi_r + w.z * b.c01.phi_r,
        w.x * b.c00.phi_g + w.z * b.c01.phi_g,
        w.x * b.c00.phi_b + w.z * b.c01.phi_b,
        w.x * b.c00.position + w.z * b.c01.position,
        w.y * b.c10.phi_r + w.w * b.c11.phi_r,
        w.y * b.c10.phi_g + w.w * b.c11.phi_g,
        w.y * b.c10.phi_b + w.w * b.c11.phi_b,
        w.y * b.c10.position + w.w * b.c11.position,
        vec2<f32>(w.x + w.z, w.y + w.w),
    );
}

// The blend of the corners' records at fraction `fx` along the row.
fn blend_in_row(row: RowBlend, fx: f32) -> Corner {
    let scale = 1.0 / mix(row.weight.x, row.weight.y, fx);
    return Corner(
        mix(row.left_r, row.right_r, fx) * scale,
        mix(row.left_g, row.right_g, fx) * scale,
        mix(row.left_b, row.right_b, fx) * scale,
        mix(row.left_position, row.right_position, fx) * scale,
        vec4<f32>(0.0),
    );
}

// The fraction of the way between a block's corners that one pixel is, across and down
// (a block at the frame's edge spans fewer pixels).
fn pixel_step(block: vec2<u32>) -> vec2<f32> {
    return 1.0 / vec2<f32>(max(corner_pixel(block + 1u) - corner_pixel(block), vec2<u32>(1u)));
}

// The blend at the pixel `offset` from the block's first (`step`: `pixel_step`).
fn blend_at(b: Block, offset: vec2<u32>, step: vec2<f32>) -> Corner {
    return blend_in_row(row_blend(b, f32(offset.y) * step.y), f32(offset.x) * step.x);
}

fn all_valid(b: Block) -> bool {
    return b.c00.position.w * b.c10.position.w * b.c01.position.w * b.c11.position.w > 0.0;
}

// Largest distance of the corners' normals from nx: 0 on a flat face. One square root of the
// largest square (the same value: the root is monotonic and correctly rounded).
fn bend(b: Block, nx: vec3<f32>) -> f32 {
    let squares = vec4<f32>(
        normal_gap2(b.c00.normal.xyz, nx),
        normal_gap2(b.c10.normal.xyz, nx),
        normal_gap2(b.c01.normal.xyz, nx),
        normal_gap2(b.c11.normal.xyz, nx),
    );
    return sqrt(max(max(squares.x, squares.y), max(squares.z, squares.w)));
}

// Whether the corners' normals lie within BENT of the first corner's.
fn agrees(b: Block) -> bool {
    return bend(b, b.c00.normal.xyz) <= BENT;
}

fn phi_size(c: Corner) -> vec3<f32> {
    return vec3<f32>(length(c.phi_r.xyz), length(c.phi_g.xyz), length(c.phi_b.xyz));
}

fn e0_of(c: Corner) -> vec3<f32> {
    return vec3<f32>(c.phi_r.w, c.phi_g.w, c.phi_b.w);
}

fn max3(v: vec3<f32>) -> f32 {
    return max(v.x, max(v.y, v.z));
}
