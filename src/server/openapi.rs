//! The parts of `api/openapi.json` made from the code, so that the document cannot drift from
//! it: `Method` as a `oneOf` over the registry and `auto` with `name` as its discriminator (each
//! method's parameters typed with their ranges, defaults and choices, as `GET /v1/methods` lists them),
//! the built-in scenes (`SceneRef`) and light images (`LightImageRef`), the listing's `method` filter, and the example jobs
//! of `api/examples/` on the operations that take a job. The test
//! `openapi_document_is_generated_from_the_code` (tests/api.rs) holds the file to this, and
//! rewrites it with `PENUMBRA_BLESS=1`.

use serde_json::{json, Map, Value};

use crate::job::auto::AUTO;
use crate::job::Limits;
use crate::light::BUILTIN_LIGHT_IMAGES;
use crate::methods::{ParamSpec, REGISTRY};
use crate::params::ParamKind;
use crate::scene::builtin::BUILTIN_SCENES;

/// `doc` with its generated parts replaced: `examples` are (name, job) pairs.
pub fn generate(doc: &mut Value, examples: &[(String, Value)]) {
    let schemas = &mut doc["components"]["schemas"];
    let mut mapping = Map::new();
    let mut one_of = Vec::new();
    for method in REGISTRY.iter() {
        let schema_name = format!("Method{}", pascal_case(method.name()));
        let reference = format!("#/components/schemas/{schema_name}");
        schemas[&schema_name] = method_schema(&schema_name, method.name(), method.summary(), method.params(), &Limits::default());
        mapping.insert(method.name().to_owned(), json!(reference));
        one_of.push(json!({"$ref": reference}));
    }
    // `auto` is no method of the registry: a budget the server resolves to one (contract §5).
    schemas["MethodAuto"] = json!({
        "title": "MethodAuto",
        "description": "A time or error budget instead of a method: the server chooses the method and parameters its model of \
                        this device predicts to fit (with a 25 % margin): under max_ms alone, the most faithful; under max_error, \
                        the cheapest. A budget nothing is predicted to meet is a 422 budget_unmet naming the closest choice.",
        "type": "object",
        "properties": {
            "name": {"type": "string", "const": AUTO},
            "max_ms": {"type": "number", "exclusiveMinimum": 0, "description": "The render's wall time, ms; at most the job deadline."},
            "max_error": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1,
                          "description": "The mean |V − Vref| over the penumbra."},
        },
        "required": ["name"],
        "anyOf": [{"required": ["max_ms"]}, {"required": ["max_error"]}],
        "additionalProperties": false,
    });
    mapping.insert(AUTO.to_owned(), json!("#/components/schemas/MethodAuto"));
    one_of.push(json!({"$ref": "#/components/schemas/MethodAuto"}));
    schemas["Method"] = json!({
        "description": "A method by name with its parameters next to it (GET /v1/methods lists them with their documentation; \
                        GET /v1/limits with the operator's caps on samples and rounds). Unknown parameters are errors.",
        "oneOf": one_of,
        "discriminator": {"propertyName": "name", "mapping": mapping},
    });
    schemas["SceneRef"]["properties"]["builtin"]["enum"] = json!(BUILTIN_SCENES);
    schemas["LightImageRef"]["properties"]["builtin"]["enum"] = json!(BUILTIN_LIGHT_IMAGES);

    let names: Vec<&str> = REGISTRY.iter().map(|m| m.name()).chain([AUTO]).collect();
    if let Some(parameters) = doc["paths"]["/v1/jobs"]["get"]["parameters"].as_array_mut() {
        for parameter in parameters.iter_mut().filter(|p| p["name"] == "method") {
            parameter["schema"] = json!({"type": "string", "enum": names});
        }
    }

    let examples: Map<String, Value> = examples.iter().map(|(name, job)| (name.clone(), json!({"summary": name, "value": job}))).collect();
    for path in ["/v1/render", "/v1/jobs"] {
        doc["paths"][path]["post"]["requestBody"]["content"]["application/json"]["examples"] = Value::Object(examples.clone());
    }
}

/// One method's schema: `name` its constant, each parameter typed and bounded by the
/// method's own range under the operator's default caps (`--max-samples`, `--max-rounds`: a
/// server's own are in `GET /v1/limits`).
/// Its title is the schema's name, which generated clients name the type after.
fn method_schema(title: &str, name: &str, summary: &str, params: &[ParamSpec], limits: &Limits) -> Value {
    let mut properties = Map::new();
    properties.insert("name".into(), json!({"type": "string", "const": name}));
    for param in params {
        let mut schema = match param.kind {
            ParamKind::Float { default, min, max } => json!({"type": "number", "minimum": min, "maximum": max, "default": default}),
            ParamKind::Integer { default, min, max } => {
                let max = param.cap.map_or(max, |cap| max.min(limits.cap(cap).0));
                json!({"type": "integer", "minimum": min, "maximum": max, "default": default})
            }
            ParamKind::Boolean { default } => json!({"type": "boolean", "default": default}),
            ParamKind::Choice { default, options } => json!({"type": "string", "enum": options, "default": default}),
        };
        schema["description"] = json!(param.doc);
        properties.insert(param.name.into(), schema);
    }
    json!({
        "type": "object",
        "title": title,
        "description": summary,
        "required": ["name"],
        "properties": properties,
        "additionalProperties": false,
    })
}

/// `jfa-l` → `JfaL`, `chun-oh` → `ChunOh`.
fn pascal_case(name: &str) -> String {
    name.split(['-', '_'])
        .map(|part| {
            let mut chars = part.chars();
            chars.next().map(|c| c.to_ascii_uppercase().to_string() + chars.as_str()).unwrap_or_default()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_is_one_typed_branch_of_method() {
        let builtin = json!({"properties": {"builtin": {}}});
        let mut doc = json!({"components": {"schemas": {"SceneRef": builtin, "LightImageRef": builtin}}, "paths": {}});
        generate(&mut doc, &[("torus".into(), json!({"scene": {"builtin": "torus"}}))]);
        let method = &doc["components"]["schemas"]["Method"];
        assert_eq!(method["oneOf"].as_array().unwrap().len(), REGISTRY.len() + 1, "every method and auto");
        assert_eq!(method["discriminator"]["mapping"]["auto"], "#/components/schemas/MethodAuto");
        assert_eq!(method["discriminator"]["mapping"]["jfa-l"], "#/components/schemas/MethodJfaL");
        let reference = &doc["components"]["schemas"]["MethodReference"];
        assert_eq!(reference["properties"]["name"]["const"], "reference");
        assert_eq!(reference["properties"]["samples"]["type"], "integer");
        assert_eq!(reference["additionalProperties"], false);
        assert!(doc["components"]["schemas"]["LightImageRef"]["properties"]["builtin"]["enum"]
            .as_array()
            .unwrap()
            .contains(&json!("mosaic")));
        assert!(!doc["components"]["schemas"]["SceneRef"]["properties"]["builtin"]["enum"].as_array().unwrap().contains(&json!("mosaic")));
        assert_eq!(pascal_case("chun-oh"), "ChunOh");
    }
}
