//! Copies render targets back to the CPU: row padding to the 256-byte copy alignment on the
//! way out, removed on the way in, all targets of a frame in one submission, through buffers
//! from a `ReadbackPool`.

use super::pool::ReadbackPool;
use super::{GpuContext, GpuError};

pub struct Readback {
    pending: Vec<(wgpu::Buffer, u32, u32, u32)>, // buffer, padded row bytes, row bytes, rows
}

impl Readback {
    pub fn new() -> Self {
        Self { pending: Vec::new() }
    }

    /// Records a copy of `texture` and returns its index in `finish`'s result.
    pub fn copy(
        &mut self,
        gpu: &GpuContext,
        pool: &mut ReadbackPool,
        encoder: &mut wgpu::CommandEncoder,
        texture: &wgpu::Texture,
    ) -> usize {
        // Readbacks are of colour targets, which always have a block size.
        let block = texture.format().block_copy_size(Some(wgpu::TextureAspect::All)).unwrap_or(16);
        let row_bytes = texture.width() * block;
        let padded = row_bytes.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = pool.alloc(&gpu.device, u64::from(padded) * u64::from(texture.height()));
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded), rows_per_image: None },
            },
            texture.size(),
        );
        self.pending.push((buffer, padded, row_bytes, texture.height()));
        self.pending.len() - 1
    }

    /// Records a copy of a whole storage buffer (`COPY_SRC`) and returns its index in
    /// `finish`'s result.
    pub fn copy_buffer(&mut self, gpu: &GpuContext, pool: &mut ReadbackPool, encoder: &mut wgpu::CommandEncoder, source: &wgpu::Buffer) -> usize {
        let size = source.size();
        let buffer = pool.alloc(&gpu.device, size);
        encoder.copy_buffer_to_buffer(source, 0, &buffer, 0, size);
        // One "row" of the whole buffer: nothing to unpad.
        let bytes = u32::try_from(size).expect("a frame's buffer fits in u32 bytes");
        self.pending.push((buffer, bytes, bytes, 1));
        self.pending.len() - 1
    }

    /// Waits for the copies (submitted by the caller) and returns each texture's tightly
    /// packed bytes, top row first. The buffers go back to `pool` unless a map failed (then
    /// they are dropped: their state is unknown).
    pub fn finish(self, gpu: &GpuContext, pool: &mut ReadbackPool) -> Result<Vec<Vec<u8>>, GpuError> {
        let slices: Vec<wgpu::BufferSlice<'_>> = self.pending.iter().map(|(buffer, ..)| buffer.slice(..)).collect();
        gpu.map_for_reading(&slices)?;
        let mut images = Vec::with_capacity(self.pending.len());
        for (buffer, padded, row_bytes, rows) in self.pending {
            let mapped = buffer.slice(..).get_mapped_range().map_err(|e| GpuError::Map(e.to_string()))?;
            let mut out = Vec::with_capacity((row_bytes * rows) as usize);
            for row in 0..rows as usize {
                let start = row * padded as usize;
                out.extend_from_slice(&mapped[start..start + row_bytes as usize]);
            }
            drop(mapped);
            buffer.unmap();
            pool.release(buffer);
            images.push(out);
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
    let bytes = staging.slice(..).get_mapped_range().map_err(|e| GpuError::Map(e.to_string()))?.to_vec();
    staging.unmap();
    Ok(bytes)
}
