//! Copies render targets back to the CPU: row padding to the 256-byte copy alignment on the
//! way out, removed on the way in, all targets of a frame in one submission, through buffers
//! from a `ReadbackPool`.

use super::pool::ReadbackPool;
use super::GpuContext;

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
        let block = texture.format().block_copy_size(Some(wgpu::TextureAspect::All)).expect("colour format");
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

    /// Waits for the copies (submitted by the caller) and returns each texture's tightly
    /// packed bytes, top row first; the buffers go back to `pool`.
    pub fn finish(self, gpu: &GpuContext, pool: &mut ReadbackPool) -> Vec<Vec<u8>> {
        for (buffer, ..) in &self.pending {
            buffer.slice(..).map_async(wgpu::MapMode::Read, |_| {});
        }
        gpu.wait_idle();
        self.pending
            .into_iter()
            .map(|(buffer, padded, row_bytes, rows)| {
                let mapped = buffer.slice(..).get_mapped_range().expect("mapped for reading above");
                let mut out = Vec::with_capacity((row_bytes * rows) as usize);
                for row in 0..rows as usize {
                    let start = row * padded as usize;
                    out.extend_from_slice(&mapped[start..start + row_bytes as usize]);
                }
                drop(mapped);
                buffer.unmap();
                pool.release(buffer);
                out
            })
            .collect()
    }
}

impl Default for Readback {
    fn default() -> Self {
        Self::new()
    }
}

/// Copies a (small) storage buffer back to the CPU and waits for it.
pub fn read_buffer(gpu: &GpuContext, buffer: &wgpu::Buffer) -> Vec<u8> {
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("Readback::staging"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Readback::encoder") });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, buffer.size());
    gpu.queue.submit([encoder.finish()]);
    staging.slice(..).map_async(wgpu::MapMode::Read, |_| {});
    gpu.wait_idle();
    let bytes = staging.slice(..).get_mapped_range().expect("mapped for reading above").to_vec();
    staging.unmap();
    bytes
}
