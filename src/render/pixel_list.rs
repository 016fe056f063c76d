//! A listed pass (`shaders/common/pixel_list.wgsl`): the list of pixels a per-pixel pass
//! appends to, the grid of the indirect dispatch that walks it, both from the renderer's
//! pools, and the recording of the size pass and the indirect dispatch over the list.

use crate::gpu::pool::{BufferKey, BufferPool};
use crate::gpu::timing::GpuTimer;
use crate::render::method::Scratch;

/// Lanes a workgroup of a listed dispatch, and the most workgroups a row of its grid holds
/// (`LIST_GROUP` and `LIST_MAX_GROUPS` in `pixel_list.wgsl`).
const LIST_GROUP: u32 = 64;
const LIST_MAX_GROUPS: u32 = 65535;

/// The workgroup grid (x, y) of a dispatch over `count` listed entries whose count the CPU
/// knows: `list_dispatch` in `pixel_list.wgsl`.
pub fn list_grid(count: u64) -> (u32, u32) {
    let groups = count.div_ceil(u64::from(LIST_GROUP)) as u32;
    (groups.min(LIST_MAX_GROUPS), groups.div_ceil(LIST_MAX_GROUPS))
}

/// A `PixelList` and its dispatch, lent by the pools for one frame.
pub struct PixelListBuffers {
    /// The count (cleared here), then at most `capacity` entries.
    pub list: wgpu::Buffer,
    /// The indirect dispatch's workgroup grid, written on the GPU (`list_dispatch`).
    pub groups: wgpu::Buffer,
    /// Bound where `groups` was while the indirect dispatch reads `groups`: a buffer may not
    /// be bound for writing and read as the dispatch's arguments at once.
    pub stand_in: wgpu::Buffer,
}

impl PixelListBuffers {
    /// Buffers for at most `capacity` entries of `entry_bytes` (a multiple of 4; a pixel
    /// index is 4): the list from `pool`, held in `scratch` until the frame's passes have run,
    /// its count cleared on `encoder` before anything appends. A pooled list holds what an
    /// earlier frame left, and only the entries below the count are read. The grid and its
    /// stand-in are 12 bytes each, made for the frame: the pool keeps two idle buffers of a
    /// key, and a frame may hold three lists.
    pub fn new(
        pool: &mut BufferPool,
        scratch: &mut Scratch,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        (owner, capacity, entry_bytes): (&'static str, u64, u64),
    ) -> Self {
        // The count, padded to the entries' alignment, then the entries; the count may be
        // copied out (E0's, the frame's counter `e0_pixels_summed_exactly`).
        let size = entry_bytes.max(4) * (1 + capacity.max(1));
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC;
        let list = scratch.buffer(pool, device, BufferKey { label: owner, size, usage });
        encoder.clear_buffer(&list, 0, Some(4));
        let small = |label, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 12,
                usage: wgpu::BufferUsages::STORAGE | usage,
                mapped_at_creation: false,
            })
        };
        let groups = small("PixelList::groups", wgpu::BufferUsages::INDIRECT);
        let stand_in = small("PixelList::stand_in", wgpu::BufferUsages::empty());
        PixelListBuffers { list, groups, stand_in }
    }

    /// The indirect dispatch over the list, of the pipeline and bind groups set on `pass`.
    pub fn dispatch(&self, pass: &mut wgpu::ComputePass<'_>) {
        pass.dispatch_workgroups_indirect(&self.groups, 0);
    }

    /// `dispatch`, timed as the dispatch `name`.
    pub fn walk(&self, pass: &mut wgpu::ComputePass<'_>, timer: &mut GpuTimer, name: &'static str) {
        self.dispatch(pass);
        timer.mark(pass, name);
    }

    /// Records, in `pass`, the size pass (`size`: one invocation turning the count into the
    /// grid, `list_dispatch`) and the indirect dispatch of `walk` over the list, each with its
    /// group-1 bind group, and times them as the dispatches `names`. `walk`'s bind group
    /// binds `stand_in` where `size`'s binds `groups`.
    pub fn size_and_walk(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        timer: &mut GpuTimer,
        size: (&wgpu::ComputePipeline, &wgpu::BindGroup),
        walk: (&wgpu::ComputePipeline, &wgpu::BindGroup),
        names: (&'static str, &'static str),
    ) {
        pass.set_pipeline(size.0);
        pass.set_bind_group(1, size.1, &[]);
        pass.dispatch_workgroups(1, 1, 1);
        timer.mark(pass, names.0);
        pass.set_pipeline(walk.0);
        pass.set_bind_group(1, walk.1, &[]);
        self.walk(pass, timer, names.1);
    }
}
