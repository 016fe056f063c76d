//! Terse constructors for bind-group-layout entries, so each pass states its bindings in
//! one readable list instead of nested descriptor literals.

use wgpu::{BindGroupLayoutEntry as Entry, BindingType, ShaderStages, TextureSampleType, TextureViewDimension};

const ALL: ShaderStages = ShaderStages::VERTEX_FRAGMENT.union(ShaderStages::COMPUTE);

pub const fn uniform(binding: u32) -> Entry {
    Entry {
        binding,
        visibility: ALL,
        ty: BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None },
        count: None,
    }
}

/// A uniform buffer bound with a dynamic offset (one slot per draw or dispatch).
pub const fn uniform_dynamic(binding: u32) -> Entry {
    Entry {
        binding,
        visibility: ALL,
        ty: BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: true, min_binding_size: None },
        count: None,
    }
}

pub const fn storage_read(binding: u32) -> Entry {
    Entry {
        binding,
        visibility: ALL,
        ty: BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

pub const fn storage_read_write(binding: u32) -> Entry {
    Entry {
        binding,
        visibility: ShaderStages::COMPUTE.union(ShaderStages::FRAGMENT),
        ty: BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: false },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn texture(binding: u32, sample_type: TextureSampleType) -> Entry {
    Entry {
        binding,
        visibility: ShaderStages::FRAGMENT.union(ShaderStages::COMPUTE),
        ty: BindingType::Texture { sample_type, view_dimension: TextureViewDimension::D2, multisampled: false },
        count: None,
    }
}

/// A float texture read with `textureLoad` (32-bit float formats are not filterable).
pub fn texture_float(binding: u32) -> Entry {
    texture(binding, TextureSampleType::Float { filterable: false })
}

/// A float texture sampled with a filtering sampler.
pub fn texture_filterable(binding: u32) -> Entry {
    texture(binding, TextureSampleType::Float { filterable: true })
}

pub fn texture_uint(binding: u32) -> Entry {
    texture(binding, TextureSampleType::Uint)
}

pub fn sampler(binding: u32) -> Entry {
    Entry {
        binding,
        visibility: ShaderStages::FRAGMENT.union(ShaderStages::COMPUTE),
        ty: BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
        count: None,
    }
}

/// Bind group entries from resources in binding order 0, 1, 2, …
pub fn entries<'a>(resources: &[wgpu::BindingResource<'a>]) -> Vec<wgpu::BindGroupEntry<'a>> {
    resources
        .iter()
        .enumerate()
        .map(|(binding, resource)| wgpu::BindGroupEntry { binding: binding as u32, resource: resource.clone() })
        .collect()
}

/// Distance between the slots of a dynamic-offset uniform buffer: 256 bytes, the offset
/// alignment every adapter accepts.
pub const UNIFORM_SLOT: u64 = 256;

/// Distance between the slots of `T`s in a `uniform_slots` buffer: `T`'s size rounded up to
/// whole `UNIFORM_SLOT`s.
fn slot_stride<T>() -> u64 {
    (std::mem::size_of::<T>() as u64).next_multiple_of(UNIFORM_SLOT)
}

/// A uniform buffer with one slot per item (one zeroed slot when there are none), for passes
/// that bind the same layout with a different offset each time.
pub fn uniform_slots<T: bytemuck::Pod>(device: &wgpu::Device, label: &str, items: &[T]) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    let stride = slot_stride::<T>() as usize;
    let mut bytes = vec![0u8; items.len().max(1) * stride];
    for (k, item) in items.iter().enumerate() {
        let start = k * stride;
        bytes[start..start + std::mem::size_of::<T>()].copy_from_slice(bytemuck::bytes_of(item));
    }
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: &bytes,
        usage: wgpu::BufferUsages::UNIFORM,
    })
}

/// The dynamic offset of slot `k` in a `uniform_slots` buffer of items up to `UNIFORM_SLOT`
/// bytes.
pub fn slot_offset(k: usize) -> u32 {
    (k as u64 * UNIFORM_SLOT) as u32
}

/// The dynamic offset of slot `k` in a `uniform_slots` buffer of `T`s.
pub fn slot_offset_of<T>(k: usize) -> u32 {
    (k as u64 * slot_stride::<T>()) as u32
}

/// A binding of one `T`-sized slot of a `uniform_slots` buffer (the offset comes at draw time).
pub fn slot_binding<T>(buffer: &wgpu::Buffer) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding { buffer, offset: 0, size: wgpu::BufferSize::new(std::mem::size_of::<T>() as u64) })
}
