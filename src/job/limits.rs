//! The limits a job is held to (contract §3: every limit configurable and enforced), and the
//! JSON nesting check made before parsing.

use serde::Serialize;

use crate::params::Cap;

/// Whether arrays and objects in `bytes` nest deeper than `max` (brackets inside strings do
/// not count). A linear scan before any parsing: a hostile body is refused before it costs
/// a deep recursion or an allocation.
pub(super) fn nesting_exceeds(bytes: &[u8], max: usize) -> bool {
    let (mut depth, mut in_string, mut escaped) = (0usize, false, false);
    for &b in bytes {
        if in_string {
            match (escaped, b) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match b {
            b'"' => in_string = true,
            b'[' | b'{' => {
                depth += 1;
                if depth > max {
                    return true;
                }
            }
            b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    false
}

/// Default deepest nesting of arrays and objects a job may have (a job needs 4; serde_json's
/// own recursion limit of 128 would still allocate for a hostile body).
pub const MAX_JSON_DEPTH: usize = 16;

/// Limits on what one job may ask for. Every one is configurable (`serve --help`) and
/// enforced before anything is allocated.
#[derive(Debug, Clone, Serialize)]
pub struct Limits {
    /// Largest output width or height in pixels.
    pub max_output_dim: u32,
    /// Largest output image in pixels (width × height).
    pub max_output_pixels: u64,
    /// Largest shadow-map side in texels.
    pub max_shadow_map_resolution: u32,
    /// Most triangles a scene may have (built-in parameters and loaded files alike).
    pub max_triangles: u64,
    /// Largest light image side in texels.
    pub max_light_image_dim: u32,
    /// Largest side of a texture inside a glTF scene.
    pub max_texture_dim: u32,
    /// Most bytes a scene's textures may take decoded, all together (8-bit RGBA: 4 bytes a
    /// texel), each image's decoding buffers included: a small file can hold a large image,
    /// and a body of many such images would otherwise decode to many times the machine's memory.
    pub max_texture_bytes: u64,
    /// Largest request body in bytes (and scene or image file, and buffer a glTF declares).
    pub max_body_bytes: usize,
    /// Deepest nesting of arrays and objects in a job's JSON, refused before parsing.
    pub max_json_depth: usize,
    /// Most vertices a loaded scene may have (summed over the nodes that instance a mesh),
    /// refused from the accessors' declared counts before any is read.
    pub max_vertices: u64,
    /// Most samples a method may take per pixel (`reference`'s `samples`).
    pub max_samples: u32,
    /// Most rounds an iterative method may run (JFA's `rounds`).
    pub max_rounds: u32,
    /// Most bytes the methods that work on the CPU (`reference`'s CPU engine, `filtered`) hold
    /// for their per-pixel work at once; a frame that needs more is worked on in bands of rows
    /// (the same pixels, each band drawing the samples' maps again).
    pub max_cpu_working_bytes: u64,
}

impl Limits {
    /// An operator cap on method parameters: its value and the flag that sets it.
    pub fn cap(&self, cap: Cap) -> (i64, &'static str) {
        match cap {
            Cap::Samples => (i64::from(self.max_samples), "max_samples"),
            Cap::Rounds => (i64::from(self.max_rounds), "max_rounds"),
        }
    }
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_output_dim: 8192,
            max_output_pixels: 16 * 1024 * 1024,
            max_shadow_map_resolution: 8192,
            max_triangles: 4_000_000,
            max_light_image_dim: 4096,
            max_texture_dim: 8192,
            max_texture_bytes: 1 << 30,
            max_body_bytes: 64 * 1024 * 1024,
            max_json_depth: MAX_JSON_DEPTH,
            max_vertices: 8_000_000,
            max_samples: 4096,
            max_rounds: 13,
            max_cpu_working_bytes: 512 * 1024 * 1024,
        }
    }
}
