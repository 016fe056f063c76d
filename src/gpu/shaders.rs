//! WGSL sources, embedded in the binary, and the two directives that compose them: a line
//! `#import common/NAME.wgsl` is replaced by that file (each file at most once per shader),
//! so shared code (frame constants, light frame, shadow lookups) is written once; and a block
//! `#unroll i in A..B { … }` is written out once per value of `i`, each copy a block that
//! begins `let i = Ku;` (`unroll`).

use std::collections::HashSet;

/// Every WGSL file under `shaders/`, by path relative to it.
pub const SOURCES: &[(&str, &str)] = &[
    ("common/frame.wgsl", include_str!("../../shaders/common/frame.wgsl")),
    ("common/frame_inputs.wgsl", include_str!("../../shaders/common/frame_inputs.wgsl")),
    ("common/light.wgsl", include_str!("../../shaders/common/light.wgsl")),
    ("common/shadow.wgsl", include_str!("../../shaders/common/shadow.wgsl")),
    ("common/edge_table.wgsl", include_str!("../../shaders/common/edge_table.wgsl")),
    ("common/pixel_list.wgsl", include_str!("../../shaders/common/pixel_list.wgsl")),
    ("shadow_map.wgsl", include_str!("../../shaders/shadow_map.wgsl")),
    ("gbuffer.wgsl", include_str!("../../shaders/gbuffer.wgsl")),
    ("e0/common.wgsl", include_str!("../../shaders/e0/common.wgsl")),
    ("e0/grid.wgsl", include_str!("../../shaders/e0/grid.wgsl")),
    ("e0/corners.wgsl", include_str!("../../shaders/e0/corners.wgsl")),
    ("e0/blend.wgsl", include_str!("../../shaders/e0/blend.wgsl")),
    ("e0/check.wgsl", include_str!("../../shaders/e0/check.wgsl")),
    ("e0/interpolate.wgsl", include_str!("../../shaders/e0/interpolate.wgsl")),
    ("e0/exact.wgsl", include_str!("../../shaders/e0/exact.wgsl")),
    ("composite.wgsl", include_str!("../../shaders/composite.wgsl")),
    ("methods/hard.wgsl", include_str!("../../shaders/methods/hard.wgsl")),
    ("methods/brabec/common.wgsl", include_str!("../../shaders/methods/brabec/common.wgsl")),
    ("methods/brabec/colour.wgsl", include_str!("../../shaders/methods/brabec/colour.wgsl")),
    ("methods/brabec/summary.wgsl", include_str!("../../shaders/methods/brabec/summary.wgsl")),
    ("methods/brabec/classify.wgsl", include_str!("../../shaders/methods/brabec/classify.wgsl")),
    ("methods/brabec/lattice.wgsl", include_str!("../../shaders/methods/brabec/lattice.wgsl")),
    ("methods/brabec/refine.wgsl", include_str!("../../shaders/methods/brabec/refine.wgsl")),
    ("methods/brabec/finish.wgsl", include_str!("../../shaders/methods/brabec/finish.wgsl")),
    ("methods/brabec/search.wgsl", include_str!("../../shaders/methods/brabec/search.wgsl")),
    ("methods/jfa/common.wgsl", include_str!("../../shaders/methods/jfa/common.wgsl")),
    ("methods/jfa/neighbours.wgsl", include_str!("../../shaders/methods/jfa/neighbours.wgsl")),
    ("methods/jfa/voronoi.wgsl", include_str!("../../shaders/methods/jfa/voronoi.wgsl")),
    ("methods/jfa/silhouette.wgsl", include_str!("../../shaders/methods/jfa/silhouette.wgsl")),
    ("methods/jfa/flood_light.wgsl", include_str!("../../shaders/methods/jfa/flood_light.wgsl")),
    ("methods/jfa/shading.wgsl", include_str!("../../shaders/methods/jfa/shading.wgsl")),
    ("methods/jfa/final_light.wgsl", include_str!("../../shaders/methods/jfa/final_light.wgsl")),
    ("methods/jfa/boundary.wgsl", include_str!("../../shaders/methods/jfa/boundary.wgsl")),
    ("methods/jfa/flood_eye.wgsl", include_str!("../../shaders/methods/jfa/flood_eye.wgsl")),
    ("methods/jfa/final_eye.wgsl", include_str!("../../shaders/methods/jfa/final_eye.wgsl")),
    ("methods/filter.wgsl", include_str!("../../shaders/methods/filter.wgsl")),
    ("methods/pcss.wgsl", include_str!("../../shaders/methods/pcss.wgsl")),
    ("methods/chun_oh/quadtree.wgsl", include_str!("../../shaders/methods/chun_oh/quadtree.wgsl")),
    ("methods/chun_oh/chun_oh.wgsl", include_str!("../../shaders/methods/chun_oh/chun_oh.wgsl")),
    ("methods/chun_oh/quadtree_probe.wgsl", include_str!("../../shaders/methods/chun_oh/quadtree_probe.wgsl")),
    ("methods/wedges/common.wgsl", include_str!("../../shaders/methods/wedges/common.wgsl")),
    ("methods/wedges/tiles.wgsl", include_str!("../../shaders/methods/wedges/tiles.wgsl")),
    ("methods/wedges/rasterize.wgsl", include_str!("../../shaders/methods/wedges/rasterize.wgsl")),
    ("methods/wedges/share.wgsl", include_str!("../../shaders/methods/wedges/share.wgsl")),
    ("methods/wedges/rasterize_umbra.wgsl", include_str!("../../shaders/methods/wedges/rasterize_umbra.wgsl")),
    ("methods/wedges/rasterize_penumbra.wgsl", include_str!("../../shaders/methods/wedges/rasterize_penumbra.wgsl")),
    ("methods/wedges/rasterize_both.wgsl", include_str!("../../shaders/methods/wedges/rasterize_both.wgsl")),
    ("methods/wedges/resolve.wgsl", include_str!("../../shaders/methods/wedges/resolve.wgsl")),
    ("methods/reference/sample_depth.wgsl", include_str!("../../shaders/methods/reference/sample_depth.wgsl")),
    ("methods/reference/accumulate.wgsl", include_str!("../../shaders/methods/reference/accumulate.wgsl")),
];

/// Shaders that are pipelines' entry files: those that declare an entry point and that no
/// other shader imports (an imported file may hold entries that need what its importer
/// defines, as `methods/filter.wgsl` needs `filtered_visibility`).
pub fn entry_shaders() -> impl Iterator<Item = &'static str> {
    SOURCES
        .iter()
        .filter(|(_, text)| text.contains("@vertex") || text.contains("@compute"))
        .filter(|(name, _)| !SOURCES.iter().any(|(_, text)| text.lines().any(|line| line.trim() == format!("#import {name}"))))
        .map(|(name, _)| *name)
}

pub(crate) fn source(name: &str) -> Option<&'static str> {
    SOURCES.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

/// The full WGSL of `name` with its imports resolved.
pub fn compose(name: &str) -> String {
    let mut out = String::new();
    let mut seen = HashSet::new();
    append(name, &mut out, &mut seen);
    out
}

fn append(name: &str, out: &mut String, seen: &mut HashSet<String>) {
    if !seen.insert(name.to_owned()) {
        return;
    }
    let text = source(name).unwrap_or_else(|| panic!("shader `{name}` is not listed in gpu::shaders::SOURCES"));
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        if let Some(import) = line.trim().strip_prefix("#import ") {
            append(import.trim(), out, seen);
        } else if let Some(header) = line.trim().strip_prefix("#unroll ") {
            unroll(name, header, &mut lines, out);
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
}

/// Writes out the block `#unroll i in A..B {` … `}` (its header after `#unroll`, its body the
/// lines up to the `}` that closes it) once per value of `i`. On lavapipe an array that a
/// loop indexes by its counter lives in memory, a load and a store lane by lane per access,
/// where one indexed by constants lives in registers: a loop over the columns of E0's grid
/// (`shaders/e0/grid.wgsl`) whose carried state is arrays runs many times slower than the
/// same loop unrolled. Mesa unrolls only small loops itself; this unrolls the ones a
/// shader marks. Each copy is a block that binds `i` as a `let` constant, so the body is the
/// loop's body unchanged — copied as it stands: a directive inside it is not read.
fn unroll<'a>(name: &str, header: &str, lines: &mut impl Iterator<Item = &'a str>, out: &mut String) {
    let malformed = format!("{name}: `#unroll {header}` is not `#unroll NAME in A..B {{`");
    let parsed = header.split_once(" in ").and_then(|(counter, range)| {
        let (start, end) = range.trim().strip_suffix('{')?.trim().split_once("..")?;
        Some((counter.trim(), start.trim().parse::<u32>().ok()?, end.trim().parse::<u32>().ok()?))
    });
    let (counter, start, end) = parsed.unwrap_or_else(|| panic!("{malformed}"));
    let mut body = Vec::new();
    let mut depth = 1usize;
    for line in lines.by_ref() {
        // Braces in a comment do not count.
        let code = line.split("//").next().unwrap_or_default();
        depth += code.matches('{').count();
        depth = depth.checked_sub(code.matches('}').count()).unwrap_or_else(|| panic!("{name}: unbalanced `}}` in `#unroll {header}`"));
        if depth == 0 {
            assert_eq!(code.trim(), "}", "{name}: `#unroll {header}` closes on a line of its own");
            break;
        }
        body.push(line);
    }
    assert_eq!(depth, 0, "{name}: `#unroll {header}` is not closed");
    for value in start..end {
        out.push_str(&format!("{{ let {counter} = {value}u;\n"));
        for line in &body {
            out.push_str(line);
            out.push('\n');
        }
        out.push_str("}\n");
    }
}

/// Compiles a composed shader into a module on `device`, with wgpu's run-time checks except
/// its loop bounding: naga gives every loop a 64-bit counter that ends it after 2⁶⁴ turns (for
/// untrusted shaders, whose endless loops a driver could miscompile), and on lavapipe a loop
/// pays for it each turn — 4 % of `wedges`' colour pass. These shaders are the crate's own,
/// none taken from a request, and every loop in them has a bound it reaches (a count, a list's
/// length or a search radius). Bounds checks and the guards of integer division stay.
pub fn module(device: &wgpu::Device, name: &str) -> wgpu::ShaderModule {
    let descriptor = wgpu::ShaderModuleDescriptor { label: Some(name), source: wgpu::ShaderSource::Wgsl(compose(name).into()) };
    let checks = wgpu::ShaderRuntimeChecks { force_loop_bounding: false, ..wgpu::ShaderRuntimeChecks::checked() };
    // SAFETY: every loop in `SOURCES` terminates (above); all other checks are kept.
    unsafe { device.create_shader_module_trusted(descriptor, checks) }
}

/// A compute pipeline of `shader`'s `entry` over these bind groups (group *k* is `groups[k]`),
/// with values for the shader's pipeline-overridable constants.
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    (shader, entry): (&str, &str),
    groups: &[&wgpu::BindGroupLayout],
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    let module = module(device, shader);
    let groups: Vec<Option<&wgpu::BindGroupLayout>> = groups.iter().map(|g| Some(*g)).collect();
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &groups,
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
        cache: None,
    })
}

/// Asserts that the WGSL file `name` declares `declaration` verbatim: a constant a shader
/// hard-codes (its passes bind no uniform for it) as Rust defines it. For tests.
#[cfg(test)]
pub(crate) fn assert_declares(name: &str, declaration: &str) {
    let wgsl = source(name).unwrap_or_else(|| panic!("{name} is not listed in SOURCES"));
    assert!(wgsl.contains(declaration), "{name} does not declare `{declaration}`");
}

/// The composed WGSL of `name`, parsed by naga. For tests.
#[cfg(test)]
fn parsed(name: &str) -> naga::Module {
    let source = compose(name);
    naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{name}:\n{}", e.emit_to_string(&source)))
}

/// The members of a WGSL struct with their byte offsets, a nested struct's members flattened
/// into its own (at their offsets within the outer one), padding (`pad…`, `_…`) left out.
#[cfg(test)]
fn wgsl_members(module: &naga::Module, members: &[naga::StructMember], base: u32, out: &mut Vec<(String, u32)>) {
    for member in members {
        let name = member.name.clone().unwrap_or_default();
        match &module.types[member.ty].inner {
            naga::TypeInner::Struct { members: inner, .. } => wgsl_members(module, inner, base + member.offset, out),
            _ if name.starts_with("pad") || name.starts_with('_') => {}
            _ => out.push((name, base + member.offset)),
        }
    }
}

/// Asserts that a Rust struct of `size` bytes with `fields` (name, offset) is laid out as the
/// WGSL struct `wgsl` in `shader` (with its imports): every WGSL member (a nested struct's
/// flattened) at the same offset as the Rust field of its name, every Rust field but padding
/// (`_…`) a WGSL member, and the Rust size the WGSL span (or that span rounded up to the 16
/// bytes of a uniform slot). For tests: `assert_wgsl_layout!` gives the size and offsets.
#[cfg(test)]
pub(crate) fn assert_layout(shader: &str, wgsl: &str, size: usize, fields: &[(&str, usize)]) {
    let module = parsed(shader);
    let (_, ty) =
        module.types.iter().find(|(_, t)| t.name.as_deref() == Some(wgsl)).unwrap_or_else(|| panic!("{shader} has no struct {wgsl}"));
    let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{wgsl} in {shader} is not a struct") };
    let mut flat = Vec::new();
    wgsl_members(&module, members, 0, &mut flat);
    for (name, offset) in &flat {
        let rust = fields.iter().find(|(f, _)| f == name).map(|(_, o)| *o);
        assert_eq!(rust, Some(*offset as usize), "{wgsl}.{name} in {shader}: WGSL offset {offset}, Rust {rust:?}");
    }
    for (field, _) in fields.iter().filter(|(f, _)| !f.starts_with('_')) {
        assert!(flat.iter().any(|(m, _)| m == field), "{wgsl} in {shader} has no member `{field}`");
    }
    let span = *span as usize;
    assert!(size == span || size == span.next_multiple_of(16), "{wgsl} in {shader}: {span} bytes in WGSL, {size} in Rust");
}

/// `assert_layout` for Rust type `$ty` and its fields, by name: size and offsets from the
/// compiler (`size_of`, `offset_of!`).
#[cfg(test)]
macro_rules! assert_wgsl_layout {
    ($ty:ty, $shader:expr, $wgsl:expr, [$($field:ident),* $(,)?]) => {
        $crate::gpu::shaders::assert_layout(
            $shader,
            $wgsl,
            ::std::mem::size_of::<$ty>(),
            &[$((stringify!($field), ::std::mem::offset_of!($ty, $field))),*],
        )
    };
}
#[cfg(test)]
pub(crate) use assert_wgsl_layout;

/// Asserts that `entries`, a bind-group layout made in Rust, holds every resource the WGSL of
/// `shaders` (each with its imports) declares in `group`, as the same kind — a uniform buffer,
/// a read-only or a read-write storage buffer, or a texture — and nothing they all leave out.
/// For tests.
#[cfg(test)]
pub(crate) fn assert_bindings(shaders: &[&str], group: u32, entries: &[wgpu::BindGroupLayoutEntry]) {
    use wgpu::{BindingType, BufferBindingType};
    let mut declared = std::collections::BTreeSet::new();
    for shader in shaders {
        let module = parsed(shader);
        for (_, global) in module.global_variables.iter() {
            let Some(binding) = &global.binding else { continue };
            if binding.group != group {
                continue;
            }
            declared.insert(binding.binding);
            let name = global.name.as_deref().unwrap_or_default();
            let entry = entries.iter().find(|e| e.binding == binding.binding).unwrap_or_else(|| {
                panic!("{shader}: `{name}` at binding {} of group {group} has no entry in the Rust layout", binding.binding)
            });
            let agrees = match (global.space, entry.ty) {
                (naga::AddressSpace::Uniform, BindingType::Buffer { ty: BufferBindingType::Uniform, .. }) => true,
                (naga::AddressSpace::Storage { access }, BindingType::Buffer { ty: BufferBindingType::Storage { read_only }, .. }) => {
                    read_only != access.contains(naga::StorageAccess::STORE)
                }
                (
                    naga::AddressSpace::Handle,
                    BindingType::Texture { .. } | BindingType::StorageTexture { .. } | BindingType::Sampler(_),
                ) => true,
                _ => false,
            };
            assert!(agrees, "{shader}: `{name}` at binding {} is {:?} in WGSL and {:?} in Rust", binding.binding, global.space, entry.ty);
        }
    }
    for entry in entries {
        assert!(declared.contains(&entry.binding), "binding {} of group {group} is declared by none of {shaders:?}", entry.binding);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_shader_parses_and_validates_with_naga() {
        for name in entry_shaders() {
            let source = compose(name);
            let module = naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{name}:\n{}", e.emit_to_string(&source)));
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::default())
                .validate(&module)
                .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        }
    }

    #[test]
    fn constants_mirrored_in_wgsl_match_their_rust_definitions() {
        use crate::light::tables::{EDGE_ANGLES, EDGE_STATIONS, KEY_CELLS};
        use crate::light::E0_GRID;
        // The edge table's shape and JFA's grid of keys over the light.
        assert_declares("common/edge_table.wgsl", &format!("const EDGE_ANGLES: u32 = {EDGE_ANGLES}u;"));
        assert_declares("common/edge_table.wgsl", &format!("const EDGE_STATIONS: u32 = {EDGE_STATIONS}u;"));
        assert_declares("methods/jfa/common.wgsl", &format!("const KEY_CELLS: u32 = {KEY_CELLS}u;"));
        // The light cells every screen-space pass may read. (Constants of higher layers are
        // checked beside their definitions: `render::passes`, `methods::brabec`,
        // `methods::reference`.)
        assert_declares("common/frame_inputs.wgsl", &format!("array<LightCell, {}>", E0_GRID * E0_GRID));
        assert_declares("e0/grid.wgsl", &format!("const SIDE: u32 = {E0_GRID}u;"));
    }

    #[test]
    fn unroll_writes_the_block_once_per_value_and_stops_at_its_brace() {
        let text = "    x[i] = y; // a brace in a comment: {\n    if i > 0u {\n        y += 1.0;\n    }\n}\nafter();";
        let mut lines = text.lines();
        let mut out = String::new();
        unroll("test", "i in 1..3 {", &mut lines, &mut out);
        let copy = |k: u32| {
            format!("{{ let i = {k}u;\n    x[i] = y; // a brace in a comment: {{\n    if i > 0u {{\n        y += 1.0;\n    }}\n}}\n")
        };
        assert_eq!(out, copy(1) + &copy(2));
        assert_eq!(lines.next(), Some("after();"), "the lines after the block are the caller's");
    }

    #[test]
    #[should_panic(expected = "is not closed")]
    fn an_unclosed_unroll_is_refused() {
        unroll("test", "i in 0..2 {", &mut "    x[i] = 0.0;".lines(), &mut String::new());
    }
}
