//! GPU timestamps per pass, where the adapter has them (lavapipe does). Each pass asks for a
//! scope; after the frame the timer resolves the queries and reports milliseconds per scope.

use super::{GpuContext, GpuError};

/// Passes one frame may time. A frame with more passes times the first ones only.
const MAX_SCOPES: u32 = 64;

pub struct GpuTimer {
    queries: Option<wgpu::QuerySet>,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
    labels: Vec<&'static str>,
    period_ns: f64,
}

impl GpuTimer {
    pub fn new(gpu: &GpuContext) -> Self {
        let queries = gpu.timestamps.then(|| {
            gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("GpuTimer::queries"),
                ty: wgpu::QueryType::Timestamp,
                count: MAX_SCOPES * 2,
            })
        });
        let size = u64::from(MAX_SCOPES) * 2 * 8;
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
        Self { queries, resolve, readback, labels: Vec::new(), period_ns: f64::from(gpu.queue.get_timestamp_period()) }
    }

    /// Starts a new frame: forgets the previous frame's scopes.
    pub fn begin_frame(&mut self) {
        self.labels.clear();
    }

    fn next_pair(&mut self, label: &'static str) -> Option<(&wgpu::QuerySet, u32)> {
        let queries = self.queries.as_ref()?;
        let index = self.labels.len() as u32;
        if index >= MAX_SCOPES {
            return None;
        }
        self.labels.push(label);
        Some((queries, index * 2))
    }

    pub fn render_scope(&mut self, label: &'static str) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        self.next_pair(label).map(|(query_set, i)| wgpu::RenderPassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        })
    }

    pub fn compute_scope(&mut self, label: &'static str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        self.next_pair(label).map(|(query_set, i)| wgpu::ComputePassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        })
    }

    /// Reads back this frame's scopes as (label, milliseconds). Blocks until the GPU is done.
    pub fn read(&self, gpu: &GpuContext) -> Result<Vec<(&'static str, f64)>, GpuError> {
        let Some(queries) = &self.queries else { return Ok(Vec::new()) };
        if self.labels.is_empty() {
            return Ok(Vec::new());
        }
        let count = self.labels.len() as u32 * 2;
        let bytes = u64::from(count) * 8;
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("GpuTimer::encoder") });
        encoder.resolve_query_set(queries, 0..count, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.readback, 0, bytes);
        gpu.queue.submit([encoder.finish()]);
        let slice = self.readback.slice(..bytes);
        gpu.map_for_reading(&[slice])?;
        let ticks: Vec<u64> = bytemuck::cast_slice(&slice.get_mapped_range().map_err(|e| GpuError::Map(e.to_string()))?).to_vec();
        self.readback.unmap();
        Ok(self
            .labels
            .iter()
            .enumerate()
            .map(|(k, label)| {
                let elapsed = ticks[2 * k + 1].saturating_sub(ticks[2 * k]);
                (*label, elapsed as f64 * self.period_ns / 1e6)
            })
            .collect())
    }
}
