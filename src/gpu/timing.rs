//! GPU timestamps per pass, where the adapter has them (lavapipe does). Each pass asks for a
//! scope named by its phase and its own label; where timestamps may also be written inside
//! a pass, `mark` after each dispatch times the dispatches one by one, and `time_encoder`
//! times copies recorded between passes. After the frame the timer resolves the queries and
//! reports milliseconds per phase and per pass.

use super::{GpuContext, GpuError};
use crate::timing::PhaseName;

/// Timestamps one frame may write (with their settling writes, below). A frame with more
/// times its first passes only.
const MAX_QUERIES: u32 = 1024;

/// One timed pass: where its begin and end timestamps are, and the marks written inside it.
struct Scope {
    phase: PhaseName,
    pass: &'static str,
    begin: u32,
    /// (dispatch name, query index), in the order they were written.
    marks: Vec<(&'static str, u32)>,
}

/// GPU time of one pass (or one dispatch inside it) of a phase.
#[derive(Debug, Clone, PartialEq)]
pub struct PassTime {
    pub phase: PhaseName,
    pub pass: &'static str,
    pub ms: f64,
}

pub struct GpuTimer {
    queries: Option<wgpu::QuerySet>,
    inside_passes: bool,
    /// Follow each timestamp that is read with one that is not (`settle`): lavapipe.
    settle: bool,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
    scopes: Vec<Scope>,
    used: u32,
    period_ns: f64,
    /// Passes run on the CPU instead (`cpu_pass`), wall time, reported after the GPU's.
    cpu: Vec<PassTime>,
}

impl GpuTimer {
    pub fn new(gpu: &GpuContext) -> Self {
        let queries = gpu.timestamps.then(|| {
            gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("GpuTimer::queries"),
                ty: wgpu::QueryType::Timestamp,
                count: MAX_QUERIES,
            })
        });
        let size = u64::from(MAX_QUERIES) * 8;
        let resolve = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("GpuTimer::resolve"),
            size,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("GpuTimer::readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            queries,
            inside_passes: gpu.timestamps_inside_passes,
            settle: gpu.software && gpu.timestamps_inside_passes,
            resolve,
            readback,
            scopes: Vec::new(),
            used: 0,
            period_ns: f64::from(gpu.queue.get_timestamp_period()),
            cpu: Vec::new(),
        }
    }

    /// Starts a new frame: forgets the previous frame's scopes.
    pub fn begin_frame(&mut self) {
        self.scopes.clear();
        self.used = 0;
        self.cpu.clear();
    }

    /// Records a pass of a phase that ran on the CPU, by its wall time: a method's work done
    /// there rather than on the device (`reference`'s engine `cpu`) counts in its phase as a
    /// pass does.
    pub fn cpu_pass(&mut self, phase: PhaseName, pass: &'static str, ms: f64) {
        self.cpu.push(PassTime { phase, pass, ms });
    }

    /// `count` fresh query indices, or None when timestamps are off or the frame ran out.
    fn take(&mut self, count: u32) -> Option<u32> {
        self.queries.as_ref()?;
        (self.used + count <= MAX_QUERIES).then(|| {
            self.used += count;
            self.used - count
        })
    }

    fn open(&mut self, phase: PhaseName, pass: &'static str) -> Option<(&wgpu::QuerySet, u32)> {
        let begin = self.take(2)?;
        self.scopes.push(Scope { phase, pass, begin, marks: Vec::new() });
        Some((self.queries.as_ref()?, begin))
    }

    /// Timestamps for a render pass of `phase` labelled `pass`.
    pub fn render_scope(&mut self, phase: PhaseName, pass: &'static str) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        self.open(phase, pass).map(|(query_set, i)| wgpu::RenderPassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        })
    }

    /// Begins a compute pass labelled `pass`, timed as that pass of `phase`.
    pub fn begin_compute_pass<'e>(
        &mut self,
        encoder: &'e mut wgpu::CommandEncoder,
        phase: PhaseName,
        pass: &'static str,
    ) -> wgpu::ComputePass<'e> {
        let timestamp_writes = self.open(phase, pass).map(|(query_set, i)| wgpu::ComputePassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        });
        let mut compute = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(pass), timestamp_writes });
        if let Some((queries, i)) = self.settling() {
            compute.write_timestamp(queries, i);
        }
        compute
    }

    /// A query for a timestamp that is written and never read, right after one that is read,
    /// where timestamps need it (`settle`). lavapipe (Mesa 22.3) carries out a timestamp by
    /// putting it in its rasteriser's queue, behind the draws recorded so far, and records
    /// the time when that queue is next flushed; and a timestamp that is not at the top of
    /// the pipe flushes it, but a dispatch does not. So a compute pass's first timestamp
    /// took the time of the next flush: after the pass's dispatches, unless a barrier came
    /// between (read in `lvp_execute.c` and `lp_setup.c`). A second timestamp at once flushes the
    /// first at the time it is recorded.
    fn settling(&mut self) -> Option<(&wgpu::QuerySet, u32)> {
        if !self.settle {
            return None;
        }
        let i = self.take(1)?;
        Some((self.queries.as_ref()?, i))
    }

    /// Records `record` (copies) straight on `encoder`, timed as pass `pass` of `phase` where
    /// timestamps can be written between passes; untimed elsewhere.
    pub fn time_encoder(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        phase: PhaseName,
        pass: &'static str,
        record: impl FnOnce(&mut wgpu::CommandEncoder),
    ) {
        // `open` gives a scope only where there are queries.
        let begin = if self.inside_passes { self.open(phase, pass).map(|(_, i)| i) } else { None };
        match begin {
            Some(i) => {
                self.write_settled(encoder, i);
                record(encoder);
                self.write_settled(encoder, i + 1);
            }
            None => record(encoder),
        }
    }

    /// Writes timestamp `i` on `encoder`, and one more that settles it (`settling`).
    fn write_settled(&mut self, encoder: &mut wgpu::CommandEncoder, i: u32) {
        if let Some(queries) = &self.queries {
            encoder.write_timestamp(queries, i);
        }
        if let Some((queries, settle)) = self.settling() {
            encoder.write_timestamp(queries, settle);
        }
    }

    /// Ends the dispatch `name` inside the compute pass opened last: its time runs from the
    /// previous mark (or the pass's beginning). Does nothing where the adapter cannot write
    /// timestamps inside passes; the pass is then timed as a whole.
    pub fn mark(&mut self, pass: &mut wgpu::ComputePass<'_>, name: &'static str) {
        if !self.inside_passes || self.scopes.is_empty() {
            return;
        }
        let Some(index) = self.take(1) else { return };
        let (Some(queries), Some(scope)) = (&self.queries, self.scopes.last_mut()) else { return };
        pass.write_timestamp(queries, index);
        scope.marks.push((name, index));
        if let Some((queries, settle)) = self.settling() {
            pass.write_timestamp(queries, settle);
        }
    }

    /// Reads back this frame's passes (dispatches, where marked) in the order they were
    /// recorded, as milliseconds, then the passes run on the CPU (`cpu_pass`). Blocks until
    /// the GPU is done.
    pub fn read(&self, gpu: &GpuContext) -> Result<Vec<PassTime>, GpuError> {
        let mut times = self.read_gpu(gpu)?;
        times.extend(self.cpu.iter().cloned());
        Ok(times)
    }

    /// The passes timed on the device.
    fn read_gpu(&self, gpu: &GpuContext) -> Result<Vec<PassTime>, GpuError> {
        let Some(queries) = &self.queries else { return Ok(Vec::new()) };
        if self.used == 0 {
            return Ok(Vec::new());
        }
        let bytes = u64::from(self.used) * 8;
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("GpuTimer::encoder") });
        encoder.resolve_query_set(queries, 0..self.used, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.readback, 0, bytes);
        gpu.queue.submit([encoder.finish()]);
        let slice = self.readback.slice(..bytes);
        gpu.map_for_reading(&[slice])?;
        let ticks: Vec<u64> = bytemuck::cast_slice(&slice.get_mapped_range().map_err(|e| GpuError::Map(e.to_string()))?).to_vec();
        self.readback.unmap();
        let ms = |from: u32, to: u32| ticks[to as usize].saturating_sub(ticks[from as usize]) as f64 * self.period_ns / 1e6;
        let mut times = Vec::new();
        for scope in &self.scopes {
            let end = scope.begin + 1;
            if scope.marks.is_empty() {
                times.push(PassTime { phase: scope.phase, pass: scope.pass, ms: ms(scope.begin, end) });
                continue;
            }
            // Each dispatch from the previous mark; whatever follows the last mark (barriers,
            // the pass's end) is counted with it, so the dispatches add up to the pass.
            let mut from = scope.begin;
            for (k, &(name, index)) in scope.marks.iter().enumerate() {
                let to = if k + 1 == scope.marks.len() { end } else { index };
                times.push(PassTime { phase: scope.phase, pass: name, ms: ms(from, to) });
                from = index;
            }
        }
        Ok(times)
    }
}
