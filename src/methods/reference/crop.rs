//! The part of each sample's map the frame's receivers can fall in (`crop`): one rectangle
//! for all the maps of a frame, drawn where it saves enough to be worth its rounding.

use glam::{Mat4, UVec2, Vec2, Vec4};

/// Texels of margin around where the receivers fall in a sample's map (`map_bounds`): the
/// accumulate pass finds a receiver's texel by arithmetic of its own, and a G-buffer position
/// may stray from the scene's bounds by a rounding error.
pub(super) const CROP_MARGIN_TEXELS: f32 = 2.0;

/// Crops are whole multiples of this many texels a side, so that frames of one scene and size
/// reuse the pool's layers instead of allocating a new size each (llvmpipe's tiles are 64²).
pub(super) const CROP_GRANULE: u32 = 64;

/// The largest crop drawn, as a fraction of the whole map's area; a larger one draws the
/// whole map. A crop changes the rounding of where texel centres fall in x and y, so a few
/// receivers on an edge seen edge-on may see a sample the other way (0.02 % of a 1080p
/// `terrain` frame); it must save enough to be worth that, and only a crop of at most a
/// quarter of the map saved much of the maps' time (docs/methods.md, `reference`).
pub(super) const MAX_CROP_FRACTION: f32 = 0.25;

/// Which part of each sample's map is drawn: a rectangle of `size` texels of the whole
/// `resolution`² map, at each sample's `origins` (its top-left texel in the whole map; `None`
/// where no receiver of the frame falls in the map). Only texels a receiver can fall in are
/// read, so drawing the rest — clearing and filling it — buys nothing. Within the crop every
/// texel sees the same scene at the same depth as in the whole map: the same frustum, shifted
/// and scaled in x and y only, which leaves the depth as it was (the clip z and w rows are
/// untouched). Only rounding differs: a texel centre on a triangle's edge may fall the other
/// side of it.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct MapCrop {
    pub(super) size: UVec2,
    pub(super) origins: Vec<Option<UVec2>>,
}

impl MapCrop {
    /// Every map whole.
    pub(super) fn whole(samples: usize, resolution: u32) -> Self {
        Self { size: UVec2::splat(resolution), origins: vec![Some(UVec2::ZERO); samples] }
    }

    /// The smallest crop, whole multiples of `CROP_GRANULE` a side, that holds every sample's
    /// receivers (`bounds`, in texels of its whole map) with a margin; the whole map where
    /// that is more than `MAX_CROP_FRACTION` of it.
    pub(super) fn fit(bounds: Vec<Option<(Vec2, Vec2)>>, resolution: u32) -> Self {
        let whole = Vec2::splat(resolution as f32);
        let rects: Vec<Option<(UVec2, UVec2)>> = bounds
            .into_iter()
            .map(|bounds| {
                let (lo, hi) = bounds?;
                let lo = (lo - CROP_MARGIN_TEXELS).floor().clamp(Vec2::ZERO, whole);
                let hi = (hi + CROP_MARGIN_TEXELS).ceil().clamp(Vec2::ZERO, whole);
                (lo.x < hi.x && lo.y < hi.y).then(|| (lo.as_uvec2(), hi.as_uvec2()))
            })
            .collect();
        let extent = rects.iter().flatten().fold(UVec2::ONE, |extent, (lo, hi)| extent.max(*hi - *lo));
        let size =
            UVec2::new(extent.x.next_multiple_of(CROP_GRANULE), extent.y.next_multiple_of(CROP_GRANULE)).min(UVec2::splat(resolution));
        if size.as_vec2().element_product() > MAX_CROP_FRACTION * whole.element_product() {
            return Self::whole(rects.len(), resolution);
        }
        let origins = rects.iter().map(|rect| rect.map(|(lo, _)| lo.min(UVec2::splat(resolution) - size))).collect();
        Self { size, origins }
    }

    /// The projection that draws a crop of the map `view_proj` draws: x and y scaled by
    /// resolution / size and shifted so that whole-map texel `origin + i` lands on crop
    /// texel `i`; `view_proj` itself for a whole map.
    pub(super) fn layer_view_proj(&self, origin: Option<UVec2>, resolution: u32, view_proj: Mat4) -> Mat4 {
        let (Some(origin), false) = (origin, self.size == UVec2::splat(resolution)) else { return view_proj };
        let (whole, crop, o) = (resolution as f32, self.size.as_vec2(), origin.as_vec2());
        Mat4::from_cols(
            Vec4::new(whole / crop.x, 0.0, 0.0, 0.0),
            Vec4::new(0.0, whole / crop.y, 0.0, 0.0),
            Vec4::Z,
            Vec4::new((whole - 2.0 * o.x) / crop.x - 1.0, 1.0 - (whole - 2.0 * o.y) / crop.y, 0.0, 1.0),
        ) * view_proj
    }
}
