//! Bands of rows: a frame worked on in parts, so that the per-pixel working memory of the
//! methods that work on the CPU (`reference`'s CPU engine, `filtered`) stays within
//! `Limits::max_cpu_working_bytes` whatever the frame's size.
//!
//! Every band sees the same samples, maps and crops as the whole frame would (a map is drawn
//! again for each band), so banding changes no pixel: a band's pixels depend only on rows
//! within its `reach` (the rows it writes, `rows`, and a `halo` of rows either side that a
//! filter reads).

use std::ops::Range;

/// Rows of the frame a band writes, and the rows it works on to write them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Band {
    pub rows: Range<u32>,
    /// `rows` and up to `halo` rows either side, within the frame.
    pub reach: Range<u32>,
}

impl Band {
    /// The band's `rows`, counted from the start of its `reach`.
    pub fn written(&self) -> Range<u32> {
        self.rows.start - self.reach.start..self.rows.end - self.reach.start
    }
}

/// The frame (`width` × `height`) cut into as few bands as keep each band's `reach` within
/// `budget` bytes at `bytes_per_pixel`, of equal heights, each a multiple of `align` rows
/// (the last one shorter) and at least `align` rows however small the budget.
pub(super) fn bands(width: u32, height: u32, bytes_per_pixel: u64, budget: u64, halo: u32, align: u32) -> Vec<Band> {
    let row_bytes = u64::from(width) * bytes_per_pixel;
    let whole = u64::from(height) * row_bytes;
    if whole <= budget || height <= align {
        return vec![Band { rows: 0..height, reach: 0..height }];
    }
    // The rows a band may write once its halo is counted.
    let fits = (budget / row_bytes.max(1)).saturating_sub(2 * u64::from(halo)) as u32;
    let most = (fits / align * align).max(align);
    let count = height.div_ceil(most);
    let rows = height.div_ceil(count).next_multiple_of(align);
    (0..height)
        .step_by(rows as usize)
        .map(|start| {
            let end = (start + rows).min(height);
            Band { rows: start..end, reach: start.saturating_sub(halo)..(end + halo).min(height) }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_within_the_budget_is_one_band() {
        assert_eq!(bands(1920, 1080, 100, 512 << 20, 64, 8), vec![Band { rows: 0..1080, reach: 0..1080 }]);
    }

    #[test]
    fn bands_cover_every_row_once_and_their_reach_fits() {
        for (width, height, budget, halo) in
            [(4096, 2048, 128 << 20, 0), (4096, 2048, 100 << 20, 64), (300, 1001, 1 << 20, 64), (64, 9, 1, 4)]
        {
            let cut = bands(width, height, 100, budget, halo, 8);
            assert!(cut.len() > 1, "{width}×{height} in {budget} bytes");
            let mut next = 0;
            for band in &cut {
                assert_eq!(band.rows.start, next, "{cut:?}");
                assert!(band.rows.start % 8 == 0 && !band.rows.is_empty(), "{cut:?}");
                assert!(band.reach.start <= band.rows.start && band.reach.end >= band.rows.end);
                assert_eq!(band.reach.start, band.rows.start.saturating_sub(halo));
                assert_eq!(band.reach.end, (band.rows.end + halo).min(height));
                let written = band.written();
                assert_eq!(written.start + band.reach.start..written.end + band.reach.start, band.rows);
                let bytes = u64::from(band.reach.len() as u32) * u64::from(width) * 100;
                assert!(bytes <= budget || band.rows.len() <= 8, "{band:?}: {bytes} bytes");
                next = band.rows.end;
            }
            assert_eq!(next, height);
        }
    }
}
