//! penumbra: a render-as-a-service daemon for soft shadows from coloured area lights.
//!
//! The data flow of one job: `job` (the contract) → `scene` and `light` (assets) → `gpu`
//! (device, pools, timing) → `render` (the frame, pass by pass) → `methods` (one module per
//! shadow method) → `output` (PNG/EXR). `engine` holds the warm state behind both the CLI and
//! `server`. See ARCHITECTURE.md for the map.

pub mod bench;
pub mod client;
pub mod color;
pub mod config;
pub mod engine;
pub mod error;
pub mod eval;
pub mod gpu;
pub mod image_input;
pub mod job;
pub mod jobs;
pub mod light;
pub mod methods;
pub mod output;
pub mod params;
pub mod quality;
pub mod render;
pub mod scene;
pub mod server;
pub mod store;
pub mod supervise;
pub mod timing;
pub mod uploads;

#[cfg(test)]
mod tidy {
    use std::path::{Path, PathBuf};

    /// Files under `root` whose name ends in `.ext`, recursively.
    fn files(root: &Path, ext: &str) -> Vec<PathBuf> {
        let mut found = Vec::new();
        let mut stack = vec![root.to_path_buf()];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(dir).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                } else if path.extension().is_some_and(|e| e == ext) {
                    found.push(path);
                }
            }
        }
        found
    }

    /// Every Rust module opens with a `//!` doc saying what it is for (rust-analyzer's tidy).
    #[test]
    fn every_module_has_a_doc_comment() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        for path in files(&root.join("src"), "rs").into_iter().chain(files(&root.join("tests"), "rs")) {
            let text = std::fs::read_to_string(&path).unwrap();
            assert!(text.starts_with("//!"), "{} lacks a `//!` module doc", path.display());
        }
    }

    /// Every WGSL file is embedded (listed in `gpu::shaders::SOURCES`) and opens with a
    /// comment saying what it is for.
    #[test]
    fn every_wgsl_file_is_listed_and_documented() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        for path in files(&root, "wgsl") {
            let name = path.strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/");
            let text = crate::gpu::shaders::source(&name).unwrap_or_else(|| panic!("{name} is not listed in SOURCES"));
            assert!(text.starts_with("// "), "{name} must open with a comment saying what it is for");
        }
    }

    /// Modules import downward only, as the layer table in ARCHITECTURE.md says: every
    /// `crate::NAME` in a module names its own module or one of a lower layer.
    #[test]
    fn imports_go_down_the_layers() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let architecture = std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap();
        let table = architecture.split("## Layers").nth(1).expect("ARCHITECTURE.md has a Layers section");
        let mut layer_of = std::collections::HashMap::new();
        for row in table.lines().take_while(|l| !l.starts_with("## ")) {
            let cells: Vec<&str> = row.split('|').map(str::trim).collect();
            let Some(layer) = cells.get(1).and_then(|c| c.parse::<u32>().ok()) else { continue };
            for module in cells[2].split(',') {
                layer_of.insert(module.trim().trim_matches('`').to_owned(), layer);
            }
        }
        let src = root.join("src");
        let mut violations = Vec::new();
        for path in files(&src, "rs") {
            let relative = path.strip_prefix(&src).unwrap();
            let module = relative.iter().next().unwrap().to_string_lossy().trim_end_matches(".rs").to_owned();
            if module == "lib" || module == "main" {
                continue;
            }
            let own = *layer_of.get(&module).unwrap_or_else(|| panic!("module `{module}` is missing from the layer table"));
            let text = std::fs::read_to_string(&path).unwrap();
            for used in text.split("crate::").skip(1) {
                let name: String = used.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                if name == module || name.is_empty() {
                    continue;
                }
                let layer =
                    *layer_of.get(&name).unwrap_or_else(|| panic!("{} uses `crate::{name}`, not in the layer table", relative.display()));
                if layer >= own {
                    violations.push(format!("{} (layer {own}) uses crate::{name} (layer {layer})", relative.display()));
                }
            }
        }
        violations.sort();
        violations.dedup();
        assert!(violations.is_empty(), "imports going up or across the layers:\n{}", violations.join("\n"));
    }
}
