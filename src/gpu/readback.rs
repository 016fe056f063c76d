//! Copies a frame's screen-space images (storage buffers, `render::targets`) back to the
//! CPU, all of them in one submission, through buffers from a `ReadbackPool`.

use super::pool::ReadbackPool;
use super::{GpuContext, GpuError};

pub struct Readback {
    pending: Vec<wgpu::Buffer>,
}

impl Readback {
    pub fn new() -> Self {
        Self { pending: Vec::new() }
    }

    /// Records a copy of a whole storage buffer (`COPY_SRC`) and returns its index in
    /// `finish`'s result.
    pub fn copy_buffer(
        &mut self,
        gpu: &GpuContext,
        pool: &mut ReadbackPool,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::Buffer,
    ) -> usize {
        let size = source.size();
        let buffer = pool.alloc(&gpu.device, size);
        encoder.copy_buffer_to_buffer(source, 0, &buffer, 0, size);
        self.pending.push(buffer);
        self.pending.len() - 1
    }

    /// Waits for the copies (submitted by the caller) and returns each buffer's bytes. The
    /// buffers go back to `pool` unless a map failed (then they are dropped: their state is
    /// unknown).
    pub fn finish(self, gpu: &GpuContext, pool: &mut ReadbackPool) -> Result<Vec<Vec<u8>>, GpuError> {
        let slices: Vec<wgpu::BufferSlice<'_>> = self.pending.iter().map(|buffer| buffer.slice(..)).collect();
        gpu.map_for_reading(&slices)?;
        let mut images = Vec::with_capacity(self.pending.len());
        for buffer in self.pending {
            let bytes = buffer.slice(..).get_mapped_range().map_err(|e| GpuError::Map(e.to_string()))?.to_vec();
            buffer.unmap();
            pool.release(buffer);
            images.push(bytes);
        }
        Ok(images)
    }
}

impl Default for Readback {
    fn default() -> Self {
        Self::new()
    }
}

/// Copies a (small) storage buffer back to the CPU and waits for it.
pub fn read_buffer(gpu: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    read_buffer_with(gpu, buffer, <[u8]>::to_vec)
}

/// Copies a storage buffer back to the CPU, waits for it and hands its bytes to `read` where
/// they were mapped (a large buffer is not copied again).
pub fn read_buffer_with<R>(gpu: &GpuContext, buffer: &wgpu::Buffer, read: impl FnOnce(&[u8]) -> R) -> Result<R, GpuError> {
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("Readback::staging"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Readback::encoder") });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, buffer.size());
    gpu.queue.submit([encoder.finish()]);
    gpu.map_for_reading(&[staging.slice(..)])?;
    let read = read(&staging.slice(..).get_mapped_range().map_err(|e| GpuError::Map(e.to_string()))?);
    staging.unmap();
    Ok(read)
}
