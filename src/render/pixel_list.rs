//! The buffers of a compacted pass (`shaders/common/pixel_list.wgsl`): the list of pixels a
//! per-pixel pass appends to, and the grid of the indirect dispatch that walks it.

/// A `PixelList` and its dispatch, made for one frame.
pub struct PixelListBuffers {
    /// The count (cleared here), then at most `capacity` pixel indices.
    pub list: wgpu::Buffer,
    /// The indirect dispatch's workgroup grid, written on the GPU (`list_dispatch`).
    pub groups: wgpu::Buffer,
    /// Bound where `groups` was while the indirect dispatch reads `groups`: a buffer may not
    /// be bound for writing and read as the dispatch's arguments at once.
    pub stand_in: wgpu::Buffer,
}

impl PixelListBuffers {
    /// Buffers for at most `capacity` pixels, labelled `{owner}::list…`; the count is cleared
    /// on `encoder` before anything appends.
    pub fn new(device: &wgpu::Device, encoder: &mut wgpu::CommandEncoder, owner: &str, capacity: u64) -> Self {
        Self::new_of(device, encoder, owner, capacity, 4)
    }

    /// `new` for a list of `entry_bytes`-sized entries (a multiple of 4).
    pub fn new_of(device: &wgpu::Device, encoder: &mut wgpu::CommandEncoder, owner: &str, capacity: u64, entry_bytes: u64) -> Self {
        let buffer = |field: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{owner}::{field}")),
                size,
                usage: wgpu::BufferUsages::STORAGE | usage,
                mapped_at_creation: false,
            })
        };
        // The count, padded to the entries' alignment, then the entries; the count may be
        // copied out (E0's, the frame's counter `e0_pixels_summed_exactly`).
        let list = buffer("list", entry_bytes.max(4) * (1 + capacity.max(1)), wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC);
        encoder.clear_buffer(&list, 0, Some(4));
        let groups = buffer("list_groups", 12, wgpu::BufferUsages::INDIRECT);
        let stand_in = buffer("list_groups_stand_in", 12, wgpu::BufferUsages::empty());
        PixelListBuffers { list, groups, stand_in }
    }
}
