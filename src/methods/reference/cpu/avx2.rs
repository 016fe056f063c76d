//! The receiver tests of `SampleTest` eight receivers at a time with AVX2 and FMA, and the
//! maps' small triangles a row of up to eight texels at a time with AVX2: the same arithmetic
//! as their scalar twins (`scalar_add_sample`, the narrow rows of `Map::fixed_spans_from`),
//! lane by lane.

use super::{BlockerBlock, ReceiverBlock, SampleTest, LANES};
use std::arch::x86_64::*;

/// `scalar_add_sample` for the eight lanes at once (the texels by one gather); with
/// `BLOCKERS`, the blockers met too.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn add_sample<const BLOCKERS: bool>(
    b: &ReceiverBlock,
    sums: &mut [[f32; LANES]],
    blockers: &mut BlockerBlock,
    t: &SampleTest<'_>,
    channels: usize,
) {
    let load = |a: &[f32; 8]| unsafe { _mm256_loadu_ps(a.as_ptr()) };
    let depth = load(&b.depth);
    let depth2 = _mm256_mul_ps(depth, depth);
    let dx = _mm256_sub_ps(load(&b.x), _mm256_set1_ps(t.origin[0]));
    let dy = _mm256_sub_ps(load(&b.y), _mm256_set1_ps(t.origin[1]));
    let dist2 = _mm256_fmadd_ps(dx, dx, _mm256_fmadd_ps(dy, dy, depth2));
    let inv_dist = _mm256_div_ps(_mm256_set1_ps(1.0), _mm256_sqrt_ps(dist2));
    let inv_dist2 = _mm256_mul_ps(inv_dist, inv_dist);
    let facing = _mm256_fmadd_ps(load(&b.nx), dx, _mm256_fmadd_ps(load(&b.ny), dy, load(&b.n_dot_z)));
    let cos = _mm256_max_ps(_mm256_sub_ps(_mm256_setzero_ps(), facing), _mm256_setzero_ps());
    let g_depth = _mm256_max_ps(depth, _mm256_setzero_ps());
    let g = _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(cos, g_depth), inv_dist2), inv_dist2);
    let ki = _mm256_mul_ps(_mm256_set1_ps(t.k), _mm256_div_ps(_mm256_set1_ps(1.0), depth));
    let (fx, fy) = (_mm256_mul_ps(dx, ki), _mm256_mul_ps(dy, ki));
    let visible = if t.empty {
        _mm256_castsi256_ps(_mm256_set1_epi32(-1))
    } else {
        let half = _mm256_set1_ps(t.half);
        let clamp = |v: __m256, hi: f32| _mm256_min_ps(_mm256_max_ps(v, _mm256_setzero_ps()), _mm256_set1_ps(hi));
        let tx = clamp(_mm256_sub_ps(_mm256_add_ps(half, fx), _mm256_set1_ps(t.crop[0])), t.last[0]);
        let ty = clamp(_mm256_sub_ps(_mm256_sub_ps(half, fy), _mm256_set1_ps(t.crop[1])), t.last[1]);
        let index =
            _mm256_add_epi32(_mm256_mullo_epi32(_mm256_cvttps_epi32(ty), _mm256_set1_epi32(t.width as i32)), _mm256_cvttps_epi32(tx));
        // Safety: every index is clamped into the map.
        let stored = unsafe { _mm256_i32gather_ps::<4>(t.depths.as_ptr(), index) };
        let magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
        let inside = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(fx, magnitude), half),
            _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(fy, magnitude), half),
        );
        let lhs = _mm256_mul_ps(
            _mm256_fmadd_ps(
                _mm256_sub_ps(_mm256_setzero_ps(), _mm256_mul_ps(depth2, load(&b.bias))),
                inv_dist,
                _mm256_mul_ps(depth, _mm256_set1_ps(t.k)),
            ),
            stored,
        );
        let lit = _mm256_cmp_ps::<_CMP_LE_OQ>(lhs, _mm256_set1_ps(t.near_k));
        if BLOCKERS {
            // A blocked test of a receiver that faces the sample met a blocker at depth
            // near / stored from the light's plane.
            let blocked = _mm256_andnot_ps(lit, _mm256_and_ps(inside, _mm256_cmp_ps::<_CMP_GT_OQ>(g, _mm256_setzero_ps())));
            let depth = _mm256_div_ps(_mm256_set1_ps(t.near_k / t.k), stored);
            let add = |sum: &mut [f32; 8], v: __m256| unsafe {
                _mm256_storeu_ps(sum.as_mut_ptr(), _mm256_add_ps(_mm256_loadu_ps(sum.as_ptr()), _mm256_and_ps(blocked, v)))
            };
            add(&mut blockers.count, _mm256_set1_ps(1.0));
            add(&mut blockers.depth_sum, depth);
        }
        _mm256_or_ps(_mm256_andnot_ps(inside, _mm256_castsi256_ps(_mm256_set1_epi32(-1))), lit)
    };
    let lit = _mm256_and_ps(visible, g);
    for c in 0..channels {
        let w = _mm256_set1_ps(t.weight[c]);
        let (shadowed, unshadowed) = sums.split_at_mut(channels);
        let (s, u) = (&mut shadowed[c], &mut unshadowed[c]);
        unsafe {
            _mm256_storeu_ps(s.as_mut_ptr(), _mm256_fmadd_ps(w, lit, _mm256_loadu_ps(s.as_ptr())));
            _mm256_storeu_ps(u.as_mut_ptr(), _mm256_fmadd_ps(w, g, _mm256_loadu_ps(u.as_ptr())));
        }
    }
}

/// The rows `rows` of a triangle whose box is `count` ≤ 8 texels wide from texel `x0`, in a
/// map of rows of `width` texels: its three edge functions `w` at the first texel's centre,
/// stepping `step_x` a texel and `step_y` a row, and its depth `z + dx·(x − ox) + dy·(y −
/// oy)` (`plane` = [z, ox, dx, oy, dy]), kept where nearer on the texels it covers — the
/// narrow rows of `Map::fixed_spans_from`, with the same integers and the same float
/// operations in the same order (no fused multiply-add): the same bits.
///
/// # Safety
/// The CPU must have AVX2; every row of `rows` holds texels `x0..x0 + count` in `depths`.
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn narrow_triangle(
    depths: &mut [f32],
    width: usize,
    (x0, count): (usize, usize),
    rows: std::ops::Range<usize>,
    mut w: [i64; 3],
    step_x: [i64; 3],
    step_y: [i64; 3],
    [z, ox, dx, oy, dy]: [f32; 5],
) {
    debug_assert!(count <= 8 && x0 + count <= width && rows.end * width <= depths.len());
    // Each edge's steps to lanes 0–3 and 4–7.
    let lanes = step_x.map(|s| (_mm256_setr_epi64x(0, s, 2 * s, 3 * s), _mm256_setr_epi64x(4 * s, 5 * s, 6 * s, 7 * s)));
    let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    let in_row = _mm256_cmpgt_epi32(_mm256_set1_epi32(count as i32), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    let row_bits = (1i32 << count) - 1;
    // The texel centres' x, each first + i (exact), and the part of the depth along the row.
    let px = _mm256_add_ps(_mm256_set1_ps(x0 as f32 + 0.5), _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0));
    let along = _mm256_add_ps(_mm256_set1_ps(z), _mm256_mul_ps(_mm256_set1_ps(dx), _mm256_sub_ps(px, _mm256_set1_ps(ox))));
    for y in rows {
        let (mut low, mut high) = (_mm256_setzero_si256(), _mm256_setzero_si256());
        for k in 0..3 {
            let at = _mm256_set1_epi64x(w[k]);
            low = _mm256_or_si256(low, _mm256_add_epi64(at, lanes[k].0));
            high = _mm256_or_si256(high, _mm256_add_epi64(at, lanes[k].1));
            w[k] += step_y[k];
        }
        // A lane is outside where an edge is negative: the sign bits of the OR.
        let outside = _mm256_movemask_pd(_mm256_castsi256_pd(low)) | (_mm256_movemask_pd(_mm256_castsi256_pd(high)) << 4);
        let covered = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(!outside & row_bits), bits), bits);
        let across = dy * ((y as f32 + 0.5) - oy);
        let drawn = _mm256_add_ps(along, _mm256_set1_ps(across));
        // Safety: the row's texels x0..x0 + count lie in `depths`; the lanes past them are
        // masked out of the load and the store (no fault there).
        unsafe {
            let at = depths.as_mut_ptr().add(y * width + x0);
            let stored = _mm256_maskload_ps(at, in_row);
            _mm256_maskstore_ps(at, covered, _mm256_max_ps(stored, drawn));
        }
    }
}
