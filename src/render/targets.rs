//! The frame's render targets: the shadow map's and the G-buffer's attachments and the
//! screen-space images (E0, visibility, colour, depth), drawn from the texture pool for one
//! frame and given back after it, with the formats every pass agrees on.

use crate::gpu::pool::{PooledTexture, TextureKey, TexturePool};

/// The frame's render targets, drawn from and returned to the pool.
pub(super) struct FrameTargets {
    pub shadow_depth_buffer: PooledTexture,
    pub shadow_depth: PooledTexture,
    pub shadow_id: PooledTexture,
    pub shadow_position: PooledTexture,
    pub depth_buffer: PooledTexture,
    pub position: PooledTexture,
    pub normal: PooledTexture,
    pub albedo: PooledTexture,
    pub object_id: PooledTexture,
    pub e0: PooledTexture,
    pub visibility: PooledTexture,
    pub color: PooledTexture,
    pub depth: PooledTexture,
}

pub(super) const SHADOW_DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
pub(super) const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
pub(super) const DEPTH_BUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
pub(super) const POSITION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
pub(super) const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub(super) const ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub(super) const FLOAT_TARGET: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

impl FrameTargets {
    pub fn alloc(pool: &mut TexturePool, device: &wgpu::Device, width: u32, height: u32, shadow: u32) -> Self {
        use wgpu::TextureUsages as U;
        let attachment = U::RENDER_ATTACHMENT | U::TEXTURE_BINDING;
        let storage = U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC;
        let mut get = |label, w, h, format, usage| pool.alloc(device, TextureKey { label, width: w, height: h, format, usage });
        Self {
            shadow_depth_buffer: get("FrameTargets::shadow_depth_buffer", shadow, shadow, DEPTH_BUFFER_FORMAT, U::RENDER_ATTACHMENT),
            shadow_depth: get("FrameTargets::shadow_depth", shadow, shadow, SHADOW_DEPTH_FORMAT, attachment),
            shadow_id: get("FrameTargets::shadow_id", shadow, shadow, ID_FORMAT, attachment),
            shadow_position: get("FrameTargets::shadow_position", shadow, shadow, POSITION_FORMAT, attachment),
            depth_buffer: get("FrameTargets::depth_buffer", width, height, DEPTH_BUFFER_FORMAT, U::RENDER_ATTACHMENT),
            position: get("FrameTargets::position", width, height, POSITION_FORMAT, attachment),
            normal: get("FrameTargets::normal", width, height, NORMAL_FORMAT, attachment),
            albedo: get("FrameTargets::albedo", width, height, ALBEDO_FORMAT, attachment),
            object_id: get("FrameTargets::object_id", width, height, ID_FORMAT, attachment),
            e0: get("FrameTargets::e0", width, height, FLOAT_TARGET, storage),
            visibility: get("FrameTargets::visibility", width, height, FLOAT_TARGET, storage),
            color: get("FrameTargets::color", width, height, FLOAT_TARGET, storage),
            depth: get("FrameTargets::depth", width, height, wgpu::TextureFormat::R32Float, storage),
        }
    }

    pub fn release(self, pool: &mut TexturePool) {
        for t in [
            self.shadow_depth_buffer,
            self.shadow_depth,
            self.shadow_id,
            self.shadow_position,
            self.depth_buffer,
            self.position,
            self.normal,
            self.albedo,
            self.object_id,
            self.e0,
            self.visibility,
            self.color,
            self.depth,
        ] {
            pool.release(t);
        }
    }
}
