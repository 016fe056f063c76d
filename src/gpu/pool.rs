//! Pools for long-lived GPU objects: pipelines compiled once per key and reused by every job,
//! and render targets recycled between jobs of the same size and format. The pool decides
//! reuse; its counters show in the timing breakdown and, later, in `/metrics`.

use std::any::Any;
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

/// Identifies a pipeline by what it is built from, so that two different pipelines can never
/// share a key: the pass or method that owns it (its label), its shader file and entry point,
/// its pipeline-overridable constants, and for a render pipeline the formats it writes.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct PipelineKey {
    pub label: &'static str,
    pub shader: &'static str,
    /// The compute entry point, or a render pipeline's fragment entry ("" for none).
    pub entry: &'static str,
    /// Each constant's name and the bits of its value, in the order given.
    constants: Vec<(&'static str, u64)>,
    /// A render pipeline's colour targets.
    targets: Vec<wgpu::TextureFormat>,
}

impl PipelineKey {
    /// A compute pipeline: `entry` of `shader` with `constants`.
    pub fn compute(label: &'static str, (shader, entry): (&'static str, &'static str), constants: &[(&'static str, f64)]) -> Self {
        let constants = constants.iter().map(|&(name, value)| (name, value.to_bits())).collect();
        Self { label, shader, entry, constants, targets: Vec::new() }
    }

    /// A render pipeline drawing with `shader`, through fragment entry `fragment` (if any)
    /// into `targets`.
    pub fn render(label: &'static str, shader: &'static str, fragment: Option<&'static str>, targets: &[wgpu::TextureFormat]) -> Self {
        Self { label, shader, entry: fragment.unwrap_or(""), constants: Vec::new(), targets: targets.to_vec() }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PoolStats {
    pub created: u64,
    pub reused: u64,
}

/// Compiled render and compute pipelines with their layouts, created on first use.
#[derive(Default)]
pub struct PipelinePool {
    render: HashMap<PipelineKey, Arc<wgpu::RenderPipeline>>,
    compute: HashMap<PipelineKey, Arc<wgpu::ComputePipeline>>,
    pub stats: PoolStats,
}

impl PipelinePool {
    pub fn render(&mut self, key: PipelineKey, create: impl FnOnce() -> wgpu::RenderPipeline) -> Arc<wgpu::RenderPipeline> {
        get_or_create(&mut self.render, &mut self.stats, key, create)
    }

    pub fn compute(&mut self, key: PipelineKey, create: impl FnOnce() -> wgpu::ComputePipeline) -> Arc<wgpu::ComputePipeline> {
        get_or_create(&mut self.compute, &mut self.stats, key, create)
    }

    pub fn len(&self) -> usize {
        self.render.len() + self.compute.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

fn get_or_create<T>(map: &mut HashMap<PipelineKey, Arc<T>>, stats: &mut PoolStats, key: PipelineKey, create: impl FnOnce() -> T) -> Arc<T> {
    if let Some(existing) = map.get(&key) {
        stats.reused += 1;
        return existing.clone();
    }
    stats.created += 1;
    let created = Arc::new(create());
    map.insert(key, created.clone());
    created
}

/// What a render target is: enough to decide whether a free one can be reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TextureKey {
    pub label: &'static str,
    pub width: u32,
    pub height: u32,
    /// Array layers (1: a plain 2D texture).
    pub layers: u32,
    pub format: wgpu::TextureFormat,
    pub usage: wgpu::TextureUsages,
}

impl TextureKey {
    pub fn bytes(&self) -> u64 {
        let block = self.format.block_copy_size(Some(wgpu::TextureAspect::All)).unwrap_or(4);
        u64::from(self.width) * u64::from(self.height) * u64::from(self.layers) * u64::from(block)
    }
}

/// Idle objects by key, at most `max_per_key` of one key and `budget` bytes in all (the
/// objects given back longest ago go first), so memory stays bounded when job sizes vary:
/// what the target, buffer and readback pools share.
struct FreeList<K, T> {
    free: HashMap<K, Vec<T>>,
    max_per_key: usize,
    /// One entry per idle object, the longest idle first: its key and bytes.
    order: VecDeque<(K, u64)>,
    bytes: u64,
    budget: u64,
}

impl<K: std::hash::Hash + Eq + Clone, T> FreeList<K, T> {
    fn new(max_per_key: usize) -> Self {
        Self { free: HashMap::new(), max_per_key, order: VecDeque::new(), bytes: 0, budget: DEFAULT_POOL_BYTES }
    }

    /// An idle object of `key`, or a new one from `create`; counted in `stats`.
    fn take_or(&mut self, key: K, stats: &mut PoolStats, create: impl FnOnce(K) -> T) -> T {
        if let Some(item) = self.free.get_mut(&key).and_then(Vec::pop) {
            // Objects of one key are alike: forget the most recently idle entry of the key.
            if let Some((_, bytes)) = self.order.iter().rposition(|(k, _)| *k == key).and_then(|at| self.order.remove(at)) {
                self.bytes -= bytes;
            }
            stats.reused += 1;
            return item;
        }
        stats.created += 1;
        create(key)
    }

    /// Keeps `item` (`bytes` of memory) for a later `take_or`, unless enough of its key are
    /// idle already; then drops the longest idle objects while the pool holds more than its
    /// budget.
    fn give(&mut self, key: K, item: T, bytes: u64) {
        let list = self.free.entry(key.clone()).or_default();
        if list.len() >= self.max_per_key {
            return;
        }
        list.push(item);
        self.order.push_back((key, bytes));
        self.bytes += bytes;
        self.trim();
    }

    fn trim(&mut self) {
        while self.bytes > self.budget {
            let Some((key, bytes)) = self.order.pop_front() else { break };
            if let Some(list) = self.free.get_mut(&key) {
                if !list.is_empty() {
                    list.remove(0);
                }
                if list.is_empty() {
                    self.free.remove(&key);
                }
            }
            self.bytes -= bytes;
        }
    }

    fn set_budget(&mut self, bytes: u64) {
        self.budget = bytes;
        self.trim();
    }
}

/// Bytes of idle objects each of the texture, buffer and readback pools keeps by default.
pub const DEFAULT_POOL_BYTES: u64 = 1 << 30;

/// A texture from the pool with its default view.
pub struct PooledTexture {
    pub key: TextureKey,
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
}

/// Free render targets by key. Jobs `alloc` what they need and `release` it when done; at
/// most two idle targets of one key are kept.
pub struct TexturePool {
    free: FreeList<TextureKey, PooledTexture>,
    pub stats: PoolStats,
}

impl Default for TexturePool {
    fn default() -> Self {
        Self { free: FreeList::new(2), stats: PoolStats::default() }
    }
}

impl TexturePool {
    pub fn alloc(&mut self, device: &wgpu::Device, key: TextureKey) -> PooledTexture {
        self.free.take_or(key, &mut self.stats, |key| {
            let texture = device.create_texture(&wgpu::TextureDescriptor {
                label: Some(key.label),
                size: wgpu::Extent3d { width: key.width, height: key.height, depth_or_array_layers: key.layers },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: key.format,
                usage: key.usage,
                view_formats: &[],
            });
            let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
            PooledTexture { key, texture, view }
        })
    }

    pub fn release(&mut self, texture: PooledTexture) {
        let (key, bytes) = (texture.key, texture.key.bytes());
        self.free.give(key, texture, bytes);
    }

    /// Bytes held by idle targets.
    pub fn idle_bytes(&self) -> u64 {
        self.free.bytes
    }

    /// At most `bytes` of idle targets are kept.
    pub fn set_budget(&mut self, bytes: u64) {
        self.free.set_budget(bytes);
    }
}

/// What a pooled storage buffer is: enough to decide whether a free one can be reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BufferKey {
    pub label: &'static str,
    pub size: u64,
    pub usage: wgpu::BufferUsages,
}

/// A storage buffer from the pool.
pub struct PooledBuffer {
    pub key: BufferKey,
    pub buffer: wgpu::Buffer,
}

/// Free per-frame storage buffers (the screen-space images) by key, kept like render targets.
pub struct BufferPool {
    free: FreeList<BufferKey, PooledBuffer>,
    pub stats: PoolStats,
}

impl Default for BufferPool {
    fn default() -> Self {
        Self { free: FreeList::new(2), stats: PoolStats::default() }
    }
}

impl BufferPool {
    pub fn alloc(&mut self, device: &wgpu::Device, key: BufferKey) -> PooledBuffer {
        self.free.take_or(key, &mut self.stats, |key| {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(key.label),
                size: key.size,
                usage: key.usage,
                mapped_at_creation: false,
            });
            PooledBuffer { key, buffer }
        })
    }

    pub fn release(&mut self, buffer: PooledBuffer) {
        let key = buffer.key;
        self.free.give(key, buffer, key.size);
    }

    /// Bytes held by idle buffers.
    pub fn idle_bytes(&self) -> u64 {
        self.free.bytes
    }

    /// At most `bytes` of idle buffers are kept.
    pub fn set_budget(&mut self, bytes: u64) {
        self.free.set_budget(bytes);
    }
}

/// Free readback (MAP_READ) buffers by size: the readbacks of a steady stream of same-sized
/// jobs reuse them instead of allocating. At most four idle ones per size.
pub struct ReadbackPool {
    free: FreeList<u64, wgpu::Buffer>,
    pub stats: PoolStats,
}

impl Default for ReadbackPool {
    fn default() -> Self {
        Self { free: FreeList::new(4), stats: PoolStats::default() }
    }
}

impl ReadbackPool {
    pub fn alloc(&mut self, device: &wgpu::Device, size: u64) -> wgpu::Buffer {
        self.free.take_or(size, &mut self.stats, |size| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Readback::buffer"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
    }

    /// Takes back an unmapped buffer.
    pub fn release(&mut self, buffer: wgpu::Buffer) {
        let size = buffer.size();
        self.free.give(size, buffer, size);
    }

    /// At most `bytes` of idle readback buffers are kept.
    pub fn set_budget(&mut self, bytes: u64) {
        self.free.set_budget(bytes);
    }
}

/// Identifies a texture derived from a job's inputs: the method or pass that derives it and a
/// fingerprint of everything it depends on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DerivedKey {
    pub name: &'static str,
    pub fingerprint: u64,
}

/// GPU resources that cost CPU or GPU time to derive from a job's inputs (a method's look-up
/// table from the light image) and stay valid for any later job with the same inputs: buffers,
/// textures, views — any type, told apart by key. At most `capacity` are kept; the least
/// recently used goes first.
pub struct DerivedResources {
    /// Most recently used last.
    entries: Vec<(DerivedKey, Arc<dyn Any + Send + Sync>)>,
    capacity: usize,
    pub stats: PoolStats,
}

impl Default for DerivedResources {
    fn default() -> Self {
        Self { entries: Vec::new(), capacity: 16, stats: PoolStats::default() }
    }
}

impl DerivedResources {
    /// The resource under `key`, created now if it is not kept. A key must always name the
    /// same type: one kept under another type is replaced.
    pub fn get_or_create<T: Any + Send + Sync>(&mut self, key: DerivedKey, create: impl FnOnce() -> T) -> Arc<T> {
        let kept = self.entries.iter().position(|(k, _)| *k == key);
        if let Some(entry) = kept.map(|at| self.entries.remove(at)) {
            if let Ok(resource) = entry.1.clone().downcast::<T>() {
                self.stats.reused += 1;
                self.entries.push(entry);
                return resource;
            }
        }
        self.stats.created += 1;
        if self.entries.len() >= self.capacity {
            self.entries.remove(0);
        }
        let resource = Arc::new(create());
        self.entries.push((key, resource.clone()));
        resource
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_lists_keep_at_most_their_budget_dropping_the_longest_idle_first() {
        let mut list: FreeList<u32, &str> = FreeList::new(2);
        list.set_budget(100);
        let mut stats = PoolStats::default();
        list.give(1, "a", 40);
        list.give(2, "b", 40);
        list.give(1, "c", 40); // 120 > 100: "a", idle longest, goes
        assert_eq!(list.bytes, 80);
        assert_eq!(list.take_or(1, &mut stats, |_| "new"), "c");
        assert_eq!(list.take_or(1, &mut stats, |_| "new"), "new");
        assert_eq!(list.bytes, 40);
        list.give(3, "d", 70); // 110: "b" goes
        assert_eq!((list.bytes, list.take_or(2, &mut stats, |_| "new")), (70, "new"));
        list.give(4, "e", 500); // over the budget alone: kept by no one
        assert_eq!(list.bytes, 0);
        assert_eq!(stats, PoolStats { created: 2, reused: 1 });
    }

    #[test]
    fn derived_resources_are_reused_and_evicted_least_recently_used_first() {
        let mut cache = DerivedResources { capacity: 2, ..Default::default() };
        let key = |fingerprint| DerivedKey { name: "test", fingerprint };
        let first = cache.get_or_create(key(1), || vec![1u8]);
        assert!(Arc::ptr_eq(&first, &cache.get_or_create(key(1), || unreachable!("cached"))));
        cache.get_or_create(key(2), || vec![2u8]);
        cache.get_or_create::<Vec<u8>>(key(1), || unreachable!("cached"));
        // 2 is now the least recently used: a third key evicts it, not 1.
        cache.get_or_create(key(3), || vec![3u8]);
        assert_eq!(cache.len(), 2);
        cache.get_or_create::<Vec<u8>>(key(1), || unreachable!("1 was used last"));
        assert_eq!(cache.stats, PoolStats { created: 3, reused: 3 });
        // The same key asked for as another type is derived again, not mistaken.
        assert_eq!(*cache.get_or_create(key(1), || 7u32), 7);
        assert_eq!(cache.len(), 2);
    }
}
