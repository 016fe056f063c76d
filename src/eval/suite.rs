//! The scenes of a suite, as the command line lists them: built-in scenes by name, and real
//! models — scene files, or folders of them — staged as a user's upload is (contract §3: on a
//! floor, with the camera and light fitted to the model's bounds).

use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::job::{AssetRef, FloorSpec, SceneRef};

/// A scene of the suite: its label in tables and file names, and what a job names.
#[derive(Debug, Clone, PartialEq)]
pub struct SuiteScene {
    pub label: String,
    pub scene: SceneRef,
    /// A file made by others (a real model), not a built-in.
    pub real: bool,
}

impl SuiteScene {
    /// A real model: the file on the default floor, labelled by its name without extension.
    pub fn model(path: &Path) -> Self {
        let label = path.file_stem().map_or_else(|| path.display().to_string(), |s| s.to_string_lossy().into_owned());
        SuiteScene { label, scene: SceneRef { asset: AssetRef::Path(path.to_path_buf()), floor: Some(FloorSpec::default()) }, real: true }
    }
}

/// Whether a path names a scene file penumbra reads.
fn is_scene_file(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
}

/// The scenes `listed` names, in order: an existing folder gives its scene files (sorted by
/// name, not recursing), an existing file itself, anything else a built-in scene with
/// parameters (`terrain:triangles=100000`).
pub fn scenes(listed: &[String]) -> anyhow::Result<Vec<SuiteScene>> {
    let mut scenes = Vec::new();
    for entry in listed {
        let path = Path::new(entry);
        if path.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .with_context(|| format!("cannot read the folder {entry}"))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| is_scene_file(p) && p.is_file())
                .collect();
            anyhow::ensure!(!files.is_empty(), "the folder {entry} holds no .glb or .gltf file");
            files.sort();
            scenes.extend(files.iter().map(|f| SuiteScene::model(f)));
        } else if path.is_file() {
            scenes.push(SuiteScene::model(path));
        } else {
            anyhow::ensure!(!is_scene_file(path) && !entry.contains('/'), "no scene file or folder at {entry}");
            let (name, params) = super::parse_named(entry)?;
            scenes.push(SuiteScene { label: entry.clone(), scene: AssetRef::Builtin { name, params }.into(), real: false });
        }
    }
    let mut labels: Vec<&str> = scenes.iter().map(|s| s.label.as_str()).collect();
    labels.sort_unstable();
    if let Some(twice) = labels.windows(2).find(|w| w[0] == w[1]) {
        anyhow::bail!("two scenes of the suite are both called `{}`: their rows and pictures would mix", twice[0]);
    }
    Ok(scenes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_give_their_scene_files_and_names_give_built_ins() {
        let folder = std::env::temp_dir().join(format!("penumbra-suite-{}", std::process::id()));
        std::fs::create_dir_all(folder.join("nested")).unwrap();
        for name in ["b.glb", "a.gltf", "notes.txt", "nested/c.glb"] {
            std::fs::write(folder.join(name), b"").unwrap();
        }
        let listed = ["torus".to_owned(), folder.display().to_string(), "terrain:triangles=1000".to_owned()];
        let suite = scenes(&listed).unwrap();
        let labels: Vec<&str> = suite.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(labels, ["torus", "a", "b", "terrain:triangles=1000"]);
        assert_eq!(suite.iter().map(|s| s.real).collect::<Vec<_>>(), [false, true, true, false]);
        assert_eq!(suite[1].scene.asset, AssetRef::Path(folder.join("a.gltf")));
        assert_eq!(suite[1].scene.floor, Some(FloorSpec::default()), "a real model is staged on a floor");
        assert_eq!(
            suite[3].scene.asset,
            AssetRef::Builtin { name: "terrain".into(), params: [("triangles".into(), 1000.into())].into_iter().collect() }
        );
        let missing = scenes(&[folder.join("missing.glb").display().to_string()]).unwrap_err();
        assert!(missing.to_string().contains("no scene file"), "{missing}");
        let listed = ["b.glb", "nested/c.glb", "b.glb"].map(|name| folder.join(name).display().to_string());
        let twice = scenes(&listed).unwrap_err();
        assert!(twice.to_string().contains("`b`"), "{twice}");
        std::fs::remove_dir_all(&folder).unwrap();
    }
}
