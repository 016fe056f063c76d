//! Tidy checks on the repository itself (after rust-analyzer's): module docs, shader
//! listing, the layers of ARCHITECTURE.md, links in the docs, no history in the code.

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

/// The Rust sources under `src/` and the shaders under `shaders/`.
fn sources(root: &Path) -> Vec<PathBuf> {
    let mut found = files(&root.join("src"), "rs");
    found.extend(files(&root.join("shaders"), "wgsl"));
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

/// The top-level modules a file names: every `crate::NAME` path, the names of a grouped
/// `crate::{a, b::c}` import, and `super::` paths that climb out of the file's own top-level
/// module (`module_path` is the file's module path below the crate).
fn modules_named(text: &str, module_path: &[String]) -> Vec<String> {
    let ident = |rest: &str| -> String { rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect() };
    let mut found = Vec::new();
    for (i, _) in text.match_indices("crate::") {
        // Not `$crate::` (macros) nor a longer word ending in `crate`.
        if text[..i].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let rest = &text[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // Top-level items of the group, split at the commas outside nested braces.
            let (mut depth, mut item_start) = (0usize, true);
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => item_start = true,
                    c if item_start && !c.is_whitespace() => {
                        item_start = false;
                        found.push(ident(&group[k..]));
                    }
                    _ => {}
                }
            }
        } else {
            found.push(ident(rest));
        }
    }
    // `super::` chains: from a file whose module path has n components, k supers reach
    // component n − k; k ≥ n names a top-level module (or the crate root, k > n). Read up to
    // the first inline module (`mod tests {`), inside which a `super::` is one level deeper.
    let outer = text
        .find("\nmod ")
        .filter(|&at| text[at + 1..].lines().next().is_some_and(|l| l.trim_end().ends_with('{')))
        .map_or(text, |at| &text[..at]);
    for (i, _) in outer.match_indices("super::") {
        if outer[..i].ends_with("super::") || outer[..i].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_') {
            continue;
        }
        let mut rest = &outer[i..];
        let mut k = 0;
        while let Some(r) = rest.strip_prefix("super::") {
            rest = r;
            k += 1;
        }
        if k >= module_path.len() {
            found.push(ident(rest));
        }
    }
    found.retain(|name| !name.is_empty());
    found
}

/// The module path of a source file below `src/` (`render/mod.rs` → `[render]`,
/// `scene/gltf/uris.rs` → `[scene, gltf, uris]`).
fn module_path(relative: &Path) -> Vec<String> {
    let mut parts: Vec<String> = relative.iter().map(|p| p.to_string_lossy().trim_end_matches(".rs").to_owned()).collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// Modules import downward only, as the layer table in ARCHITECTURE.md says: every module
/// a file names (by `crate::` paths, grouped imports, or `super::` out of its own module) is
/// its own or one of a lower layer — in every file, submodules' included — and `server`
/// names nothing of `gpu` (it knows nothing of the device: ARCHITECTURE.md's invariants).
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
        let modules = module_path(relative);
        let module = modules[0].clone();
        if ["lib", "main", "tidy"].contains(&module.as_str()) {
            continue;
        }
        let own = *layer_of.get(&module).unwrap_or_else(|| panic!("module `{module}` is missing from the layer table"));
        let text = std::fs::read_to_string(&path).unwrap();
        for name in modules_named(&text, &modules) {
            if name == module {
                continue;
            }
            let layer = *layer_of.get(&name).unwrap_or_else(|| panic!("{} names `{name}`, not in the layer table", relative.display()));
            if layer >= own {
                violations.push(format!("{} (layer {own}) uses {name} (layer {layer})", relative.display()));
            }
            if module == "server" && name == "gpu" {
                violations.push(format!("{} uses gpu: the server knows nothing of the device", relative.display()));
            }
        }
    }
    violations.sort();
    violations.dedup();
    assert!(violations.is_empty(), "imports going up or across the layers:\n{}", violations.join("\n"));
}

#[test]
fn the_layer_test_reads_grouped_imports_and_climbing_supers() {
    let path = |p: &str| module_path(Path::new(p));
    let text = "use crate::{engine::Engine, gpu::{self, pool}, job};\nuse super::super::queue::X;\nlet y = crate::render::thing;";
    let mut named = modules_named(text, &path("server/connections/mod.rs"));
    named.sort();
    assert_eq!(named, ["engine", "gpu", "job", "queue", "render"]);
    // One `super::` from a submodule stays inside its own module.
    assert_eq!(modules_named("use super::Thing;", &path("scene/gltf/uris.rs")), Vec::<String>::new());
    assert_eq!(modules_named("use super::scene::Scene;", &path("eval.rs")), ["scene"]);
}

/// Expands `{a,b}` groups in a path: `e0/{common,grid}.wgsl` → `e0/common.wgsl`, `e0/grid.wgsl`.
fn expand_braces(token: &str) -> Vec<String> {
    match (token.find('{'), token.find('}')) {
        (Some(open), Some(close)) if open < close => token[open + 1..close]
            .split(',')
            .flat_map(|part| expand_braces(&format!("{}{}{}", &token[..open], part.trim(), &token[close + 1..])))
            .collect(),
        _ => vec![token.to_owned()],
    }
}

/// ARCHITECTURE.md's code map names every source and shader file, and only files that exist:
/// a row's "where" is a file or a folder, and a folder's row names its files relative to it.
/// Every path `src/…` or `shaders/…` named anywhere in the document exists too.
#[test]
fn the_code_map_names_every_file() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let architecture = std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap();
    let map = architecture.split("## Code map").nth(1).expect("a Code map section").split("\n## ").next().unwrap();
    let backticked = |text: &str| -> Vec<String> { text.split('`').skip(1).step_by(2).map(str::to_owned).collect() };
    let is_source = |t: &str| t.ends_with(".rs") || t.ends_with(".wgsl");
    let from_root = |t: &str| t.starts_with("src/") || t.starts_with("shaders/");
    let mut named = std::collections::BTreeSet::new();
    let mut missing = Vec::new();
    for row in map.lines().filter(|l| l.starts_with("| `")) {
        let cells: Vec<&str> = row.splitn(3, '|').skip(1).collect();
        let places = backticked(cells[0]);
        let (Some(place), Some(what)) = (places.first(), cells.get(1)) else { continue };
        let mut tokens: Vec<String> = backticked(what).iter().flat_map(|t| expand_braces(t)).filter(|t| is_source(t)).collect();
        if is_source(place) {
            tokens.push(place.to_owned());
        }
        for token in tokens {
            // A token is named from the root, from its row's folder, or beside its row's file.
            let path = if from_root(&token) {
                root.join(&token)
            } else if place.ends_with('/') {
                root.join(place).join(&token)
            } else {
                root.join(place).parent().unwrap().join(&token)
            };
            if path.exists() {
                named.insert(path.canonicalize().unwrap());
            } else {
                missing.push(format!("{place}: {token}"));
            }
        }
    }
    for token in backticked(&architecture).iter().flat_map(|t| expand_braces(t)) {
        if from_root(&token) && !root.join(token.trim_end_matches(')')).exists() {
            missing.push(token);
        }
    }
    let mut left_out: Vec<String> = sources(root)
        .into_iter()
        .filter(|p| p.file_name().is_some_and(|n| n != "tests.rs"))
        .filter(|p| !named.contains(&p.canonicalize().unwrap()))
        .map(|p| p.strip_prefix(root).unwrap().display().to_string())
        .collect();
    left_out.sort();
    missing.sort();
    missing.dedup();
    assert!(missing.is_empty(), "ARCHITECTURE.md names files that do not exist:\n{}", missing.join("\n"));
    assert!(left_out.is_empty(), "ARCHITECTURE.md's code map leaves out:\n{}", left_out.join("\n"));
}

/// The markdown files a reader follows links through: the README, `ARCHITECTURE.md`,
/// everything under `docs/`, and `deploy/README.md`.
fn documents(root: &Path) -> Vec<PathBuf> {
    let mut found = vec![root.join("README.md"), root.join("ARCHITECTURE.md"), root.join("deploy/README.md")];
    found.extend(files(&root.join("docs"), "md"));
    found
}

/// A heading's anchor as GitHub makes it: lower case, punctuation but `-` and `_` dropped,
/// spaces made `-`.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// The lines of a markdown file outside its fenced code blocks (and not their fences).
fn prose_lines(text: &str) -> impl Iterator<Item = &str> {
    let mut in_code = false;
    text.lines().filter(move |line| {
        if line.starts_with("```") {
            in_code = !in_code;
            return false;
        }
        !in_code
    })
}

/// The anchors of a markdown file's headings (outside code blocks).
fn anchors(text: &str) -> Vec<String> {
    prose_lines(text).filter(|line| line.starts_with('#')).map(|line| anchor(line.trim_start_matches('#'))).collect()
}

/// The targets of a markdown file's inline links and images, `](target)`, outside code blocks.
fn link_targets(text: &str) -> Vec<String> {
    prose_lines(text)
        .flat_map(|line| line.split("](").skip(1))
        .filter_map(|part| part.find(')').map(|end| part[..end].to_owned()))
        .collect()
}

/// Every relative link in the README and the docs names a file that exists, and a `#part`
/// names a heading of it.
#[test]
fn every_relative_link_in_the_docs_resolves() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut broken = Vec::new();
    for doc in documents(root) {
        let text = std::fs::read_to_string(&doc).unwrap();
        for target in link_targets(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (file, part) = target.split_once('#').unwrap_or((&target, ""));
            let path = if file.is_empty() { doc.clone() } else { doc.parent().unwrap().join(file) };
            let shown = format!("{}: {target}", doc.strip_prefix(root).unwrap().display());
            if !path.exists() {
                broken.push(format!("{shown} (no such file)"));
            } else if !part.is_empty() && !anchors(&std::fs::read_to_string(&path).unwrap_or_default()).iter().any(|a| a == part) {
                broken.push(format!("{shown} (no such heading)"));
            }
        }
    }
    assert!(broken.is_empty(), "links that lead nowhere:\n{}", broken.join("\n"));
}

/// The README's quick start is two commands, the second of which is the one CI runs.
#[test]
fn the_readme_quick_start_is_what_ci_runs() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let section = readme.split("## Quick start").nth(1).expect("the README has a Quick start section");
    let block = section.split("```sh\n").nth(1).and_then(|b| b.split("```").next()).expect("a sh block");
    let commands: Vec<&str> = block.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(commands.len(), 2, "the quick start is two commands: {commands:?}");
    assert!(commands[0].contains("render") || commands[0].contains("serve"), "the first command runs the main job");
    let ci = std::fs::read_to_string(root.join(".ci/run")).unwrap();
    assert!(ci.lines().any(|l| l.trim() == commands[1]), "`.ci/run` does not run the README's test command `{}`", commands[1]);
}

/// A word that looks like a git commit: 7 to 40 hex digits with a digit and a letter among
/// them, not a `0x` literal.
fn looks_like_a_commit(word: &str) -> bool {
    (7..=40).contains(&word.len())
        && word.chars().all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
        && word.chars().any(|c| c.is_ascii_digit())
        && word.chars().any(|c| c.is_ascii_alphabetic())
}

/// The code says why it is as it is; how it came to be (commits, before and after) is in git
/// and `docs/performance-log.md`. No comment in `src/` or `shaders/` names a commit.
#[test]
fn no_commit_hash_in_the_code() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    for path in sources(root) {
        let text = std::fs::read_to_string(&path).unwrap();
        for (number, line) in text.lines().enumerate() {
            let Some(comment) = line.split_once("//").map(|(_, c)| c) else { continue };
            for word in comment.split(|c: char| !c.is_ascii_alphanumeric()) {
                if looks_like_a_commit(word) {
                    found.push(format!("{}:{}: {word}", path.strip_prefix(root).unwrap().display(), number + 1));
                }
            }
        }
    }
    assert!(found.is_empty(), "commit hashes in comments (history belongs in git and the performance log):\n{}", found.join("\n"));
}
