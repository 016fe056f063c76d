// Jump flooding's communication pattern (Rong & Tan 2006 §3): in a round with step length k,
// cell p reads the cells p + (a, b), a, b ∈ {−k, 0, k}. Every flood uses this one function, so
// the Voronoi test (`voronoi.wgsl` against a brute-force nearest seed) checks the pattern the
// shadow methods rely on.

// The i-th of the 8 neighbours (i in 0..9, 4 being p itself) at this step, or (−1, −1) when
// it is p or lies outside the grid.
fn jump_neighbour(p: vec2<i32>, i: u32, step: i32, size: vec2<i32>) -> vec2<i32> {
    let n = p + vec2<i32>(i32(i % 3u) - 1, i32(i / 3u) - 1) * step;
    if i == 4u || any(n < vec2<i32>(0)) || any(n >= size) {
        return vec2<i32>(-1);
    }
    return n;
}
