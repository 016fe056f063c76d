// Method `chun-oh` (Chun & Oh 2016 §3): the quadtree over one pixel's filter. A region's
// visibility variance is E − E² (Eq. 1: the tests are 0 or 1, so no second moment is
// stored); it splits into 4 when that exceeds the threshold, or — when it is not 0 — when the
// part of the light it maps to varies in colour; at most twice (4×4). Each leaf's visibility
// weights the emission of its part of the light (Fig. 3). Free of bindings: the importer
// declares `cells` (lit tests per 4×4 cell, `var<private> array<u32, 16>`) and defines
// `light_region(i)` (the light table), so `quadtree_probe.wgsl` runs this on synthetic tiles.

struct QuadtreeParams {
    mode: u32,            // 1 adaptive, 2 fixed (always 4×4)
    threshold: f32,       // visibility variance above which a region splits
    light_threshold: f32, // relative colour variance of the light part that forces a split
    cell_taps: u32,       // shadow tests per side of one 4×4 cell
}

const MODE_FIXED: u32 = 2u;
// Indices into the light table: 0–15 the 4×4 cells, 16–19 the 2×2 quadrants, 20 the whole.
const QUADRANTS: u32 = 16u;
const WHOLE: u32 = 20u;

struct Subdivision {
    sum: vec3<f32>, // Σ over leaves of visibility × the emission of the leaf's light part
    level: u32,     // deepest split: 0, 1 (2×2) or 2 (4×4)
    forced: u32,    // splits only the light's colour asked for
}

fn visibility_variance(e: f32) -> f32 {
    return e - e * e;
}

// Whether a region at `level` with visibility e over light part `region` splits: 0 no, 1 by
// visibility variance (or fixed mode), 2 only because the light's colour varies there.
fn split(e: f32, level: u32, region: u32, q: QuadtreeParams) -> u32 {
    if level >= 2u {
        return 0u;
    }
    if q.mode == MODE_FIXED {
        return 1u;
    }
    let variance = visibility_variance(e);
    if variance <= 0.0 {
        return 0u; // umbra or fully lit: the light's colours cannot show
    }
    if variance > q.threshold {
        return 1u;
    }
    return select(0u, 2u, light_region(region).w > q.light_threshold);
}

fn cell_visibility(x: u32, y: u32, q: QuadtreeParams) -> f32 {
    return f32(cells[y * 4u + x]) / f32(q.cell_taps * q.cell_taps);
}

fn quadrant_visibility(x: u32, y: u32, q: QuadtreeParams) -> f32 {
    let first = 8u * y + 2u * x;
    let lit = cells[first] + cells[first + 1u] + cells[first + 4u] + cells[first + 5u];
    return f32(lit) / f32(4u * q.cell_taps * q.cell_taps);
}

// The filter's subdivision, given its overall visibility e0.
fn subdivide(e0: f32, q: QuadtreeParams) -> Subdivision {
    var s = Subdivision(vec3<f32>(0.0), 0u, 0u);
    let top = split(e0, 0u, WHOLE, q);
    if top == 0u {
        s.sum = e0 * light_region(WHOLE).rgb;
        return s;
    }
    s.level = 1u;
    s.forced += u32(top == 2u);
    for (var quadrant = 0u; quadrant < 4u; quadrant++) {
        let qx = quadrant % 2u;
        let qy = quadrant / 2u;
        let e1 = quadrant_visibility(qx, qy, q);
        let below = split(e1, 1u, QUADRANTS + quadrant, q);
        if below == 0u {
            s.sum += e1 * light_region(QUADRANTS + quadrant).rgb;
            continue;
        }
        s.level = 2u;
        s.forced += u32(below == 2u);
        for (var c = 0u; c < 4u; c++) {
            let cx = 2u * qx + c % 2u;
            let cy = 2u * qy + c / 2u;
            s.sum += cell_visibility(cx, cy, q) * light_region(cy * 4u + cx).rgb;
        }
    }
    return s;
}

fn quadtree_luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// The pixel's RGB visibility: the leaves' sum over the light's own emission per channel; a
// channel the light does not emit takes the luminance-weighted visibility (it shows nowhere,
// but stays well defined).
fn coloured_visibility(s: Subdivision, e0: f32) -> vec3<f32> {
    let total = light_region(WHOLE).rgb;
    let gray = select(e0, quadtree_luminance(s.sum) / quadtree_luminance(total), quadtree_luminance(total) > 0.0);
    return select(vec3<f32>(gray), s.sum / max(total, vec3<f32>(1e-30)), total > vec3<f32>(0.0));
}
