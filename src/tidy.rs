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
        if module == "lib" || module == "main" || module == "tidy" {
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

/// The anchors of a markdown file's headings (outside code blocks).
fn anchors(text: &str) -> Vec<String> {
    let mut in_code = false;
    let mut found = Vec::new();
    for line in text.lines() {
        if line.starts_with("```") {
            in_code = !in_code;
        } else if !in_code && line.starts_with('#') {
            found.push(anchor(line.trim_start_matches('#')));
        }
    }
    found
}

/// The targets of a markdown file's inline links and images, `](target)`, outside code blocks.
fn link_targets(text: &str) -> Vec<String> {
    let mut in_code = false;
    let mut found = Vec::new();
    for line in text.lines() {
        if line.starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            continue;
        }
        for part in line.split("](").skip(1) {
            if let Some(end) = part.find(')') {
                found.push(part[..end].to_owned());
            }
        }
    }
    found
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
    for path in files(&root.join("src"), "rs").into_iter().chain(files(&root.join("shaders"), "wgsl")) {
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
