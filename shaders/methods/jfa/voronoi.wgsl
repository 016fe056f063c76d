// Jump flooding as a Voronoi diagram (Rong & Tan 2006 §3, after their earlier JFA paper):
// every cell keeps the nearest seed among those its neighbours know. Used by the tests to
// check the flooding pattern against a brute-force nearest seed; the shadow methods flood
// occluders with the same `jump_neighbour`.

#import methods/jfa/neighbours.wgsl

struct VoronoiParams {
    step: i32,
    size: u32,
}

@group(0) @binding(0) var<uniform> params: VoronoiParams;
@group(0) @binding(1) var<storage, read> seeds: array<vec2<i32>>;
@group(0) @binding(2) var<storage, read> src: array<i32>;
@group(0) @binding(3) var<storage, read_write> dst: array<i32>;
// Per TILE×TILE tile, 1 once a cell of it holds a seed (`reach_holds_record`).
@group(0) @binding(4) var<storage, read_write> tiles: array<atomic<u32>>;

fn tile_count() -> vec2<i32> {
    return vec2<i32>((i32(params.size) + TILE - 1) / TILE);
}

fn tile_holds_record(tile: vec2<i32>) -> bool {
    return atomicLoad(&tiles[tile.y * tile_count().x + tile.x]) != 0u;
}

var<workgroup> in_reach: u32;

fn distance2(p: vec2<i32>, seed: i32) -> i32 {
    let d = p - seeds[seed];
    return d.x * d.x + d.y * d.y;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32, @builtin(workgroup_id) group: vec3<u32>) {
    if local == 0u {
        in_reach = u32(reach_holds_record(vec2<i32>(group.xy), params.step, tile_count()));
    }
    if workgroupUniformLoad(&in_reach) == 0u {
        return;
    }
    let size = i32(params.size);
    if any(id.xy >= vec2<u32>(params.size)) {
        return;
    }
    let p = vec2<i32>(id.xy);
    var best = src[id.y * params.size + id.x];
    for (var i = 0u; i < JUMP_NEIGHBOURS; i++) {
        let n = jump_neighbour(p, i, params.step, vec2<i32>(size));
        if n.x < 0 {
            continue;
        }
        let candidate = src[n.y * size + n.x];
        if candidate >= 0 && (best < 0 || distance2(p, candidate) < distance2(p, best) || (distance2(p, candidate) == distance2(p, best) && candidate < best)) {
            best = candidate;
        }
    }
    dst[id.y * params.size + id.x] = best;
    if best >= 0 {
        atomicStore(&tiles[i32(id.y) / TILE * tile_count().x + i32(id.x) / TILE], 1u);
    }
}
