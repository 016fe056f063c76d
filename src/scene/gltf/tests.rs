//! Unit tests of `gltf`.

use std::io::Cursor;

use std::path::Component;

use base64::Engine as _;

use super::checks::check_glb_container;
use super::synthetic::{height_field, height_field_with_images};
use super::uris::exporter_spellings;
use super::*;

/// `cargo fuzz run scene` found this: a GLB header declaring a length of 0.
#[test]
fn malformed_glb_containers_are_refused_before_parsing() {
    let fuzzed = b"glTF\x02\x00\x00\x00\x00\x00\x00\x00\x80\x02\x00\x00cene\xcd\":[{";
    for bytes in [&fuzzed[..], b"glTF\x02\x00\x00\x00", b"glTF\x02\x00\x00\x00\x14\x00\x00\x00\xff\xff\xff\x7fJSON"] {
        let error = check_glb_container(bytes, "scene").unwrap_err();
        assert_eq!(error.code, ErrorCode::InvalidAsset, "{}", error.message);
        assert_eq!(load(bytes, &Limits::default(), "scene").unwrap_err().code, ErrorCode::InvalidAsset);
    }
    let valid = height_field_glb(3, 1);
    assert!(check_glb_container(&valid, "scene").is_ok());
}

/// `cargo fuzz run scene` found this: a POSITION accessor index past the accessors makes
/// the `gltf` crate's own validator index out of bounds; the loader answers `invalid_asset`.
#[test]
fn an_attribute_naming_a_missing_accessor_is_an_invalid_asset() {
    let document = br#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 5}}]}],
        "accessors": [{"componentType": 5126, "count": 3, "type": "VEC3"}]}"#;
    let error = load(document, &Limits::default(), "scene").unwrap_err();
    assert_eq!((error.code, error.field.as_deref()), (ErrorCode::InvalidAsset, Some("scene")));
}

#[test]
fn counts_and_lengths_are_refused_from_what_the_file_declares() {
    let bytes = height_field_glb(9, 3); // 81 vertices, 128 triangles, 1.3 KiB buffer.
    let refused = |limits: Limits| {
        let error = load(&bytes, &limits, "scene").unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::LimitExceeded, Some("scene")), "{}", error.message);
        error.message
    };
    assert!(refused(Limits { max_vertices: 80, ..Limits::default() }).contains("max_vertices"));
    assert!(refused(Limits { max_triangles: 127, ..Limits::default() }).contains("max_triangles"));
    assert!(refused(Limits { max_body_bytes: 1000, ..Limits::default() }).contains("declares"));
    load(&bytes, &Limits { max_vertices: 81, max_triangles: 128, ..Limits::default() }, "scene").expect("at the limits");

    // A billion vertices declared over a 36-byte buffer: refused from the count alone.
    let document = br#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 5}]}],
        "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA"}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 1000000000, "type": "VEC3"}]}"#;
    let error = load(document, &Limits::default(), "scene").unwrap_err();
    assert!(matches!(error.code, ErrorCode::LimitExceeded | ErrorCode::InvalidAsset), "{error}");
}

#[test]
fn height_fields_load_with_the_requested_triangles_and_differ_by_seed() {
    let bytes = height_field_glb(9, 3);
    let scene = load(&bytes, &Limits::default(), "scene").expect("a valid GLB");
    assert_eq!(scene.indices.len(), 3 * 2 * 8 * 8);
    assert_ne!(bytes, height_field_glb(9, 4));
}

/// A texture is decoded under the same guard as a light image: an EXR whose data window
/// is far larger than its display window (found by `cargo fuzz run light_image`; its 30 GB
/// allocation inside the `exr` crate aborted the process) is refused, `limit_exceeded`.
#[test]
fn a_texture_whose_exr_parts_exceed_the_limits_is_refused() {
    let exr = include_bytes!("../../../fuzz/regressions/light_image-exr-data-window.exr");
    let error = load(&height_field_with_images(&[exr.to_vec()]), &Limits::default(), "scene").unwrap_err();
    assert_eq!((error.code, error.field.as_deref()), (ErrorCode::LimitExceeded, Some("scene")), "{}", error.message);
    assert!(error.message.contains("data window"), "{}", error.message);
}

/// `max_texture_bytes` bounds what a scene's textures take decoded, together: a body of many
/// small files of large images cannot decode to more. Refused from the decoder's own
/// budget (an RGBA image that does not fit what is left) or from the RGBA texels of one
/// whose decoder took less (RGB).
#[test]
fn textures_are_decoded_within_the_scenes_texture_budget() {
    let rgba = image::ColorType::Rgba8;
    let bytes = textured_height_field_glb(&[rgba, rgba, image::ColorType::Rgb8], 64);
    let texture = 64 * 64 * 4;
    let fits = |max_texture_bytes: u64| load(&bytes, &Limits { max_texture_bytes, ..Limits::default() }, "scene");
    let scene = fits(3 * texture).expect("three textures within the budget");
    assert_eq!(scene.textures.len(), 3);
    for (max, refused_image) in [(texture + texture / 2, "image 1"), (2 * texture + 3 * 64 * 64, "image 2"), (3 * texture - 1, "image 2")] {
        let error = fits(max).unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::LimitExceeded, Some("scene")), "{}", error.message);
        assert!(error.message.contains(refused_image) && error.message.contains("max_texture_bytes"), "{max}: {}", error.message);
    }
}

/// A folder `root` holding a height field as `box.gltf` beside `mesh data.bin`, a
/// `secret.bin` outside it, and `root/link.bin`, a symlink to the secret.
struct MultiFile {
    top: PathBuf,
    root: PathBuf,
    bin: Vec<u8>,
}

impl MultiFile {
    fn new(name: &str) -> Self {
        let top = std::env::temp_dir().join(format!("penumbra-uris-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&top);
        let root = top.join("root");
        std::fs::create_dir_all(root.join("sub")).unwrap();
        let (_, bin) = height_field(5, 2);
        std::fs::write(root.join("mesh data.bin"), &bin).unwrap();
        std::fs::write(top.join("secret.bin"), &bin).unwrap();
        std::os::unix::fs::symlink(top.join("secret.bin"), root.join("link.bin")).unwrap();
        let root = std::fs::canonicalize(root).unwrap();
        MultiFile { top, root, bin }
    }

    /// The height field's document with buffer 0 read from `uri`.
    fn document(&self, uri: &str) -> Vec<u8> {
        let (mut document, _) = height_field(5, 2);
        document["buffers"][0]["uri"] = uri.into();
        serde_json::to_vec(&document).unwrap()
    }

    fn load(&self, uri: &str, confined: bool, limits: &Limits) -> JobResult<Scene> {
        let resources = Resources::Beside { folder: &self.root, confined_to: confined.then_some(self.root.as_path()) };
        load_from(&self.document(uri), limits, "scene", resources)
    }
}

impl Drop for MultiFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.top);
    }
}

#[test]
fn relative_uris_are_read_beside_the_document_percent_decoded() {
    let files = MultiFile::new("beside");
    let triangles = 3 * 2 * 4 * 4;
    for uri in ["mesh%20data.bin", "./mesh%20data.bin", "sub/../mesh%20data.bin", "mesh%20data.bin?v=2"] {
        let scene = files.load(uri, true, &Limits::default()).unwrap_or_else(|e| panic!("{uri}: {e}"));
        assert_eq!(scene.indices.len(), triangles, "{uri}");
    }
    // The same document uploaded is refused, naming the URI and the way out.
    let error = load(&files.document("mesh%20data.bin"), &Limits::default(), "body").unwrap_err();
    assert_eq!((error.code, error.field.as_deref()), (ErrorCode::InvalidAsset, Some("body")));
    assert!(error.message.contains("`mesh%20data.bin`") && error.message.contains("GLB"), "{}", error.message);
    // A missing file is named; so is a document whose files outgrow the upload limit.
    let error = files.load("missing.bin", true, &Limits::default()).unwrap_err();
    assert_eq!(error.code, ErrorCode::InvalidAsset);
    assert!(error.message.contains("`missing.bin`"), "{}", error.message);
    let small = Limits { max_body_bytes: files.bin.len() - 1, ..Limits::default() };
    assert_eq!(files.load("mesh%20data.bin", true, &small).unwrap_err().code, ErrorCode::LimitExceeded);
}

/// A 2×2 orange PNG.
fn orange_png() -> Vec<u8> {
    let mut png = Vec::new();
    image::RgbaImage::from_pixel(2, 2, image::Rgba([200, 100, 50, 255]))
        .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png
}

/// What `penumbra submit` uploads: the document and its files as one GLB, which loads
/// alone to the same scene; an image file becomes a view of the BIN chunk.
#[test]
fn a_multi_file_document_packs_into_one_self_contained_glb() {
    let files = MultiFile::new("pack");
    let png = orange_png();
    std::fs::write(files.root.join("sub/tex ture.png"), &png).unwrap();
    let mut document: serde_json::Value = serde_json::from_slice(&files.document("mesh%20data.bin")).unwrap();
    document["images"] = serde_json::json!([{"uri": "sub/tex%20ture.png"}]);
    let bytes = serde_json::to_vec(&document).unwrap();

    let packed = pack(&bytes, &files.root, &Limits::default(), "scene").unwrap();
    let scene = load(&packed, &Limits::default(), "scene").expect("self-contained");
    assert_eq!(scene.indices.len(), 3 * 2 * 4 * 4);
    let glb = gltf::Gltf::from_slice(&packed).unwrap();
    let image = glb.document.images().next().unwrap();
    let gltf::image::Source::View { view, mime_type } = image.source() else { panic!("the image is still a file") };
    assert_eq!(mime_type, "image/png");
    let blob = glb.blob.as_deref().unwrap();
    assert_eq!(&blob[view.offset()..view.offset() + view.length()], png.as_slice());
    // A GLB, or a document naming no file, is left as it is; a missing file is named.
    let glb_bytes = height_field_glb(3, 1);
    assert_eq!(pack(&glb_bytes, &files.root, &Limits::default(), "scene").unwrap(), glb_bytes);
    let error = pack(&files.document("gone.bin"), &files.root, &Limits::default(), "scene").unwrap_err();
    assert!(error.message.contains("`gone.bin`"), "{}", error.message);
}

/// Contract §3: a texture never stops a shadow. Images an exporter names its own way are
/// found beside the document; the ones that cannot be read or decoded are skipped with a
/// warning naming them; a missing buffer still refuses the scene.
#[test]
fn textures_that_cannot_be_read_are_skipped_by_name_and_exporters_spellings_are_found() {
    let files = MultiFile::new("textures");
    let png = orange_png();
    std::fs::write(files.root.join("sub/wood.png"), &png).unwrap();
    std::fs::write(files.root.join("wood.png"), &png).unwrap();
    std::fs::write(files.root.join("paint.tga"), [0u8, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 1, 0, 24, 0, 1, 2, 3]).unwrap();
    std::fs::write(files.top.join("outside.png"), &png).unwrap();
    let uris = [
        "sub/wood.png",              // as glTF writes it
        "D:\\models\\sub\\wood.png", // the author's absolute path: its name beside the document
        ".\\sub\\wood.png",          // Windows separators
        "//sub/wood.png",            // Blender's "relative to the .blend"
        "missing.png",
        "paint.tga",                     // a format glTF does not allow
        "../outside.png",                // outside the directory the server reads
        "Procedural,num=0,type=Voronoi", // not a file at all
    ];
    let mut document: serde_json::Value = serde_json::from_slice(&files.document("mesh%20data.bin")).unwrap();
    document["images"] = uris.iter().map(|uri| serde_json::json!({"uri": uri})).collect();
    document["textures"] = (0..uris.len()).map(|k| serde_json::json!({"source": k})).collect();
    document["materials"] = (0..uris.len())
        .map(
            |k| serde_json::json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": k}, "baseColorFactor": [0.5, 0.25, 0.125, 1.0]}}),
        )
        .collect();
    let primitive = document["meshes"][0]["primitives"][0].clone();
    document["meshes"][0]["primitives"] = (0..uris.len())
        .map(|k| {
            let mut primitive = primitive.clone();
            primitive["material"] = k.into();
            primitive
        })
        .collect();
    let bytes = serde_json::to_vec(&document).unwrap();
    let resources = Resources::Beside { folder: &files.root, confined_to: Some(&files.root) };
    let scene = load_from(&bytes, &Limits::default(), "scene", resources).expect("textures never stop a shadow");
    assert_eq!(scene.textures.len(), 4, "{:?}", scene.warnings);
    assert!(scene.materials.iter().all(|m| m.base_color == [0.5, 0.25, 0.125, 1.0]));
    assert_eq!(scene.materials.iter().filter(|m| m.texture.is_none()).count(), 4);
    let said = |uri: &str, what: &str| {
        assert!(scene.warnings.iter().any(|w| w.contains(&format!("(`{uri}`)")) && w.contains(what)), "{uri}: {what}: {:?}", scene.warnings)
    };
    said("D:\\models\\sub\\wood.png", "read from `wood.png`");
    said(".\\sub\\wood.png", "read from `./sub/wood.png`");
    said("//sub/wood.png", "read from `sub/wood.png`");
    said("missing.png", "is not used");
    said("paint.tga", "PNG, a JPEG or an OpenEXR");
    said("../outside.png", "outside the directory");
    said("Procedural,num=0,type=Voronoi", "is not used");
    assert!(!scene.warnings.iter().any(|w| w.contains("(`sub/wood.png`)")), "read as written: nothing to say");
    // The name alone is read beside the document only, never above it.
    assert!(exporter_spellings("D:\\x\\..\\..").iter().all(|p| p.components().all(|c| matches!(c, Component::Normal(_)))));

    // `penumbra submit` packs what it can embed (its user's own files: `..` too) and leaves
    // the rest to the same warnings.
    let packed = pack(&bytes, &files.root, &Limits::default(), "scene").unwrap();
    let uploaded = load(&packed, &Limits::default(), "scene").unwrap();
    assert_eq!(uploaded.textures.len(), 5, "{:?}", uploaded.warnings);
    assert!(uploaded.warnings.iter().any(|w| w.contains("(`missing.png`)") && w.contains("self-contained")), "{:?}", uploaded.warnings);

    // Geometry is another matter: a missing buffer is refused, naming it.
    let error = files.load("gone.bin", true, &Limits::default()).unwrap_err();
    assert!(error.message.contains("`gone.bin`"), "{}", error.message);
}

/// An exporter that writes a Latin-1 name into the JSON (assimp's OBJ `regr01`): read,
/// the name's byte replaced, and said; in a GLB and in a `.gltf`.
#[test]
fn json_that_is_not_utf8_is_read_with_its_bad_bytes_replaced_and_said() {
    let (mut document, bin) = height_field(3, 1);
    document["nodes"][0]["name"] = "caf\u{e9}".into();
    let latin1 = |json: Vec<u8>| -> Vec<u8> {
        let at = json.windows(2).position(|w| w == "é".as_bytes()).expect("the name");
        [&json[..at], &[0xE9u8][..], &json[at + 2..]].concat()
    };
    let glb_json = latin1(serde_json::to_vec(&document).unwrap());
    let mut padded = glb_json.clone();
    padded.resize(padded.len().next_multiple_of(4), b' ');
    let glb_bytes = [
        &b"glTF"[..],
        &2u32.to_le_bytes(),
        &((20 + padded.len() + 8 + bin.len()) as u32).to_le_bytes(),
        &(padded.len() as u32).to_le_bytes(),
        b"JSON",
        &padded,
        &(bin.len() as u32).to_le_bytes(),
        b"BIN\0",
        &bin,
    ]
    .concat();
    let scene = load(&glb_bytes, &Limits::default(), "scene").expect("repaired");
    assert!(scene.warnings.iter().any(|w| w.contains("UTF-8")), "{:?}", scene.warnings);
    assert_eq!(scene.objects[0], "caf\u{fffd}");
    assert_eq!(scene.triangle_count(), 8);
    let mut embedded = document.clone();
    embedded["buffers"][0]["uri"] =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin)).into();
    let scene = load(&latin1(serde_json::to_vec(&embedded).unwrap()), &Limits::default(), "scene").expect("repaired");
    assert!(scene.warnings.iter().any(|w| w.contains("UTF-8")), "{:?}", scene.warnings);
    // Valid UTF-8 needs no repair, and garbage is still refused.
    assert!(load(&height_field_glb(3, 1), &Limits::default(), "scene").unwrap().warnings.is_empty());
    assert_eq!(load(b"{\"asset\": \xff}", &Limits::default(), "scene").unwrap_err().code, ErrorCode::InvalidAsset);
}

#[test]
fn uris_leading_outside_the_scene_directory_are_refused_naming_the_uri() {
    let files = MultiFile::new("escapes");
    let secret = files.top.join("secret.bin");
    let absolute = secret.display().to_string();
    let file_uri = format!("file://{absolute}");
    let escapes = [
        "../secret.bin",
        "sub/../../secret.bin",
        "%2e%2e/secret.bin",
        "..%2fsecret.bin",
        "link.bin", // a symlink out of the directory
        absolute.as_str(),
        file_uri.as_str(),
        "http://127.0.0.1:1/secret.bin",
        "//127.0.0.1/secret.bin",
        "C:/secret.bin",
    ];
    for uri in escapes {
        let error = files.load(uri, true, &Limits::default()).unwrap_err();
        assert_eq!((error.code, error.field.as_deref()), (ErrorCode::PathNotAllowed, Some("scene")), "{uri}: {}", error.message);
        assert!(error.message.contains(&format!("`{uri}`")), "{uri}: {}", error.message);
    }
    // Unconfined (the CLI reads its user's own files), `..` and symlinks are followed,
    // but absolute, `file:` and network URIs are still not.
    for uri in ["../secret.bin", "link.bin"] {
        files.load(uri, false, &Limits::default()).unwrap_or_else(|e| panic!("{uri}: {e}"));
    }
    for uri in [absolute.as_str(), file_uri.as_str(), "http://127.0.0.1:1/secret.bin"] {
        assert_eq!(files.load(uri, false, &Limits::default()).unwrap_err().code, ErrorCode::PathNotAllowed, "{uri}");
    }
}
