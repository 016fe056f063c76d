//! The frame's render targets: the shadow map's and the G-buffer's attachments, drawn from
//! the texture pool, and the screen-space images (E0, visibility, colour, depth), storage
//! buffers drawn from the buffer pool — all for one frame and given back after it, with the
//! formats and layouts every pass agrees on.
//!
//! The screen-space images are buffers, not storage textures, because lavapipe pays several
//! times a buffer store for a store to an `rgba32float` storage texture, and every method's last pass, E0 and the composite store one; a buffer also reads
//! back without row padding. Pixel (x, y) is element `y × width + x` (`pixel_index` in
//! `shaders/common/frame_inputs.wgsl`).

use crate::gpu::pool::{BufferKey, BufferPool, PooledBuffer, PooledTexture, TextureKey, TexturePool};

/// The frame's render targets, drawn from and returned to the pools.
pub(super) struct FrameTargets {
    pub shadow_depth_buffer: PooledTexture,
    pub shadow_depth: PooledTexture,
    pub shadow_id: PooledTexture,
    pub depth_buffer: PooledTexture,
    pub position: PooledTexture,
    /// The geometric normal: the plane of the triangle seen, facing the eye. Every
    /// visibility test (biases, receiver planes, which side of a surface the light is on)
    /// reads it.
    pub normal: PooledTexture,
    pub albedo: PooledTexture,
    /// The shading normal (interpolated from the vertices) on the seen side: what E0's
    /// cosine reads (contract §1).
    pub shading: PooledTexture,
    pub object_id: PooledTexture,
    /// `array<vec4<f32>>`: rgb = E0 per channel.
    pub e0: PooledBuffer,
    /// `array<vec4<f32>>`: rgb = V per channel.
    pub visibility: PooledBuffer,
    /// `array<vec4<f32>>`: linear radiance and coverage alpha (EXR and comparisons).
    pub color: PooledBuffer,
    /// `array<f32>`: view depth, +∞ for background (EXR).
    pub depth: PooledBuffer,
}

pub(super) const SHADOW_DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
pub(super) const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
pub(super) const DEPTH_BUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
pub(super) const POSITION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
pub(super) const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub(super) const ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

impl FrameTargets {
    pub fn alloc(
        textures: &mut TexturePool,
        buffers: &mut BufferPool,
        device: &wgpu::Device,
        width: u32,
        height: u32,
        shadow: u32,
    ) -> Self {
        use wgpu::TextureUsages as U;
        let attachment = U::RENDER_ATTACHMENT | U::TEXTURE_BINDING;
        let mut get =
            |label, w, h, format, usage| textures.alloc(device, TextureKey { label, width: w, height: h, layers: 1, format, usage });
        let pixels = u64::from(width) * u64::from(height);
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let mut image = |label, bytes_per_pixel: u64, extra: wgpu::BufferUsages| {
            buffers.alloc(device, BufferKey { label, size: pixels * bytes_per_pixel, usage: usage | extra })
        };
        Self {
            shadow_depth_buffer: get("FrameTargets::shadow_depth_buffer", shadow, shadow, DEPTH_BUFFER_FORMAT, U::RENDER_ATTACHMENT),
            shadow_depth: get("FrameTargets::shadow_depth", shadow, shadow, SHADOW_DEPTH_FORMAT, attachment | U::COPY_SRC),
            shadow_id: get("FrameTargets::shadow_id", shadow, shadow, ID_FORMAT, attachment),
            depth_buffer: get("FrameTargets::depth_buffer", width, height, DEPTH_BUFFER_FORMAT, U::RENDER_ATTACHMENT),
            // Read back by an engine that works on the CPU (`MethodContext::read_surfaces`).
            position: get("FrameTargets::position", width, height, POSITION_FORMAT, attachment | U::COPY_SRC),
            normal: get("FrameTargets::normal", width, height, NORMAL_FORMAT, attachment | U::COPY_SRC),
            albedo: get("FrameTargets::albedo", width, height, ALBEDO_FORMAT, attachment),
            shading: get("FrameTargets::shading", width, height, NORMAL_FORMAT, attachment),
            object_id: get("FrameTargets::object_id", width, height, ID_FORMAT, attachment),
            e0: image("FrameTargets::e0", 16, wgpu::BufferUsages::empty()),
            // Written by the CPU where a method works there (`reference`'s engine `cpu`).
            visibility: image("FrameTargets::visibility", 16, wgpu::BufferUsages::COPY_DST),
            color: image("FrameTargets::color", 16, wgpu::BufferUsages::empty()),
            depth: image("FrameTargets::depth", 4, wgpu::BufferUsages::empty()),
        }
    }

    pub fn release(self, textures: &mut TexturePool, buffers: &mut BufferPool) {
        for t in [
            self.shadow_depth_buffer,
            self.shadow_depth,
            self.shadow_id,
            self.depth_buffer,
            self.position,
            self.normal,
            self.albedo,
            self.shading,
            self.object_id,
        ] {
            textures.release(t);
        }
        for b in [self.e0, self.visibility, self.color, self.depth] {
            buffers.release(b);
        }
    }
}
