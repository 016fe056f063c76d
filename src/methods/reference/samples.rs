//! The reference's light samples and their plan: the first points of a nested, stratified
//! sequence on the light's emitting texels with their weights, each sample's frustum and map,
//! in batches.

use bytemuck::Zeroable as _;
use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::crop::MapCrop;
use super::gpu::{BatchSample, BatchUniforms};
use super::{Counters, MethodContext, Params, BIAS_TEXELS, CROP, RESOLUTION, SAMPLES, SEED, SLOPE_BIAS_TEXELS};
use crate::gpu::pool::DerivedKey;
use crate::gpu::scene::GpuScene;
use crate::light::{AreaLight, LightImage};
use crate::render::convex::{map_bounds, ConvexSolid};
use crate::render::{FrameSpec, LightProjection};
use crate::scene::Extent;

/// The points of the sequence a plan's near plane and crop are made for: every sample a
/// reference can take (`samples`' maximum).
const PLANNED: u32 = super::MAX_SAMPLES;

/// The projection a sample's depth map is drawn with: the angle `fit` gives that sample and the
/// near plane every map shares, reversed-Z with the far plane at infinity, so the stored depth
/// is `near / view depth` (`sample_depth.wgsl`) and float depth keeps the same relative
/// precision at every distance.
pub(super) fn reversed_projection(tan_half: f32, near: f32) -> Mat4 {
    Mat4::perspective_infinite_reverse_rh(2.0 * tan_half.atan(), 1.0, near)
}

/// The rotation into every sample's view coordinates: each frustum looks along the light
/// normal with the image's up, from its own sample point.
pub(super) fn sample_rotation(light: &AreaLight) -> Mat4 {
    Mat4::look_to_rh(Vec3::ZERO, light.n, light.u)
}

/// A point on the light and its weight: `L(y)` times the area of its stratum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    pub position: Vec3,
    pub weight: Vec3,
}

/// The reference's samples: the first `requested` points of one sequence over the light
/// (`sequence_point`), those on black texels skipped, each with its half (`half_of_index`).
/// The samples of fewer are the first of more — a progressive job's rounds add samples to the
/// sums without changing those already taken — and a weight does not depend on how many there
/// are (`L(y)` times the light's area: the ratio estimator divides the count out). Returns the
/// samples, each one's index in the sequence (its half: `half_of_index`) and how many points
/// were drawn (black ones included).
pub fn light_samples(light: &AreaLight, image: &LightImage, requested: u32, seed: u64) -> (Vec<LightSample>, Vec<u32>, u32) {
    let scrambles = scramble_seeds(seed);
    let area = light.area_m2();
    let (mut samples, mut indices) = (Vec::with_capacity(requested as usize), Vec::with_capacity(requested as usize));
    for i in 0..requested {
        let half = half_of_index(i);
        let (s, t) = sequence_point(i >> 1, scrambles[usize::from(half)]);
        let (ti, tj) = image.texel_at(s, t);
        let emission = image.emission(ti, tj);
        if emission.max_element() <= 0.0 {
            continue;
        }
        samples.push(LightSample { position: light.image_point(s, t), weight: emission * light.intensity * area });
        indices.push(i);
    }
    (samples, indices, requested)
}

/// Which half of the reference's samples sample `i` is in: the even ones and the odd ones,
/// each its own sequence (`light_samples`). The halves are two independent randomisations of
/// one stratified sequence — randomised quasi-Monte Carlo's replicates (Owen 1997) — so half
/// their difference estimates the whole's error without bias. Halves cut from one sequence
/// (its blocks, say) would not do: its later points fill exactly the strata its earlier ones
/// left empty, so each half alone is badly stratified and the halves differ by far more than
/// the whole errs (measured: docs/performance-log.md).
pub fn half_of_index(i: u32) -> bool {
    i & 1 == 1
}

/// Point `i` of a sequence in the unit square: the first two dimensions of Sobol's sequence
/// (van der Corput's radical inverse, and the Pascal-matrix dimension), each Owen-scrambled
/// by a hash of `scramble` (Burley 2020, "Practical Hash-based Owen Scrambling"). Sobol's 2D
/// sequence is a (0,2)-sequence: every aligned block of 2^k points — a prefix of 2^k points
/// among them — has one point in each of the 2^k elementary boxes of any shape (k even: a
/// √2^k-square grid), and Owen scrambling keeps that while making every point uniform. So any
/// prefix is stratified as finely as its length allows, where a jittered grid is stratified
/// only at the count it was made for.
pub(super) fn sequence_point(i: u32, (seed_x, seed_y): (u32, u32)) -> (f32, f32) {
    let x = i.reverse_bits();
    let mut y = 0u32;
    let (mut bits, mut column) = (i, 1u32 << 31);
    while bits != 0 {
        if bits & 1 == 1 {
            y ^= column;
        }
        bits >>= 1;
        column ^= column >> 1;
    }
    let unit = |v: u32| (v >> 8) as f32 / (1u32 << 24) as f32;
    (unit(owen_scramble(x, seed_x)), unit(owen_scramble(y, seed_y)))
}

/// The scrambling seeds of the two halves' sequences, one per dimension each, from the job's
/// seed.
fn scramble_seeds(seed: u64) -> [(u32, u32); 2] {
    let mut rng = SplitMix64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15).wrapping_add(1));
    let mut pair = || {
        let word = rng.next_u64();
        (word as u32, (word >> 32) as u32)
    };
    [pair(), pair()]
}

/// Owen scrambling of a fixed-point number in [0, 1): each digit flipped by a hash of the
/// digits above it, by Laine and Karras' hash on the bit-reversed value (Burley 2020, §3).
fn owen_scramble(v: u32, seed: u32) -> u32 {
    let mut x = v.reverse_bits();
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x.reverse_bits()
}

/// splitmix64: a tiny, well-mixed generator whose stream never changes between versions.
pub(super) struct SplitMix64(u64);

impl SplitMix64 {
    pub(super) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
}

/// What a reference's whole plan follows from: the light and its image, the seed, the maps'
/// resolution and crop, the scene's bounds and the camera's view of them.
fn plan_fingerprint(ctx: &MethodContext<'_>, params: &Params) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    let light = &ctx.spec.light;
    let vectors = [light.center, light.n, light.u, light.r, ctx.scene.bounds_min, ctx.scene.bounds_max];
    for v in vectors.iter().chain(&ctx.scene.shadow_fit_points(light)) {
        v.to_array().map(f32::to_bits).hash(&mut hasher);
    }
    (light.size_m.to_array().map(f32::to_bits), light.intensity.to_bits()).hash(&mut hasher);
    ctx.spec.light_image.fingerprint().hash(&mut hasher);
    (params.get(&SEED), params.get(&RESOLUTION), params.get(&CROP), ctx.width, ctx.height).hash(&mut hasher);
    ctx.spec.camera.view_proj(ctx.width as f32 / ctx.height as f32).to_cols_array().map(f32::to_bits).hash(&mut hasher);
    hasher.finish()
}

/// Each sample's whole map from its point on the light (`positions`): its view-projection and
/// its texels per unit of tan from the map's centre; with the near plane every map shares.
/// Each frustum's angle is fitted to the scene (`corners`: `gpu::scene::shadow_fit_points`) from
/// its point, and one near plane serves every map (the nearest any fit allows), so that the
/// accumulate pass reads it once per pixel, not per sample.
fn frusta(light: &AreaLight, positions: &[Vec3], corners: &[Vec3], resolution: u32) -> (f32, Vec<(Mat4, f32)>) {
    let rotation = sample_rotation(light);
    // On every core: a reference's plan is made for all 4,096 samples it may take.
    let fits: Vec<LightProjection> =
        positions.par_iter().map(|&center| LightProjection::fit(&AreaLight { center, ..*light }, corners)).collect();
    let near = fits.iter().map(|fit| fit.near).reduce(f32::min).unwrap_or(1.0);
    let frusta = positions
        .iter()
        .zip(&fits)
        .map(|(position, fit)| {
            let view = rotation * Mat4::from_translation(-*position);
            let proj = reversed_projection(fit.tan_half, near);
            (proj * view, proj.y_axis.y * resolution as f32 * 0.5)
        })
        .collect();
    (near, frusta)
}

/// The crop of the maps `frusta` draw that holds every receiver of a frame seen through
/// `camera_view_proj`: every receiver (a G-buffer position) lies in what the camera sees of
/// the scene's bounds.
fn receivers_crop(camera_view_proj: Mat4, extent: &Extent, frusta: &[(Mat4, f32)], resolution: u32) -> MapCrop {
    let receivers = ConvexSolid::frustum(camera_view_proj).intersect(&ConvexSolid::cuboid(extent.bounds_min, extent.bounds_max));
    MapCrop::fit(frusta.par_iter().map(|(view_proj, ..)| map_bounds(&receivers, *view_proj, resolution)).collect(), resolution)
}

/// The share of each sample map's texels a reference frame of this view draws (its crop's
/// area over the whole map's; 1 where the maps are drawn whole), predicted before the scene is
/// uploaded, for the model's cost (`model::Features`): the plan's own crop, made for nine
/// points of the light's rectangle (its corners, its edges' midpoints and its centre) in place
/// of its samples. The samples lie inside the rectangle, whose corners' maps reach furthest,
/// so this is the crop of a light that emits everywhere: a light with dark parts may crop
/// tighter.
pub fn predicted_map_share(camera_view_proj: Mat4, light: &AreaLight, extent: &Extent, resolution: u32) -> f64 {
    let positions: Vec<Vec3> = [0.0f32, 0.5, 1.0].into_iter().flat_map(|s| [0.0f32, 0.5, 1.0].map(|t| light.image_point(s, t))).collect();
    let (_, frusta) = frusta(light, &positions, &crate::gpu::scene::shadow_fit_points(extent, light), resolution);
    let crop = receivers_crop(camera_view_proj, extent, &frusta, resolution);
    f64::from(crop.size.element_product()) / f64::from(resolution).powi(2)
}

/// A frame's light samples and how each one's map is drawn and read.
#[derive(Clone)]
pub(super) struct SamplePlan {
    pub(super) samples: Vec<LightSample>,
    /// Each sample's index in the sequence (its half: `half_of_index`; the CPU engine keeps
    /// the halves' sums apart for its error estimate).
    pub(super) indices: Vec<u32>,
    /// Strata of the light, black ones included (`samples_skipped_black`).
    pub(super) strata: u32,
    pub(super) resolution: u32,
    /// Into every sample's view coordinates (`sample_rotation`).
    pub(super) rotation: Mat4,
    /// The near plane every map shares.
    pub(super) near: f32,
    /// Every sample point's z in view coordinates: they all lie on the light's plane.
    pub(super) plane: f32,
    /// Per sample, its whole map's view-projection and its texels per unit of tan from the
    /// map's centre.
    pub(super) frusta: Vec<(Mat4, f32)>,
    pub(super) crop: MapCrop,
    channels: u32,
}

impl SamplePlan {
    /// The reference's plan: its first `samples` of the sequence, with the near plane and crop
    /// of the sequence's every possible sample (`PLANNED`), so that the plan of fewer samples
    /// is the first part of the plan of more, map for map (a progressive job's rounds). The
    /// whole plan is kept for later frames of the same view, light and maps (`ctx.derived`):
    /// a progressive job's rounds, and a daemon's repeated jobs, make it once.
    pub(super) fn new(ctx: &mut MethodContext<'_>, params: &Params) -> Self {
        Self::first(ctx, params, params.get(&SAMPLES))
    }

    /// The plan of the sequence's first `requested` points (`new`'s, for a count of one's own:
    /// method `filtered`'s).
    pub(super) fn first(ctx: &mut MethodContext<'_>, params: &Params, requested: u32) -> Self {
        let spec = ctx.spec;
        let seed = u64::from(params.get(&SEED));
        let key = DerivedKey { name: "reference.plan", fingerprint: plan_fingerprint(ctx, params) };
        let (scene, size) = (ctx.scene, (ctx.width, ctx.height));
        let planned = ctx.derived.get_or_create(key, || {
            let (planned, indices, _) = light_samples(&spec.light, &spec.light_image, PLANNED, seed);
            Self::plan(spec, scene, size, params, (planned, indices), PLANNED)
        });
        let requested = requested.min(PLANNED);
        let mut plan = (*planned).clone();
        // The first `requested` points of the sequence, less the black ones.
        plan.keep_first(planned.indices.partition_point(|&i| i < requested), requested);
        plan
    }

    /// The plan of these samples and their indices in the sequence (of `strata` points, black
    /// ones included) for a frame of `spec` on `scene`, `size` pixels, with the maps'
    /// resolution, crop and bias of `params`.
    fn plan(
        spec: &FrameSpec,
        scene: &GpuScene,
        (width, height): (u32, u32),
        params: &Params,
        (samples, indices): (Vec<LightSample>, Vec<u32>),
        strata: u32,
    ) -> Self {
        let resolution = params.get(&RESOLUTION);
        let rotation = sample_rotation(&spec.light);
        let positions: Vec<Vec3> = samples.iter().map(|sample| sample.position).collect();
        let (near, frusta) = frusta(&spec.light, &positions, &scene.shadow_fit_points(&spec.light), resolution);
        let plane = rotation.transform_point3(spec.light.center).z;
        let crop = if params.get(&CROP) {
            receivers_crop(spec.camera.view_proj(width as f32 / height as f32), &scene.extent(), &frusta, resolution)
        } else {
            MapCrop::whole(samples.len(), resolution)
        };
        // One channel where every weight is gray (its three sums would be equal), else three.
        let channels = if samples.iter().all(|s| s.weight.x == s.weight.y && s.weight.x == s.weight.z) { 1 } else { 3 };
        Self { samples, indices, strata, resolution, rotation, near, plane, frusta, crop, channels }
    }

    /// The samples' effective count (`estimate::effective_samples`).
    pub(super) fn effective_samples(&self) -> f32 {
        super::estimate::effective_samples(self.samples.iter().map(|s| s.weight))
    }

    /// Keeps the first `count` samples (of `strata` points drawn), with the near plane and
    /// crop planned for all of them.
    fn keep_first(&mut self, count: usize, strata: u32) {
        self.samples.truncate(count);
        self.indices.truncate(count);
        self.frusta.truncate(count);
        self.crop.origins.truncate(count);
        self.strata = strata;
    }

    /// Per sample: its map's projection (the depth pass) and what the accumulate pass needs.
    pub(super) fn slots(&self) -> (Vec<[[f32; 4]; 4]>, Vec<BatchSample>) {
        self.samples
            .iter()
            .zip(&self.frusta)
            .zip(&self.crop.origins)
            .map(|((sample, (view_proj, texels_per_tan)), origin)| {
                // The crop's first texel, x and y in one word: indices under 2¹² leave the float
                // exponent short of all ones, so the word is never a NaN to be canonicalised.
                let crop_origin = origin.map_or(0, |o| o.x | o.y << 16);
                let view = self.rotation.transform_point3(sample.position);
                let slot = BatchSample {
                    origin: [view.x, view.y, f32::from_bits(crop_origin), 0.0],
                    radiance: sample.weight.extend(*texels_per_tan).to_array(),
                };
                (self.crop.layer_view_proj(*origin, self.resolution, *view_proj).to_cols_array_2d(), slot)
            })
            .unzip()
    }

    /// What every test of the CPU engine shares, with the bias of `params`.
    pub(super) fn test_constants(&self, params: &Params, light_center: Vec3) -> super::cpu::TestConstants {
        super::cpu::TestConstants {
            rotation: self.rotation,
            plane: self.plane,
            near: self.near,
            resolution: self.resolution,
            bias_texels: params.get(&BIAS_TEXELS),
            slope_bias_texels: params.get(&SLOPE_BIAS_TEXELS),
            light_center,
        }
    }

    /// Each sample as the CPU engine draws and reads it: as the GPU engine's accumulate pass
    /// reads it, with its crop's projection.
    pub(super) fn cpu_samples(&self) -> Vec<super::cpu::CpuSample> {
        let (view_projs, slots) = self.slots();
        slots
            .iter()
            .zip(&view_projs)
            .zip(&self.crop.origins)
            .map(|((slot, view_proj), origin)| super::cpu::CpuSample {
                view_proj: Mat4::from_cols_array_2d(view_proj),
                origin: [slot.origin[0], slot.origin[1]],
                texels_per_tan: slot.radiance[3],
                crop_origin: *origin,
                weight: Vec3::from_slice(&slot.radiance[..3]),
            })
            .collect()
    }

    /// The accumulate passes' uniforms, `layers` samples a pass (the last may hold fewer),
    /// each with its count of samples. No samples (a black light): one empty batch, whose
    /// ratio is 1 everywhere.
    pub(super) fn batches(&self, slots: &[BatchSample], layers: u32, params: &Params) -> Vec<(u32, BatchUniforms)> {
        let chunks: Vec<&[BatchSample]> = if slots.is_empty() { vec![&[]] } else { slots.chunks(layers as usize).collect() };
        chunks
            .into_iter()
            .map(|chunk| {
                let mut batch = BatchUniforms::zeroed();
                batch.rotation = [0, 1, 2].map(|i| self.rotation.row(i).to_array());
                batch.resolution = self.resolution;
                batch.bias_texels = params.get(&BIAS_TEXELS);
                batch.slope_bias_texels = params.get(&SLOPE_BIAS_TEXELS);
                batch.plane = self.plane;
                batch.near = self.near;
                batch.samples[..chunk.len()].copy_from_slice(chunk);
                (chunk.len() as u32, batch)
            })
            .collect()
    }

    /// The counters either engine reports: samples taken and left out, the row segments
    /// tested, the maps' resolution and the part of each map drawn.
    pub(super) fn counters(&self, segments_tested: u32, ctx: &MethodContext<'_>) -> Counters {
        let total = self.samples.len() as f64;
        // The triangles each map draws: the bounding ones the light lies beyond are left out.
        let runs = ctx.scene.casting_runs(&ctx.spec.light);
        let map_triangles: u32 = runs.iter().map(|run| (run.end - run.start) / 3).sum();
        Counters::from([
            ("map_triangles".to_owned(), f64::from(map_triangles)),
            ("samples".to_owned(), total),
            ("segments_tested".to_owned(), f64::from(segments_tested)),
            ("samples_skipped_black".to_owned(), f64::from(self.strata) - total),
            ("resolution".to_owned(), f64::from(self.resolution)),
            ("map_crop_fraction".to_owned(), f64::from(self.crop.size.element_product()) / f64::from(self.resolution).powi(2)),
        ])
    }

    /// Channels of the sums: one where every sample planned for has a gray weight (its three
    /// sums would be equal), else three — of all the samples planned for, so that a plan of
    /// fewer keeps its sums as a plan of more does.
    pub(super) fn channels(&self) -> u32 {
        self.channels
    }
}
