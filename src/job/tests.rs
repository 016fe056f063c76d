//! Unit tests of `job`.

use super::*;

#[test]
fn a_missing_field_is_named() {
    let error = Job::from_json(br#"{"output": {"width": 64}}"#).unwrap_err();
    assert_eq!((error.code, error.field.as_deref()), (ErrorCode::InvalidField, Some("scene")), "{}", error.message);
}

#[test]
fn deep_nesting_is_refused_before_parsing_and_strings_do_not_count() {
    let deep = format!("{{\"scene\": {}{}}}", "[".repeat(100_000), "]".repeat(100_000));
    let error = Job::from_json(deep.as_bytes()).unwrap_err();
    assert_eq!(error.code, ErrorCode::InvalidJson);
    assert!(error.message.contains("nests deeper"), "{}", error.message);
    assert!(!nesting_exceeds(br#"{"a": "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[", "b": "\\\"{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{"}"#, 3));
    assert!(nesting_exceeds(b"[[[[", 3) && !nesting_exceeds(b"[[[]]]", 3));
}

#[test]
fn parses_the_design_example() {
    let job = Job::from_json(
        br#"{
          "scene":  {"builtin": "torus"},
          "camera": {"eye": [0, 4, 8], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 45},
          "light":  {"center": [0, 5, 0], "direction": [0, -1, 0], "up": [0, 0, -1],
                     "size": [1.0, 1.0], "intensity": 10.0, "image": {"builtin": "stripes"}},
          "method": {"name": "jfa-e", "rounds": 6},
          "shadow_map": {"resolution": 1024},
          "output": {"width": 512, "height": 512, "format": "exr"}
        }"#,
    )
    .unwrap();
    assert_eq!(job.method.name, "jfa-e");
    assert_eq!(job.method.params["rounds"], 6);
    assert_eq!(job.output.format, OutputFormat::Exr);
    assert_eq!(job.light.image, Some(AssetRef::builtin("stripes")));
}

#[test]
fn errors_name_the_field() {
    let err = Job::from_json(br#"{"scene": {"builtin": "torus"}, "camera": {"fov_y_deg": "wide"}}"#).unwrap_err();
    assert_eq!(err.code, ErrorCode::InvalidField);
    assert_eq!(err.field.as_deref(), Some("camera.fov_y_deg"));

    let err = Job::from_json(br#"{"scene": {"builtin": "torus"}, "output": {"widht": 3}}"#).unwrap_err();
    assert_eq!(err.code, ErrorCode::UnknownField);
    assert_eq!(err.field.as_deref(), Some("output.widht"));

    let err = Job::from_json(br#"{"scene": {"builtin": "torus", "id": "x"}}"#).unwrap_err();
    assert_eq!(err.field.as_deref(), Some("scene"));

    let err =
        Job::from_json(br#"{"scene": {"builtin": "torus"}, "output": {"width": 0}}"#).unwrap().validate(&Limits::default()).unwrap_err();
    assert_eq!(err.field.as_deref(), Some("output.width"));

    let err = Job::from_json(b"{not json").unwrap_err();
    assert_eq!(err.code, ErrorCode::InvalidJson);
}
