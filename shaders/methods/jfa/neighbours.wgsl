// Jump flooding's communication pattern (Rong & Tan 2006 §3), and which workgroups a round
// may skip. In a round with step length k, cell p reads the cells p + (a, b), a, b ∈ {−k, 0, k}.
// Every flood uses these functions, so the Voronoi test (`voronoi.wgsl` against a brute-force
// nearest seed) checks the pattern and the skipping the shadow methods rely on.

// A cell's jump neighbours: p + (a, b)·step but p itself, whose record the cell holds already.
// Left out of the loop rather than skipped in it: on lavapipe lanes run in lockstep, so an
// iteration every lane skips still costs a full one — a ninth of a round.
const JUMP_NEIGHBOURS: u32 = 8u;

// The i-th jump neighbour at this step (i in 0..JUMP_NEIGHBOURS, row by row: (−1, −1),
// (0, −1), (1, −1), (−1, 0), (1, 0), …), or (−1, −1) when it lies outside the grid.
fn jump_neighbour(p: vec2<i32>, i: u32, step: i32, size: vec2<i32>) -> vec2<i32> {
    let k = i + u32(i >= 4u); // the 3×3 offsets row by row, the centre (4) left out
    let n = p + vec2<i32>(i32(k % 3u) - 1, i32(k / 3u) - 1) * step;
    if any(n < vec2<i32>(0)) || any(n >= size) {
        return vec2<i32>(-1);
    }
    return n;
}

// Floods run in TILE×TILE workgroups, one per tile of the grid.
const TILE: i32 = 8;

fn floor_div(a: i32, b: i32) -> i32 {
    return select(a / b, (a - b + 1) / b, a < 0);
}

// Past the paper: a flood only ever adds or improves records, so a tile whose cells and all
// their jump neighbours hold none would copy empty records over the empty records both
// buffers already hold — it need not run. Most of a shadow map is far from any silhouette,
// so this is where a round's cost goes. (The shadow methods list the tiles that must run and
// launch only those, `list_tiles` in common.wgsl; the Voronoi twin returns early from the
// others: the same tiles run.) Whether a record may reach `tile` this
// round: some tile holding a neighbour of its cells (offsets a·step, b·step) — or the tile
// itself — holds one. The importer defines `tile_holds_record(tile)`: a flag any cell of
// that tile sets once it holds a record (seed pass or an earlier round).
fn reach_holds_record(tile: vec2<i32>, step: i32, tiles: vec2<i32>) -> bool {
    if step < TILE {
        // The offsets' tiles are the 3×3 tiles around this one: each once, not once per
        // offset that reaches it (36 looks, most of them repeats, below).
        for (var ty = max(tile.y - 1, 0); ty <= min(tile.y + 1, tiles.y - 1); ty++) {
            for (var tx = max(tile.x - 1, 0); tx <= min(tile.x + 1, tiles.x - 1); tx++) {
                if tile_holds_record(vec2<i32>(tx, ty)) {
                    return true;
                }
            }
        }
        return false;
    }
    for (var b = -1; b <= 1; b++) {
        // The cells tile.y·TILE + b·step … + TILE − 1 span one tile, or two when step is not
        // a multiple of TILE.
        let y = tile.y * TILE + b * step;
        let rows = clamp(vec2<i32>(floor_div(y, TILE), floor_div(y + TILE - 1, TILE)), vec2<i32>(0), vec2<i32>(tiles.y - 1));
        for (var a = -1; a <= 1; a++) {
            let x = tile.x * TILE + a * step;
            let columns = clamp(vec2<i32>(floor_div(x, TILE), floor_div(x + TILE - 1, TILE)), vec2<i32>(0), vec2<i32>(tiles.x - 1));
            for (var ty = rows.x; ty <= rows.y; ty++) {
                for (var tx = columns.x; tx <= columns.y; tx++) {
                    if tile_holds_record(vec2<i32>(tx, ty)) {
                        return true;
                    }
                }
            }
        }
    }
    return false;
}
