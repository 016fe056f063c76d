//! Engine `gpu` of method `filtered`: its tests on the device — the reference's maps
//! (`DepthMaps`) and test (`filtered_main` in `accumulate.wgsl`) over the row segments the CPU
//! lists — read back for the classification and the filter, which stay the CPU engine's own
//! (`filter.rs`). On a GPU the maps and tests are the work; what the CPU adds is a pass or two
//! over the frame's pixels.

use glam::UVec2;

use super::super::gpu::{batch_layers, maps_entry, BatchUniforms, DepthMaps, SEGMENT};
use super::super::samples::SamplePlan;
use super::super::{MethodContext, Params, Progress};
use super::Tested;
use crate::error::JobResult;
use crate::gpu::layout;
use crate::timing::PhaseName;

/// A batch: consecutive samples of one round's half, drawn into the maps' layers and tested
/// by one pass.
struct Batch {
    /// Its first sample among the engine's (its map's slot).
    first: usize,
    count: u32,
    half: u32,
    /// Its uniforms' slot.
    uniform: usize,
}

/// The device's share of a frame of `filtered`: every sample's map and test, in the order of
/// the rounds (the probes, then the rest) and, within a round, of the halves.
pub(super) struct DeviceTests {
    maps: DepthMaps,
    uniforms: wgpu::Buffer,
    rounds: [Vec<Batch>; 2],
    /// Each sample's crop origin (`None`: its map is empty), in the engine's order.
    origins: Vec<Option<UVec2>>,
    channels: u32,
    cropped: bool,
}

impl DeviceTests {
    /// The maps and batches of `plan`'s samples, `rounds[round][half]` listing each round's
    /// and half's samples by their place in the plan, in order.
    pub(super) fn new(ctx: &mut MethodContext<'_>, plan: &SamplePlan, params: &Params, rounds: &[[Vec<usize>; 2]; 2]) -> Self {
        let (view_projs, slots) = plan.slots();
        let order: Vec<usize> = rounds.iter().flatten().flatten().copied().collect();
        let layers = batch_layers(plan.resolution).min(order.len().max(1) as u32);
        let (mut uniforms, mut batches, mut first) = (Vec::new(), [Vec::new(), Vec::new()], 0);
        for (round, halves) in rounds.iter().enumerate() {
            for (half, samples) in halves.iter().enumerate().filter(|(_, samples)| !samples.is_empty()) {
                let slots: Vec<_> = samples.iter().map(|&i| slots[i]).collect();
                for (count, batch) in plan.batches(&slots, layers, params) {
                    batches[round].push(Batch { first, count, half: half as u32, uniform: uniforms.len() });
                    uniforms.push(batch);
                    first += count as usize;
                }
            }
        }
        let view_projs: Vec<_> = order.iter().map(|&i| view_projs[i]).collect();
        Self {
            maps: DepthMaps::new(ctx, plan.crop.size, layers, &view_projs),
            uniforms: layout::uniform_slots::<BatchUniforms>(&ctx.gpu.device, "Filtered::batches", &uniforms),
            rounds: batches,
            origins: order.iter().map(|&i| plan.crop.origins[i]).collect(),
            channels: plan.channels(),
            cropped: plan.crop.size != UVec2::splat(plan.resolution),
        }
    }

    /// Floats of a lane's record: each half's Σ L·G·V and Σ L·G per channel, then the
    /// blockers met (count, summed depth).
    pub(super) fn record_floats(&self) -> usize {
        4 * self.channels as usize + 2
    }

    /// Tests the covered pixels of the row segments `segments` (each the frame's index of its
    /// first pixel) against the `tested` samples, the first of them the `before`-th of the
    /// frame's for `progress`, and hands `read` each listed lane's record (`record_floats`
    /// each, lane `SEGMENT · s + l` the `l`-th pixel of segment `s`; an uncovered pixel's is
    /// 0). Stops between batches once the job is cancelled.
    pub(super) fn test(
        &self,
        ctx: &mut MethodContext<'_>,
        tested: Tested,
        segments: &[u32],
        (before, progress): (u64, &mut Progress<'_>),
        read: impl FnOnce(&[f32]),
    ) -> JobResult<()> {
        let batches = match tested {
            Tested::Probes => &self.rounds[0],
            Tested::Others => &self.rounds[1],
            // `render_band` asks for it only where the CPU engine found tiles lit.
            Tested::ProbesUnmapped => unreachable!("the device tests no unmapped probes"),
        };
        if segments.is_empty() || batches.is_empty() {
            return Ok(());
        }
        let device = ctx.gpu.device.clone();
        let list = {
            use wgpu::util::DeviceExt as _;
            let words: Vec<u32> = std::iter::once(segments.len() as u32).chain(segments.iter().copied()).collect();
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("Filtered::segments"),
                contents: bytemuck::cast_slice(&words),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let lanes = segments.len() as u64 * u64::from(SEGMENT);
        let bytes = lanes * self.record_floats() as u64 * 4;
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let records = ctx.scratch_buffer("Filtered::records", bytes, usage);
        ctx.encoder.clear_buffer(&records, 0, None);
        let grid = crate::render::list_grid(lanes);
        let mut done = before;
        for batch in batches {
            let range = batch.first..batch.first + batch.count as usize;
            self.maps.draw(ctx, "filtered_maps", batch.first, &self.origins[range]);
            let pipeline = ctx.screen_specialized(
                "filtered.accumulate",
                ("methods/reference/accumulate.wgsl", "filtered_main"),
                &[layout::uniform_dynamic(0), maps_entry(), layout::storage_read_write(4), layout::storage_read_write(6)],
                &[
                    ("SAMPLES", f64::from(batch.count)),
                    ("CHANNELS", f64::from(self.channels)),
                    ("CROPPED", f64::from(u8::from(self.cropped))),
                    ("HALF", f64::from(batch.half)),
                    ("BLOCKERS", 1.0),
                ],
            );
            // Bindings 0, 1, 4 and 6: numbered as the reference's (`accumulate.wgsl`).
            let resources = [
                (0, layout::slot_binding::<BatchUniforms>(&self.uniforms)),
                (1, wgpu::BindingResource::TextureView(&self.maps.array_view)),
                (4, list.as_entire_binding()),
                (6, records.as_entire_binding()),
            ];
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("Filtered::accumulate"),
                layout: &pipeline.get_bind_group_layout(1),
                entries: &resources.map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource }),
            });
            let mut pass = ctx.timer.begin_compute_pass(ctx.encoder, PhaseName::Method, "filtered_accumulate");
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &ctx.inputs.bind_group, &[]);
            pass.set_bind_group(1, &group, &[layout::slot_offset_of::<BatchUniforms>(batch.uniform)]);
            pass.dispatch_workgroups(grid.0, grid.1, 1);
            drop(pass);
            done += u64::from(batch.count);
            if progress.reaches(done) {
                ctx.flush()?;
                ctx.supervisor.progress(done, progress.total);
                // Cancelled: the renderer discards this frame.
                if ctx.supervisor.cancelled() {
                    break;
                }
            }
        }
        ctx.flush()?;
        crate::gpu::readback::read_buffer_with(ctx.gpu, &records, |bytes| read(bytemuck::cast_slice(bytes)))?;
        Ok(())
    }
}
