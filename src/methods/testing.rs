//! Shader code run on synthetic input, for the tests (`tests/render.rs`): no render calls
//! these. `voronoi` floods seeds with the jump-flooding pattern of `jfa-l` and `jfa-e`;
//! `quadtree_probe` runs `chun-oh`'s quadtree on made-up tiles of shadow tests.

use wgpu::util::DeviceExt;

use super::filter::{MODE_ADAPTIVE, MODE_FIXED};
use super::jfa::{steps, TILE};
use crate::gpu::layout;

/// Jump flooding of nearest seeds over a `size`² grid: the Voronoi diagram the flooding pattern
/// approximates (Rong & Tan 2006 §3). Returns, per cell, the index of the seed it ended with
/// (−1 for none). It runs `voronoi.wgsl`, which shares `jump_neighbour` with the shadow
/// methods' floods, so testing it against brute force tests their communication pattern.
pub fn voronoi(
    gpu: &crate::gpu::GpuContext,
    size: u32,
    seeds: &[(u32, u32)],
    rounds: u32,
    standard: bool,
) -> Result<Vec<i32>, crate::gpu::GpuError> {
    let device = &gpu.device;
    let steps = steps(rounds, standard);
    // `VoronoiParams` in `voronoi.wgsl`: step, grid size (both non-negative, so i32 bits do).
    let slots: Vec<[i32; 2]> = steps.iter().map(|&step| [step, size as i32]).collect();
    let uniforms = layout::uniform_slots(device, "Voronoi::uniforms", &slots);
    let seed_coords: Vec<[i32; 2]> = seeds.iter().map(|&(x, y)| [x as i32, y as i32]).collect();
    let seed_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("Voronoi::seeds"),
        contents: bytemuck::cast_slice(&seed_coords),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let mut initial = vec![-1i32; (size * size) as usize];
    for (k, &(x, y)) in seeds.iter().enumerate() {
        initial[(y * size + x) as usize] = k as i32;
    }
    let cells = |label| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(&initial),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        })
    };
    let (a, b) = (cells("Voronoi::cells_a"), cells("Voronoi::cells_b"));
    let tiles_across = size.div_ceil(TILE);
    let mut tile_flags = vec![0u32; (tiles_across * tiles_across) as usize];
    for &(x, y) in seeds {
        tile_flags[(y / TILE * tiles_across + x / TILE) as usize] = 1;
    }
    let tiles = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("Voronoi::tiles"),
        contents: bytemuck::cast_slice(&tile_flags),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("Voronoi::layout"),
        entries: &[
            layout::uniform_dynamic(0),
            layout::storage_read(1),
            layout::storage_read(2),
            layout::storage_read_write(3),
            layout::storage_read_write(4),
        ],
    });
    let pipeline =
        crate::gpu::shaders::compute_pipeline(device, "Voronoi::pipeline", ("methods/jfa/voronoi.wgsl", "main"), &[&bind_layout], &[]);
    let group = |src: &wgpu::Buffer, dst: &wgpu::Buffer| {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("Voronoi::bind_group"),
            layout: &bind_layout,
            entries: &layout::entries(&[
                layout::slot_binding::<[i32; 2]>(&uniforms),
                seed_buffer.as_entire_binding(),
                src.as_entire_binding(),
                dst.as_entire_binding(),
                tiles.as_entire_binding(),
            ]),
        })
    };
    let (a_to_b, b_to_a) = (group(&a, &b), group(&b, &a));
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Voronoi::encoder") });
    let mut result_in_a = true;
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("Voronoi::pass"), timestamp_writes: None });
        pass.set_pipeline(&pipeline);
        for k in 0..steps.len() {
            pass.set_bind_group(0, if result_in_a { &a_to_b } else { &b_to_a }, &[layout::slot_offset(k)]);
            pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), 1);
            result_in_a = !result_in_a;
        }
    }
    gpu.queue.submit([encoder.finish()]);
    Ok(bytemuck::cast_slice(&crate::gpu::readback::read_buffer(gpu, if result_in_a { &a } else { &b })?).to_vec())
}

/// One synthetic tile's outcome in `quadtree_probe`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeResult {
    pub visibility: [f32; 3],
    /// Deepest split: 0, 1 (2×2) or 2 (4×4).
    pub level: u32,
    /// Splits only the light's colour asked for.
    pub forced: u32,
}

/// Runs the shader's quadtree (`quadtree.wgsl`, through `quadtree_probe.wgsl`) on synthetic
/// tiles: per tile, lit tests in each 4×4 cell (row-major, x along the shadow map's u), with
/// `cell_taps`² tests per cell, against the light table `regions` (`light_regions`).
pub fn quadtree_probe(
    gpu: &crate::gpu::GpuContext,
    tiles: &[[u32; 16]],
    regions: &[[f32; 4]; 21],
    fixed: bool,
    threshold: f32,
    light_threshold: f32,
    cell_taps: u32,
) -> Result<Vec<ProbeResult>, crate::gpu::GpuError> {
    let device = &gpu.device;
    let storage = |label, contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    };
    let tiles_buffer = storage("Probe::tiles", bytemuck::cast_slice(tiles), wgpu::BufferUsages::STORAGE);
    let regions_buffer = storage("Probe::regions", bytemuck::cast_slice(regions), wgpu::BufferUsages::STORAGE);
    let mode = if fixed { MODE_FIXED } else { MODE_ADAPTIVE };
    let params: [u32; 4] = [mode, threshold.to_bits(), light_threshold.to_bits(), cell_taps];
    let params_buffer = storage("Probe::params", bytemuck::cast_slice(&params), wgpu::BufferUsages::UNIFORM);
    let results = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("Probe::results"),
        size: (tiles.len() * 16) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("Probe::layout"),
        entries: &[layout::storage_read(0), layout::storage_read(1), layout::uniform(2), layout::storage_read_write(3)],
    });
    let pipeline = crate::gpu::shaders::compute_pipeline(
        device,
        "Probe::pipeline",
        ("methods/chun_oh/quadtree_probe.wgsl", "main"),
        &[&bind_layout],
        &[],
    );
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("Probe::bind_group"),
        layout: &bind_layout,
        entries: &layout::entries(&[
            tiles_buffer.as_entire_binding(),
            regions_buffer.as_entire_binding(),
            params_buffer.as_entire_binding(),
            results.as_entire_binding(),
        ]),
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("Probe::encoder") });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("Probe::pass"), timestamp_writes: None });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((tiles.len() as u32).div_ceil(64), 1, 1);
    }
    gpu.queue.submit([encoder.finish()]);
    let values: Vec<[f32; 4]> = bytemuck::cast_slice(&crate::gpu::readback::read_buffer(gpu, &results)?).to_vec();
    Ok(values
        .iter()
        .map(|v| {
            let code = v[3] as u32;
            ProbeResult { visibility: [v[0], v[1], v[2]], level: code % 4, forced: code / 4 }
        })
        .collect())
}
