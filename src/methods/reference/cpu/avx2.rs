//! The receiver tests of `SampleTest` eight receivers at a time with AVX2 and FMA: the same
//! arithmetic as the scalar twin (`scalar_add_sample`), lane by lane.

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
