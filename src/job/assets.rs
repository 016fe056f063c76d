//! How a job names its assets: a built-in, a path or an upload id (`AssetRef`), and the
//! scene with its optional floor (`SceneRef`, `FloorSpec`), in the job's JSON spellings.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

/// A scene or light image: built in (with parameters), uploaded (by id) or a file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(try_from = "Map<String, Value>", into = "Map<String, Value>")]
pub enum AssetRef {
    Builtin { name: String, params: Map<String, Value> },
    Id(String),
    Path(PathBuf),
}

impl AssetRef {
    pub fn builtin(name: &str) -> Self {
        AssetRef::Builtin { name: name.to_owned(), params: Map::new() }
    }
}

impl TryFrom<Map<String, Value>> for AssetRef {
    type Error = String;

    fn try_from(mut map: Map<String, Value>) -> Result<Self, String> {
        let keys = ["builtin", "id", "path"];
        let present: Vec<&str> = keys.iter().copied().filter(|k| map.contains_key(*k)).collect();
        if present.len() != 1 {
            return Err("expected exactly one of `builtin`, `id` or `path`".into());
        }
        let value = map.remove(present[0]).unwrap_or_default();
        let Value::String(text) = value else {
            return Err(format!("`{}` must be a string", present[0]));
        };
        match present[0] {
            "builtin" => Ok(AssetRef::Builtin { name: text, params: map }),
            other => {
                if let Some(extra) = map.keys().next() {
                    return Err(format!("unknown field `{extra}` next to `{other}`"));
                }
                if other == "id" {
                    Ok(AssetRef::Id(text))
                } else {
                    Ok(AssetRef::Path(PathBuf::from(text)))
                }
            }
        }
    }
}

impl From<AssetRef> for Map<String, Value> {
    fn from(asset: AssetRef) -> Self {
        match asset {
            AssetRef::Builtin { name, mut params } => {
                params.insert("builtin".into(), Value::String(name));
                params
            }
            AssetRef::Id(id) => Map::from_iter([("id".to_owned(), Value::String(id))]),
            AssetRef::Path(path) => Map::from_iter([("path".to_owned(), Value::String(path.to_string_lossy().into_owned()))]),
        }
    }
}

/// The job's scene: the asset, and whether a floor is added under it (contract §3).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(try_from = "Map<String, Value>", into = "Map<String, Value>")]
pub struct SceneRef {
    pub asset: AssetRef,
    pub floor: Option<FloorSpec>,
}

impl From<AssetRef> for SceneRef {
    fn from(asset: AssetRef) -> Self {
        SceneRef { asset, floor: None }
    }
}

impl TryFrom<Map<String, Value>> for SceneRef {
    type Error = String;

    fn try_from(mut map: Map<String, Value>) -> Result<Self, String> {
        let floor = match map.remove("floor") {
            None | Some(Value::Bool(false)) => None,
            Some(Value::Bool(true)) => Some(FloorSpec::default()),
            Some(value @ Value::Object(_)) => {
                let floor: FloorSpec = serde_json::from_value(value).map_err(|e| format!("`floor`: {e}"))?;
                floor.check().map_err(|e| format!("`floor`: {e}"))?;
                Some(floor)
            }
            Some(_) => return Err("`floor` must be true, false or {\"albedo\": [r, g, b], \"margin\": m}".into()),
        };
        Ok(SceneRef { asset: AssetRef::try_from(map)?, floor })
    }
}

impl From<SceneRef> for Map<String, Value> {
    fn from(scene: SceneRef) -> Self {
        let mut map = Map::from(scene.asset);
        if let Some(floor) = scene.floor {
            map.insert("floor".into(), serde_json::to_value(floor).unwrap_or(Value::Bool(true)));
        }
        map
    }
}

/// A receiving ground plane under the scene's bounds: a square centred under them, wider
/// than them by `margin` times the scene's bounding radius on every side (contract §3).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FloorSpec {
    /// Lambertian albedo, linear RGB in [0, 1].
    pub albedo: [f32; 3],
    /// How far the floor reaches past the bounds, in bounding radii (0–100).
    pub margin: f32,
}

impl Default for FloorSpec {
    fn default() -> Self {
        FloorSpec { albedo: [0.8, 0.8, 0.8], margin: 2.0 }
    }
}

impl FloorSpec {
    fn check(&self) -> Result<(), String> {
        if !self.albedo.iter().all(|a| (0.0..=1.0).contains(a)) {
            return Err(format!("albedo {:?} must lie in [0, 1]", self.albedo));
        }
        if !(0.0..=100.0).contains(&self.margin) {
            return Err(format!("margin {} must lie in [0, 100]", self.margin));
        }
        Ok(())
    }
}
