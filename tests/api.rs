//! The service over real HTTP: the real router on an ephemeral port, spoken to by a real
//! client. PNG and EXR answers, Server-Timing, JSON answers with image links, documented 4xx
//! errors for bad input while other jobs keep being served; and the CLI binary.

mod common;
#[path = "api/tools.rs"]
mod tools;

use std::sync::Arc;

use common::daemon::{free_address, Daemon};
use penumbra::engine::{Engine, PathPolicy, DEFAULT_CACHE_BYTES};
use penumbra::job::Limits;
use penumbra::server::{app, AppState};
use reqwest::StatusCode;
use serde_json::{json, Value};

/// Starts the real server on 127.0.0.1:0 with a small body limit and a scene directory.
async fn start() -> (String, tempdir::Dir) {
    let (base, dir, _, _) = start_configured(DEFAULT_CACHE_BYTES, |state| state).await;
    (base, dir)
}

/// The server with an upload cache of `cache_bytes` and its state set up by `configure`.
async fn start_configured(
    cache_bytes: u64,
    configure: impl FnOnce(AppState) -> AppState,
) -> (String, tempdir::Dir, Arc<Engine>, Arc<AppState>) {
    let scene_dir = tempdir::Dir::new();
    std::fs::write(scene_dir.path().join("inside.png"), b"not really a png").unwrap();
    let gpu = common::engine().gpu();
    let limits = Limits { max_body_bytes: 64 * 1024, max_output_dim: 2048, ..Limits::default() };
    let engine = Arc::new(Engine::new(gpu, limits, PathPolicy::Under(scene_dir.path().to_path_buf())).with_cache_budget(cache_bytes));
    let state = Arc::new(configure(AppState::new(engine.clone(), 8)));
    let warm = state.clone();
    let warm_engine = engine.clone();
    tokio::task::spawn_blocking(move || {
        warm_up(&warm_engine);
        warm.set_ready();
    })
    .await
    .unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let served = state.clone();
    tokio::spawn(async move { axum::serve(listener, app(served)).await.unwrap() });
    (base, scene_dir, engine, state)
}

fn warm_up(engine: &Engine) {
    engine.warm_up().expect("warm-up renders");
}

/// A temporary directory removed on drop (no extra crate for one test).
mod tempdir {
    pub struct Dir(std::path::PathBuf);
    impl Dir {
        pub fn new() -> Self {
            static COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
            let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let path = std::env::temp_dir().join(format!("penumbra-api-{}-{n}", std::process::id()));
            std::fs::create_dir_all(&path).unwrap();
            Self(path)
        }
        pub fn path(&self) -> &std::path::Path {
            &self.0
        }
    }
    impl Drop for Dir {
        fn drop(&mut self) {
            std::fs::remove_dir_all(&self.0).ok();
        }
    }
}

fn small_job(format: &str) -> Value {
    json!({
        "scene": {"builtin": "torus"},
        "light": {"image": {"builtin": "stripes"}},
        "output": {"width": 96, "height": 64, "format": format}
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_methods_and_renders() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();

    let health: Value = client.get(format!("{base}/healthz")).send().await.unwrap().json().await.unwrap();
    assert_eq!(health["status"], "ok");
    let ready = client.get(format!("{base}/readyz")).send().await.unwrap();
    assert_eq!(ready.status(), StatusCode::OK);

    let methods: Value = client.get(format!("{base}/v1/methods")).send().await.unwrap().json().await.unwrap();
    let hard = methods["methods"].as_array().unwrap().iter().find(|m| m["name"] == "hard").expect("hard listed");
    assert!(hard["params"].as_array().unwrap().iter().any(|p| p["name"] == "bias_texels" && p["default"].is_number()));
    assert!(methods["scenes"].as_array().unwrap().contains(&json!("terrain")));
    assert!(methods["light_images"].as_array().unwrap().contains(&json!("quadrants")));
    let param = |method: &str, name: &str| -> Value {
        let method = methods["methods"].as_array().unwrap().iter().find(|m| m["name"] == method).unwrap();
        method["params"].as_array().unwrap().iter().find(|p| p["name"] == name).cloned().unwrap_or_else(|| panic!("{name} listed"))
    };
    assert_eq!(param("wedges", "color_angles")["default"], 8);
    assert_eq!(param("jfa-l", "inner")["default"], true);
    assert_eq!(param("jfa-e", "edge")["default"], "silhouette");

    // PNG with a Server-Timing header naming every phase.
    let response = client.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::OK);
    assert_eq!(response.headers()["content-type"], "image/png");
    let timing = response.headers()["server-timing"].to_str().unwrap().to_owned();
    for phase in ["scene", "shadow_map", "gbuffer", "e0", "method", "composite", "readback", "encode", "total"] {
        assert!(timing.contains(&format!("{phase};dur=")), "Server-Timing lacks {phase}: {timing}");
    }
    let png = image::load_from_memory(&response.bytes().await.unwrap()).unwrap();
    assert_eq!((png.width(), png.height()), (96, 64));

    // EXR with colour, visibility and depth channels.
    let response = client.post(format!("{base}/v1/render")).json(&small_job("exr")).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::OK);
    assert_eq!(response.headers()["content-type"], "image/x-exr");
    let (w, h, channels) = common::decode_exr(&response.bytes().await.unwrap());
    assert_eq!((w, h), (96, 64));
    for name in ["R", "G", "B", "A", "visibility.R", "visibility.G", "visibility.B", "depth"] {
        assert_eq!(channels.get(name).map(Vec::len), Some(96 * 64), "channel {name}");
    }
    let depth = &channels["depth"];
    assert!(depth.iter().any(|d| d.is_infinite()) && depth.iter().any(|d| d.is_finite() && *d > 0.0));
    assert!(channels["visibility.R"].contains(&0.0), "the torus casts a shadow");

    // JSON answer: timings of a warm job (nothing compiled, nothing uploaded) and an image link.
    let answer: Value = client
        .post(format!("{base}/v1/render"))
        .header("accept", "application/json")
        .json(&small_job("png"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(answer["status"], "succeeded");
    assert_eq!(answer["timings"]["pipelines_compiled"], 0);
    assert_eq!(answer["timings"]["scene_cached"], true);
    assert_eq!(answer["timings"]["scene_upload_bytes"], 0);
    let link = answer["image"].as_str().unwrap();
    let image = client.get(format!("{base}{link}")).send().await.unwrap();
    assert_eq!(image.status(), StatusCode::OK);
    assert_eq!(image.bytes().await.unwrap().len() as u64, answer["bytes"].as_u64().unwrap());
    let record: Value =
        client.get(format!("{base}/v1/jobs/{}", answer["id"].as_str().unwrap())).send().await.unwrap().json().await.unwrap();
    assert_eq!(record["id"], answer["id"]);
}

/// Sends `body` and checks the documented error: status, code and field.
async fn expect_error(client: &reqwest::Client, base: &str, body: Vec<u8>, status: StatusCode, code: &str, field: Option<&str>) {
    let response =
        client.post(format!("{base}/v1/render")).header("content-type", "application/json").body(body.clone()).send().await.unwrap();
    assert_eq!(response.status(), status, "body {}", String::from_utf8_lossy(&body[..body.len().min(200)]));
    let answer: Value = response.json().await.unwrap();
    assert_eq!(answer["error"]["code"], code, "{answer}");
    assert!(answer["error"]["message"].as_str().is_some_and(|m| !m.is_empty()));
    match field {
        Some(field) => assert_eq!(answer["error"]["field"], field, "{answer}"),
        None => assert!(answer["error"].get("field").is_none(), "{answer}"),
    }
}

/// A refused request's status and its `error` object.
async fn refusal(response: reqwest::Response) -> (StatusCode, Value) {
    let status = response.status();
    (status, response.json::<Value>().await.unwrap()["error"].clone())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_input_gets_documented_errors_and_the_daemon_keeps_serving() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    let with = |patch: Value| {
        let mut job = small_job("png");
        for (k, v) in patch.as_object().unwrap() {
            job[k] = v.clone();
        }
        serde_json::to_vec(&job).unwrap()
    };
    use StatusCode as S;
    let unprocessable = |code: &'static str, field: &'static str| (S::UNPROCESSABLE_ENTITY, code, Some(field));
    let invalid = |field: &'static str| unprocessable("invalid_field", field);
    for (body, (status, code, field)) in [
        (b"{\"scene\": ".to_vec(), (S::BAD_REQUEST, "invalid_json", None)),
        (b"[1, 2]".to_vec(), (S::BAD_REQUEST, "invalid_json", None)),
        (with(json!({"method": {"name": "magic"}})), unprocessable("unknown_method", "method.name")),
        (with(json!({"method": {"name": "hard", "rounds": 6}})), unprocessable("unknown_field", "method.rounds")),
        (with(json!({"method": {"name": "hard", "bias_texels": -1}})), invalid("method.bias_texels")),
        (with(json!({"scene": {"builtin": "teapot"}})), unprocessable("unknown_builtin", "scene.builtin")),
        (with(json!({"scene": {"id": "ab12"}})), (S::NOT_FOUND, "not_uploaded", Some("scene.id"))),
        (with(json!({"scene": {"path": "../../etc/passwd"}})), (S::FORBIDDEN, "path_not_allowed", Some("scene.path"))),
        (with(json!({"light": {"image": {"path": "inside.png"}}})), unprocessable("invalid_asset", "light.image")),
        (with(json!({"light": {"image": {"builtin": "moon"}}})), unprocessable("unknown_builtin", "light.image.builtin")),
        (with(json!({"output": {"width": 0, "height": 8}})), invalid("output.width")),
        (with(json!({"output": {"width": 4096, "height": 8}})), unprocessable("limit_exceeded", "output.width")),
        (with(json!({"output": {"format": "gif"}})), invalid("output.format")),
        (with(json!({"output": {"width": -3}})), invalid("output.width")),
        (with(json!({"shadow_map": {"resolution": 1_000_000}})), unprocessable("limit_exceeded", "shadow_map.resolution")),
        (with(json!({"camera": {"eye": [0, 1]}})), invalid("camera.eye")),
        (with(json!({"camera": {"fov_y_deg": 180}})), invalid("camera.fov_y_deg")),
        (with(json!({"camera": {"eye": [0, 0, 0], "target": [0, 0, 0]}})), invalid("camera.target")),
        (with(json!({"light": {"direction": [0, 0, 0]}})), invalid("light.direction")),
        (with(json!({"light": {"intensity": -1}})), invalid("light.intensity")),
        (with(json!({"light": {"size": [1, 0]}})), invalid("light.size[1]")),
        (with(json!({"colour": 1})), unprocessable("unknown_field", "colour")),
        // Zero field of view, numbers of the wrong type, and numbers that only overflow once
        // they are f32 (1e39) or not at all representable (1e999): each named.
        (with(json!({"camera": {"fov_y_deg": 0}})), invalid("camera.fov_y_deg")),
        (with(json!({"camera": {"fov_y_deg": "wide"}})), invalid("camera.fov_y_deg")),
        (with(json!({"light": {"size": [1, "1"]}})), invalid("light.size[1]")),
        (with(json!({"light": {"center": [0, 1e39, 0]}})), invalid("light.center")),
        (with(json!({"camera": {"eye": [0, 4, 1e39]}})), invalid("camera.eye")),
        (with(json!({"light": {"intensity": 1e39}})), invalid("light.intensity")),
        (with(json!({"output": {"exposure": 1e39}})), invalid("output.exposure")),
        (br#"{"scene": {"builtin": "torus"}, "light": {"intensity": 1e999}}"#.to_vec(), invalid("light.intensity")),
    ] {
        expect_error(&client, &base, body, status, code, field).await;
    }
    expect_error(&client, &base, vec![b' '; 100 * 1024], S::PAYLOAD_TOO_LARGE, "payload_too_large", None).await;

    let missing = client.get(format!("{base}/v1/jobs/nope/image")).send().await.unwrap();
    assert_eq!(missing.status(), StatusCode::NOT_FOUND);
    let route = client.get(format!("{base}/v2/everything")).send().await.unwrap();
    assert_eq!(route.status(), StatusCode::NOT_FOUND);
    assert_eq!(route.json::<Value>().await.unwrap()["error"]["code"], "not_found");

    // Still serving.
    let response = client.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::OK);
}

#[test]
fn cli_renders_the_embedded_default_and_example_jobs() {
    let dir = tempdir::Dir::new();
    let exe = env!("CARGO_BIN_EXE_penumbra");
    let png = dir.path().join("default.png");
    let timings = dir.path().join("timings.json");
    // A quiet start, as on a headless machine: stderr holds the phase table and nothing else
    // (no loader or layer noise, no log line when nothing is wrong).
    let output = std::process::Command::new(exe)
        .args(["render", "-o", png.to_str().unwrap(), "--timings-json", timings.to_str().unwrap()])
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .env_remove("MESA_VK_DEVICE_SELECT")
        .env_remove("PENUMBRA_LOG")
        .output()
        .unwrap();
    assert!(output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    let table = [
        "adapter ",
        "phase ",
        "scene ",
        "shadow_map ",
        "gbuffer ",
        "e0 ",
        "method ",
        "composite ",
        "readback ",
        "encode ",
        "total ",
        "cpu ",
        "wrote ",
    ];
    for line in stderr.lines() {
        assert!(table.iter().any(|start| line.starts_with(start)), "stderr holds more than the phase table: {line:?}\n{stderr}");
    }
    assert!(stderr.lines().any(|l| l.starts_with("total ")), "{stderr}");
    let image = image::open(&png).unwrap();
    assert_eq!((image.width(), image.height()), (512, 512));
    let report: Value = serde_json::from_slice(&std::fs::read(&timings).unwrap()).unwrap();
    assert!(report["timings"]["phases"].as_array().unwrap().len() >= 8);
    // What the render cost the process in CPU time: some, whatever the machine.
    assert!(report["process_cpu_ms"].as_f64().unwrap() > 0.0, "{report}");

    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/api/examples/torus-stripes.json");
    let exr = dir.path().join("example.exr");
    // Logs as JSON objects for collectors.
    let output = std::process::Command::new(exe)
        .args(["--log-format", "json", "render", example, "-o", exr.to_str().unwrap()])
        .env("PENUMBRA_LOG", "info")
        .output()
        .unwrap();
    assert!(output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    let adapter_line = stderr.lines().find(|l| l.contains("GPU adapter")).expect("the adapter is logged");
    let logged: Value = serde_json::from_str(adapter_line).expect("a JSON log line");
    assert_eq!(logged["level"], "INFO");
    let (_, _, channels) = common::decode_exr(&std::fs::read(&exr).unwrap());
    assert!(channels.contains_key("visibility.G"));

    // A scene file instead of a job: staged on a floor, its shadow in view, warnings said.
    let (mut document, bin) = common::test_gltf();
    std::fs::write(dir.path().join("tri.bin"), &bin).unwrap();
    document["buffers"][0]["uri"] = "tri.bin".into();
    document["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]);
    std::fs::write(dir.path().join("tri.gltf"), document.to_string()).unwrap();
    let staged = dir.path().join("staged.exr");
    let output = std::process::Command::new(exe)
        .args(["render", dir.path().join("tri.gltf").to_str().unwrap(), "-o", staged.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(String::from_utf8_lossy(&output.stderr).contains("warning: extension `KHR_materials_emissive_strength` is ignored"));
    let (_, _, channels) = common::decode_exr(&std::fs::read(&staged).unwrap());
    let shadowed = channels["visibility.R"].iter().filter(|&&v| v < 0.5).count();
    assert!(shadowed > 100, "the shadow on the floor is in view: {shadowed} pixels");

    // `auto` from the command line: chosen by the shipped model, and said.
    let auto = dir.path().join("auto.json");
    std::fs::write(
        &auto,
        r#"{"scene": {"builtin": "torus"}, "output": {"width": 64, "height": 48}, "method": {"name": "auto", "max_ms": 2000}}"#,
    )
    .unwrap();
    let output = std::process::Command::new(exe).args(["render", auto.to_str().unwrap(), "-o", png.to_str().unwrap()]).output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(String::from_utf8_lossy(&output.stderr).contains("auto: "), "{}", String::from_utf8_lossy(&output.stderr));
    std::fs::write(&auto, r#"{"scene": {"builtin": "torus"}, "method": {"name": "auto", "max_error": 1e-6}}"#).unwrap();
    let output = std::process::Command::new(exe).args(["render", auto.to_str().unwrap(), "-o", png.to_str().unwrap()]).output().unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("method.max_error"));

    // A bad job: one clear line and a non-zero exit.
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"scene": {"builtin": "torus"}, "method": {"name": "nope"}}"#).unwrap();
    let output = std::process::Command::new(exe).args(["render", bad.to_str().unwrap(), "-o", png.to_str().unwrap()]).output().unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("method.name"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openapi_document_matches_the_server() {
    let doc: Value = serde_json::from_str(include_str!("../api/openapi.json")).unwrap();
    assert_eq!(doc["openapi"], "3.1.0");
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    // Every documented path is routed (a placeholder id gives 404 `not_found` for a job,
    // never the router's "no such route").
    for (path, item) in doc["paths"].as_object().unwrap() {
        let url = format!("{base}{}", path.replace("{id}", "0"));
        for method in item.as_object().unwrap().keys() {
            let response = match method.as_str() {
                "get" => client.get(&url).send().await.unwrap(),
                "post" => client.post(&url).json(&small_job("png")).send().await.unwrap(),
                "delete" => client.delete(&url).send().await.unwrap(),
                "put" => client.put(&url).body("{}").send().await.unwrap(),
                "head" => client.head(&url).send().await.unwrap(),
                other => panic!("undocumented verb {other}"),
            };
            let status = response.status();
            let body = response.bytes().await.unwrap();
            // (A HEAD answer has no body: its 404 is the documented "not held".)
            let routed = status != StatusCode::NOT_FOUND || method == "head" || !String::from_utf8_lossy(&body).contains("no such route");
            assert!(routed, "{method} {path} is documented but not served");
            assert!(item[method]["responses"].get(status.as_str()).is_some(), "{method} {path} answered {status}, which is not documented");
        }
    }
    // Every documented error code is one the server can send, and every example job is valid.
    let codes = doc["components"]["schemas"]["Error"]["properties"]["error"]["properties"]["code"]["enum"].as_array().unwrap();
    assert!(codes.contains(&json!("invalid_json")) && codes.contains(&json!("limit_exceeded")));
    for entry in std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/api/examples")).unwrap() {
        let path = entry.unwrap().path();
        let job = penumbra::job::Job::from_json(&std::fs::read(&path).unwrap()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        penumbra::engine::check_job(&job, &Limits::default()).unwrap();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn compare_reports_quality_against_a_cached_reference() {
    let (base, _dir, engine, _) = start_configured(DEFAULT_CACHE_BYTES, |state| state).await;
    let client = reqwest::Client::new();
    let mut job = small_job("png");
    job["compare"] = json!(true);
    let ask = |job: Value| {
        let client = client.clone();
        let base = base.clone();
        async move {
            let response = client.post(format!("{base}/v1/render")).header("accept", "application/json").json(&job).send().await.unwrap();
            assert_eq!(response.status(), StatusCode::OK);
            response.json::<Value>().await.unwrap()
        }
    };
    let first = ask(job.clone()).await;
    let quality = &first["quality"];
    for kind in ["visibility", "color"] {
        for region in ["whole", "penumbra"] {
            for metric in ["rmse", "mae", "ssim", "flip"] {
                assert!(quality[kind][region][metric].is_number(), "{kind}.{region}.{metric} in {quality}");
            }
        }
    }
    assert!(quality["penumbra_pixels"].as_u64().unwrap() > 0);
    assert!(quality["visibility"]["penumbra"]["rmse"].as_f64().unwrap() > 0.05, "hard is far from the truth in the penumbra");
    assert!(first["timings"]["phases"].as_array().unwrap().iter().any(|p| p["name"] == "reference"));
    let misses = engine.stats().reference_cache_misses;

    // Another method setting over the same scene, view and light reuses the reference.
    job["method"] = json!({"name": "hard", "bias_texels": 3.0});
    let second = ask(job.clone()).await;
    assert!(second["quality"]["visibility"]["whole"]["rmse"].is_number());
    let stats = engine.stats();
    assert_eq!(stats.reference_cache_misses, misses, "the reference was rendered again");
    assert!(stats.reference_cache_hits >= 1);

    // Without `compare`, no quality.
    job["compare"] = json!(false);
    assert!(ask(job).await["quality"].is_null());
}

#[tokio::test(flavor = "multi_thread")]
async fn uploads_are_content_addressed_cached_under_a_budget_and_rendered_by_id() {
    let glb = common::as_glb();
    let gltf = common::as_gltf_with_data_uri();
    // Room for one of the two (equal) test scenes, not both: the second evicts the first.
    let cost = 2 * penumbra::scene::gltf::load(&glb, &Limits::default(), "scene").unwrap().gpu_bytes();
    let (base, dir, engine, _) = start_configured(cost + cost / 2, |state| state).await;
    let client = reqwest::Client::new();
    let upload = |path: &'static str, body: Vec<u8>| {
        let request = client.post(format!("{base}{path}")).body(body);
        async move {
            let response = request.send().await.unwrap();
            let status = response.status();
            (status, response.json::<Value>().await.unwrap())
        }
    };
    let render = |scene: Value, light: Value| {
        let job = json!({"scene": scene, "light": light, "method": {"name": "hard"}, "output": {"width": 64, "height": 48}});
        let request = client.post(format!("{base}/v1/render")).json(&job);
        async move {
            let response = request.send().await.unwrap();
            let status = response.status();
            (status, response.bytes().await.unwrap())
        }
    };

    // The id is the content: the same bytes again are the same entry and cost nothing.
    let (status, first) = upload("/v1/scenes", glb.clone()).await;
    assert_eq!(status, StatusCode::CREATED, "{first}");
    let id = first["id"].as_str().unwrap().to_owned();
    assert_eq!(id, sha256_hex(&glb), "the id is the SHA-256 a client can compute");
    assert_eq!(first["cache_bytes"].as_u64(), Some(cost), "{first}");
    let (status, again) = upload("/v1/scenes", glb.clone()).await;
    assert_eq!((status, &again["id"], &again["created"]), (StatusCode::OK, &first["id"], &json!(false)));
    // HEAD says whether the server holds an id; PUT uploads under an id the server checks.
    let head = |path: String| client.head(format!("{base}{path}")).send();
    assert_eq!(head(format!("/v1/scenes/{id}")).await.unwrap().status(), StatusCode::OK);
    assert_eq!(head(format!("/v1/lights/{id}")).await.unwrap().status(), StatusCode::NOT_FOUND, "ids are per kind");
    let put = |path: String, body: Vec<u8>| client.put(format!("{base}{path}")).body(body).send();
    assert_eq!(put(format!("/v1/scenes/{id}"), glb.clone()).await.unwrap().status(), StatusCode::OK);
    let wrong = put(format!("/v1/scenes/{}", sha256_hex(b"other")), glb.clone()).await.unwrap();
    assert_eq!(wrong.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(wrong.json::<Value>().await.unwrap()["error"]["field"], "id");
    assert_eq!(put("/v1/scenes/scene-1".into(), glb.clone()).await.unwrap().status(), StatusCode::UNPROCESSABLE_ENTITY);

    // Rendered by id it is the same picture as the same file rendered by path.
    std::fs::write(dir.path().join("scene.glb"), &glb).unwrap();
    let (status, by_id) = render(json!({"id": id}), json!({})).await;
    assert_eq!(status, StatusCode::OK);
    let (_, by_path) = render(json!({"path": dir.path().join("scene.glb")}), json!({})).await;
    assert_eq!(by_id, by_path, "upload and file render the same bytes");

    // A light image by id.
    let mut png = std::io::Cursor::new(Vec::new());
    image::RgbaImage::from_fn(4, 2, |x, _| image::Rgba([255, (x * 60) as u8, 0, 255])).write_to(&mut png, image::ImageFormat::Png).unwrap();
    let (status, light) = upload("/v1/lights", png.into_inner()).await;
    assert_eq!(status, StatusCode::CREATED, "{light}");
    let (status, _) = render(json!({"id": id}), json!({"image": {"id": light["id"]}})).await;
    assert_eq!(status, StatusCode::OK);

    // Under the budget a second scene evicts the least recently used one, which must be sent again.
    let (status, second) = upload("/v1/scenes", gltf).await;
    assert_eq!(status, StatusCode::CREATED);
    assert_ne!(second["id"], first["id"]);
    let (status, body) = render(json!({"id": id}), json!({})).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(String::from_utf8_lossy(&body).contains("not_uploaded"), "{}", String::from_utf8_lossy(&body));
    let stats = engine.upload_stats();
    assert!(stats.evictions >= 1 && stats.bytes <= stats.budget_bytes, "{stats:?}");

    // Deleting: 204, then 404; a light id is no scene.
    let delete = |path: String| client.delete(format!("{base}{path}")).send();
    let second_id = second["id"].as_str().unwrap();
    assert_eq!(delete(format!("/v1/scenes/{second_id}")).await.unwrap().status(), StatusCode::NO_CONTENT);
    assert_eq!(delete(format!("/v1/scenes/{second_id}")).await.unwrap().status(), StatusCode::NOT_FOUND);
    assert_eq!(render(json!({"id": light["id"]}), json!({})).await.0, StatusCode::NOT_FOUND);

    // Not a scene, not an image: 422 naming the body.
    let (status, error) = upload("/v1/scenes", b"{\"not\": \"gltf\"}".to_vec()).await;
    assert_eq!((status, error["error"]["code"].as_str()), (StatusCode::UNPROCESSABLE_ENTITY, Some("invalid_asset")), "{error}");
    let (status, _) = upload("/v1/lights", b"GIF89a".to_vec()).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
}

#[tokio::test(flavor = "multi_thread")]
async fn metrics_parse_as_prometheus_text_and_move_with_jobs() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    let scrape = || {
        let request = client.get(format!("{base}/metrics"));
        async move {
            let response = request.send().await.unwrap();
            assert_eq!(response.status(), StatusCode::OK);
            assert!(response.headers()[reqwest::header::CONTENT_TYPE].to_str().unwrap().starts_with("text/plain; version=0.0.4"));
            let text = response.text().await.unwrap();
            prometheus_parse::Scrape::parse(text.lines().map(|l| Ok(l.to_owned()))).expect("Prometheus text format")
        }
    };
    let value = |scrape: &prometheus_parse::Scrape, name: &str, labels: &[(&str, &str)]| -> f64 {
        scrape
            .samples
            .iter()
            .filter(|s| s.metric == name && labels.iter().all(|(k, v)| s.labels.get(k) == Some(*v)))
            .map(|s| match s.value {
                prometheus_parse::Value::Counter(v) | prometheus_parse::Value::Gauge(v) | prometheus_parse::Value::Untyped(v) => v,
                prometheus_parse::Value::Histogram(ref buckets) => buckets.last().map_or(0.0, |b| b.count),
                _ => 0.0,
            })
            .sum()
    };
    let before = scrape().await;
    // One good job, one bad one, one unknown method (labelled `unknown`, not by the client's text).
    client.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.unwrap();
    client.post(format!("{base}/v1/render")).body("{").send().await.unwrap();
    let mut unknown = small_job("png");
    unknown["method"] = json!({"name": "made-up"});
    client.post(format!("{base}/v1/render")).json(&unknown).send().await.unwrap();
    let after = scrape().await;
    let jobs = |s: &prometheus_parse::Scrape, outcome: &str| value(s, "penumbra_jobs_total", &[("outcome", outcome)]);
    assert_eq!(jobs(&after, "ok") - jobs(&before, "ok"), 1.0);
    assert_eq!(jobs(&after, "invalid_json") - jobs(&before, "invalid_json"), 1.0);
    assert_eq!(value(&after, "penumbra_jobs_total", &[("method", "unknown"), ("outcome", "unknown_method")]), 1.0);
    assert!(!after.samples.iter().any(|s| s.labels.values().any(|v| v == "made-up")), "client text never becomes a label");
    assert!(value(&after, "penumbra_phase_duration_seconds_count", &[("phase", "shadow_map")]) >= 1.0);
    assert_eq!(value(&after, "penumbra_jobs_in_flight", &[]), 0.0);
    assert!(value(&after, "penumbra_pipelines", &[]) > 0.0);
    assert!(value(&after, "penumbra_pool_allocations_total", &[("pool", "targets"), ("result", "reused")]) > 0.0);
    assert_eq!(value(&after, "penumbra_device_info", &[]), 1.0);
    assert_eq!(value(&after, "penumbra_device_resets_total", &[]), 0.0);
    // HTTP requests by route template and status; the process.
    assert!(value(&after, "penumbra_http_requests_total", &[("route", "/v1/render"), ("status", "200")]) >= 1.0);
    assert!(value(&after, "penumbra_http_requests_total", &[("route", "/v1/render"), ("status", "400")]) >= 1.0);
    assert!(value(&after, "penumbra_http_request_duration_seconds_count", &[("route", "/v1/render")]) >= 3.0);
    assert!(value(&after, "process_resident_memory_bytes", &[]) > 0.0 && value(&after, "process_cpu_seconds_total", &[]) > 0.0);
    // Prometheus's naming rules: counters end in `_total`, one quantity per metric (no `what`
    // label), units in names, bounded labels (routes are templates, statuses numbers).
    for sample in &after.samples {
        let name = sample.metric.as_str();
        if matches!(sample.value, prometheus_parse::Value::Counter(_)) {
            assert!(name.ends_with("_total"), "counter {name} does not end in _total");
        }
        assert!(!sample.labels.contains_key("what"), "{name} mixes quantities behind a `what` label");
        assert!(!name.contains("_ms") && !name.ends_with("_s"), "{name}: seconds, in full");
        if let Some(route) = sample.labels.get("route") {
            assert!(route.starts_with('/') || route == "(no route)", "{name}: route {route} is not a template");
        }
        if let Some(status) = sample.labels.get("status") {
            assert!(status.parse::<u16>().is_ok(), "{name}: status {status}");
        }
    }
    for name in after.docs.keys().filter(|name| name.contains("bytes")) {
        assert!(name.ends_with("_bytes") || name.ends_with("_bytes_total"), "{name}: the unit ends the name");
    }
    // The same state as JSON for the dashboard.
    let stats: Value = client.get(format!("{base}/v1/stats")).send().await.unwrap().json().await.unwrap();
    assert!(
        stats["engine"]["pipelines"].as_u64().unwrap() > 0 && stats["engine"]["uploads"]["budget_bytes"].as_u64().unwrap() > 0,
        "{stats}"
    );
    assert_eq!(stats["jobs_in_flight"], 0);
}

/// Waits (at most 30 s) until a daemon at `base` answers `/readyz` with 200.
async fn wait_ready(base: &str) {
    let client = reqwest::Client::new();
    for _ in 0..300 {
        if client.get(format!("{base}/readyz")).send().await.is_ok_and(|r| r.status() == StatusCode::OK) {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    panic!("the daemon at {base} did not become ready in 30 s");
}

/// Polls `/metrics` (at most 30 s) until `ready` holds for its text.
async fn wait_for_metrics(client: &reqwest::Client, base: &str, ready: impl Fn(&str) -> bool) {
    for _ in 0..600 {
        let text = client.get(format!("{base}/metrics")).send().await.unwrap().text().await.unwrap();
        if ready(&text) {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    panic!("the metrics never reached the expected state");
}

/// `penumbra_jobs_total{outcome="cancelled"}` summed over methods.
fn cancelled_jobs(metrics: &str) -> u64 {
    metrics
        .lines()
        .filter(|l| l.starts_with("penumbra_jobs_total{") && l.contains(r#"outcome="cancelled""#))
        .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .sum::<f64>() as u64
}

/// Polls `/v1/stats` (at most 30 s) until `ready` holds for it.
async fn wait_for_stats(client: &reqwest::Client, base: &str, ready: impl Fn(&Value) -> bool) {
    for _ in 0..600 {
        let stats: Value = client.get(format!("{base}/v1/stats")).send().await.unwrap().json().await.unwrap();
        if ready(&stats) {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    panic!("the server never reached the expected state");
}

#[tokio::test(flavor = "multi_thread")]
async fn the_queue_is_bounded_has_a_deadline_and_drops_jobs_whose_client_left() {
    use penumbra::server::QueueConfig;
    use std::time::Duration;
    let client = reqwest::Client::new();
    let render = |base: &str| client.post(format!("{base}/v1/render")).json(&small_job("png")).send();

    // Room for one job. With the device held, one job is admitted and waits; the next is
    // refused at once with 429 and Retry-After; once the device is free the first completes.
    let one = QueueConfig { capacity: 1, concurrency: 1, deadline: Duration::from_secs(60) };
    let (base, _dir, _, state) = start_configured(DEFAULT_CACHE_BYTES, |state| state.with_queue(one)).await;
    let held = state.try_hold_device().expect("the device is free");
    let waiting = tokio::spawn(render(&base));
    wait_for_stats(&client, &base, |s| s["jobs_queued"] == 1).await;
    let refused = render(&base).await.unwrap();
    assert_eq!(refused.status(), StatusCode::TOO_MANY_REQUESTS);
    assert_eq!(refused.headers()[reqwest::header::RETRY_AFTER], "1");
    assert_eq!(refused.json::<Value>().await.unwrap()["error"]["code"], "queue_full");
    drop(held);
    assert_eq!(waiting.await.unwrap().unwrap().status(), StatusCode::OK, "the admitted job runs once the device is free");

    // A job that cannot reach the device before the deadline fails with 503; one whose client
    // gives up while it waits is dropped, never rendered, and counted as cancelled.
    let short = QueueConfig { capacity: 8, concurrency: 1, deadline: Duration::from_secs(1) };
    let (base, _dir, _, state) = start_configured(DEFAULT_CACHE_BYTES, |state| state.with_queue(short)).await;
    let held = state.try_hold_device().expect("the device is free");
    let late = render(&base).await.unwrap();
    assert_eq!(late.status(), StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(late.json::<Value>().await.unwrap()["error"]["code"], "deadline_exceeded");
    let impatient = reqwest::Client::builder().timeout(Duration::from_millis(100)).build().unwrap();
    assert!(impatient.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.is_err(), "the client gives up");
    wait_for_metrics(&client, &base, |text| cancelled_jobs(text) == 1).await; // The abandoned job.
    drop(held);
    wait_for_stats(&client, &base, |s| s["jobs_queued"] == 0 && s["jobs_in_flight"] == 0).await;
    assert_eq!(render(&base).await.unwrap().status(), StatusCode::OK, "the queue serves again");
}

#[tokio::test(flavor = "multi_thread")]
async fn submitted_jobs_report_progress_as_server_sent_events_and_finish() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    let job = json!({"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 24, "resolution": 256},
                     "output": {"width": 64, "height": 48}});
    let accepted = client.post(format!("{base}/v1/jobs")).json(&job).send().await.unwrap();
    assert_eq!(accepted.status(), StatusCode::ACCEPTED);
    let location = accepted.headers()[reqwest::header::LOCATION].to_str().unwrap().to_owned();
    let links: Value = accepted.json().await.unwrap();
    assert_eq!(location, links["record"]);
    // The stream ends after the final event, so the whole body can be read.
    let stream = client.get(format!("{base}{}", links["events"].as_str().unwrap())).send().await.unwrap();
    assert_eq!(stream.headers()[reqwest::header::CONTENT_TYPE], "text/event-stream");
    let text = stream.text().await.unwrap();
    let events: Vec<(String, Value)> = text
        .split("\n\n")
        .filter(|block| block.contains("data:"))
        .map(|block| {
            let name = block.lines().find_map(|l| l.strip_prefix("event: ")).unwrap_or_default().to_owned();
            let data = block.lines().find_map(|l| l.strip_prefix("data: ")).unwrap();
            (name, serde_json::from_str(data).unwrap())
        })
        .collect();
    let (last, rest) = events.split_last().expect("events");
    assert_eq!(last.0, "succeeded", "{text}");
    assert!(rest.iter().all(|(name, _)| name == "progress"), "{text}");
    // Samples done only grow, and reach all of them.
    let done: Vec<u64> = events.iter().map(|(_, e)| e["done"].as_u64().unwrap()).collect();
    assert!(done.windows(2).all(|w| w[0] <= w[1]), "{done:?}");
    assert_eq!(last.1["done"], last.1["total"]);
    assert!(last.1["total"].as_u64().unwrap() >= 24, "{}", last.1);
    // The record and the image.
    let record: Value = client.get(format!("{base}{location}")).send().await.unwrap().json().await.unwrap();
    assert_eq!(record["status"], "succeeded");
    let image = client.get(format!("{base}{}/image", location)).send().await.unwrap();
    assert_eq!(image.headers()[reqwest::header::CONTENT_TYPE], "image/png");
    // A bad job is refused at submission, not later.
    let bad = client.post(format!("{base}/v1/jobs")).json(&json!({"method": {"name": "nope"}})).send().await.unwrap();
    assert_eq!(bad.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(client.get(format!("{base}/v1/jobs/0/events")).send().await.unwrap().status(), StatusCode::NOT_FOUND);
}

#[tokio::test(flavor = "multi_thread")]
async fn draining_for_shutdown_waits_for_submitted_jobs_and_admits_no_more() {
    use std::time::Duration;
    let queue = penumbra::server::QueueConfig { capacity: 4, concurrency: 1, deadline: Duration::from_secs(60) };
    let (base, _dir, _, state) = start_configured(DEFAULT_CACHE_BYTES, |state| state.with_queue(queue)).await;
    let client = reqwest::Client::new();
    let held = state.try_hold_device().expect("the device is free");
    let accepted: Value = client.post(format!("{base}/v1/jobs")).json(&small_job("png")).send().await.unwrap().json().await.unwrap();
    wait_for_stats(&client, &base, |s| s["jobs_queued"] == 1).await;
    let draining = state.clone();
    let drain = tokio::spawn(async move { draining.drain(Duration::from_secs(60)).await });
    drop(held);
    assert!(drain.await.unwrap(), "the submitted job finished before the drain returned");
    let record: Value = client.get(format!("{base}{}", accepted["record"].as_str().unwrap())).send().await.unwrap().json().await.unwrap();
    assert_eq!(record["status"], "succeeded");
    // A stopping (drained) daemon admits nothing new: 503, and readiness goes away, so a load
    // balancer sends the work elsewhere.
    for path in ["/v1/render", "/v1/jobs"] {
        let refused = client.post(format!("{base}{path}")).json(&small_job("png")).send().await.unwrap();
        assert_eq!(refused.status(), StatusCode::SERVICE_UNAVAILABLE, "{path}");
        assert_eq!(refused.json::<Value>().await.unwrap()["error"]["code"], "shutting_down");
    }
    assert_eq!(client.get(format!("{base}/readyz")).send().await.unwrap().status(), StatusCode::SERVICE_UNAVAILABLE);
}

/// Device loss (contract §3): a device destroyed between jobs, and one destroyed in
/// the middle of a job, are replaced; the affected job is retried once and comes out the same
/// as before the loss, and the resets are counted. The engine has its own device: destroying
/// the shared one would take every other test down.
#[test]
fn a_lost_device_is_replaced_and_the_affected_job_retried() {
    use penumbra::gpu::{AdapterChoice, GpuContext};
    let gpu = Arc::new(GpuContext::new(AdapterChoice::Auto).expect("a Vulkan adapter"));
    let engine = Engine::new(gpu, Limits::default(), PathPolicy::Deny);
    let job = penumbra::job::Job::from_json(small_job("png").to_string().as_bytes()).unwrap();
    let before = engine.render(&job, &()).expect("renders on the first device");

    engine.gpu().simulate_loss();
    let after_loss = engine.render(&job, &()).expect("renders on a new device after a loss between jobs");
    assert_eq!(engine.device_resets(), 1);
    assert!(!engine.gpu().is_lost());
    assert_eq!(after_loss.bytes, before.bytes, "the new device renders the same image");

    // Lose the device while the job runs: the first progress report of a reference render
    // comes after its first batch of samples was submitted.
    let mut reference = job.clone();
    reference.method.name = "reference".into();
    reference.method.params.insert("samples".into(), json!(8));
    let clean = engine.render(&reference, &()).expect("a reference render");
    let lost_once = std::sync::atomic::AtomicBool::new(false);
    let current = engine.gpu();
    let retried = engine
        .render(&reference, &|_, _| {
            if !lost_once.swap(true, std::sync::atomic::Ordering::SeqCst) {
                current.simulate_loss();
            }
        })
        .expect("the job is retried once on a new device");
    assert_eq!(engine.device_resets(), 2);
    assert_eq!(retried.bytes, clean.bytes, "the retried job renders what an undisturbed one does");
    assert_eq!(engine.stats().device_resets, 2);
}

/// A GPU error on the readback path (a buffer map that fails) fails that one job with a
/// generic 500 and nothing else: no panic, the next job on the same device renders, and the
/// daemon answers health checks throughout. The server has its own device, since the fault is
/// injected into it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_readback_fails_one_job_and_the_daemon_serves_on() {
    use penumbra::gpu::{AdapterChoice, GpuContext};
    let gpu = Arc::new(GpuContext::new(AdapterChoice::Auto).expect("a Vulkan adapter"));
    let engine = Arc::new(Engine::new(gpu, Limits::default(), PathPolicy::Deny));
    let state = Arc::new(AppState::new(engine.clone(), 8));
    state.set_ready();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    tokio::spawn(async move { axum::serve(listener, app(state)).await.unwrap() });
    let client = reqwest::Client::new();
    let render = || client.post(format!("{base}/v1/render")).json(&small_job("png")).send();

    engine.gpu().fail_next_readback();
    let failed = render().await.unwrap();
    assert_eq!(failed.status(), StatusCode::INTERNAL_SERVER_ERROR);
    let body: Value = failed.json().await.unwrap();
    assert_eq!(body["error"]["code"], "internal");
    assert!(!body["error"]["message"].as_str().unwrap().contains("map"), "5xx bodies stay generic: {body}");
    assert_eq!(client.get(format!("{base}/healthz")).send().await.unwrap().status(), StatusCode::OK);
    let next = render().await.unwrap();
    assert_eq!(next.status(), StatusCode::OK, "the next job renders on the same device");
    assert!(next.bytes().await.unwrap().starts_with(b"\x89PNG"));
    assert_eq!(engine.device_resets(), 0, "a failed map is not a lost device");
}

/// An observer that cancels the render once it has heard `after` progress reports.
struct CancelAfter {
    after: usize,
    heard: std::sync::atomic::AtomicUsize,
}

impl penumbra::supervise::Supervisor for CancelAfter {
    fn progress(&self, _done: u64, _total: u64) {
        self.heard.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    }
    fn cancelled(&self) -> bool {
        self.heard.load(std::sync::atomic::Ordering::SeqCst) >= self.after
    }
}

#[test]
fn a_cancelled_render_stops_at_its_next_batch_and_the_engine_renders_on() {
    use penumbra::gpu::{AdapterChoice, GpuContext};
    let gpu = Arc::new(GpuContext::new(AdapterChoice::Auto).expect("a Vulkan adapter"));
    let engine = Engine::new(gpu, Limits::default(), PathPolicy::Deny);
    let mut reference = penumbra::job::Job::from_json(small_job("png").to_string().as_bytes()).unwrap();
    reference.method.name = "reference".into();
    reference.method.params.extend([("samples".into(), json!(256)), ("resolution".into(), json!(128))]);
    let observer = CancelAfter { after: 1, heard: Default::default() };
    let Err(error) = engine.render(&reference, &observer) else { panic!("the render is cancelled") };
    assert_eq!(error.code, penumbra::error::ErrorCode::Cancelled);
    // 256 samples are 16 batches; a cancelled render stops after the first.
    assert_eq!(observer.heard.load(std::sync::atomic::Ordering::SeqCst), 1, "no batch runs after the cancel");

    // Cancelled before it reaches the device: nothing is rendered at all.
    let error = engine.render(&reference, &CancelAfter { after: 0, heard: Default::default() }).err().unwrap();
    assert_eq!(error.code, penumbra::error::ErrorCode::Cancelled);
    let job = penumbra::job::Job::from_json(small_job("png").to_string().as_bytes()).unwrap();
    assert_eq!(engine.render(&job, &()).expect("the engine renders on").bytes, engine.render(&job, &()).unwrap().bytes);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_client_that_disconnects_mid_render_cancels_its_job_and_others_are_served() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    // A reference render long enough to be caught running: 4096 samples, 256 batches.
    let mut long = small_job("png");
    long["method"] = json!({"name": "reference", "samples": 4096, "resolution": 256});
    let leaving = tokio::spawn(client.post(format!("{base}/v1/render")).json(&long).send());
    wait_for_stats(&client, &base, |s| s["jobs_in_flight"] == 1).await;
    leaving.abort(); // The client goes away: its connection closes mid-render.
    let _ = leaving.await;
    // Counted only once the render returned `cancelled`, i.e. stopped before its last batch.
    wait_for_metrics(&client, &base, |text| cancelled_jobs(text) == 1).await;
    let served = client.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.unwrap();
    assert_eq!(served.status(), StatusCode::OK, "the next client is served");
}

/// Finished jobs expire: after the configured time their record, events and image answer 404.
#[tokio::test(flavor = "multi_thread")]
async fn finished_jobs_expire_after_their_time() {
    let ttl = std::time::Duration::from_millis(400);
    let (base, _dir, _, _) = start_configured(DEFAULT_CACHE_BYTES, |state| state.with_results_ttl(ttl)).await;
    let client = reqwest::Client::new();
    let accepted: Value = client.post(format!("{base}/v1/jobs")).json(&small_job("png")).send().await.unwrap().json().await.unwrap();
    let record = format!("{base}{}", accepted["record"].as_str().unwrap());
    // The event stream ends when the job does.
    client.get(format!("{record}/events")).send().await.unwrap().text().await.unwrap();
    let finished: Value = client.get(&record).send().await.unwrap().json().await.unwrap();
    assert_eq!(finished["status"], "succeeded");
    assert_eq!(client.get(format!("{record}/image")).send().await.unwrap().status(), StatusCode::OK);
    tokio::time::sleep(ttl * 2).await;
    for path in ["", "/image", "/events", "/thumbnail"] {
        assert_eq!(client.get(format!("{record}{path}")).send().await.unwrap().status(), StatusCode::NOT_FOUND, "{path}");
    }
}

/// The dashboard in a real browser (Debian's `chromium`, headless): it loads its script and
/// Chart.js from the daemon, polls `/v1/stats`, draws a phase bar for every recent successful
/// job and a thumbnail for each, and a screenshot is kept in `target/test-artifacts/`.
#[tokio::test(flavor = "multi_thread")]
async fn the_dashboard_draws_live_data_in_headless_chromium() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    for (scene, method) in [("torus", "hard"), ("crowd", "pcss"), ("columns", "jfa-e"), ("torus", "chun-oh")] {
        let job = json!({"scene": {"builtin": scene}, "method": {"name": method}, "output": {"width": 192, "height": 128}});
        assert_eq!(client.post(format!("{base}/v1/render")).json(&job).send().await.unwrap().status(), StatusCode::OK);
    }
    let failing = json!({"scene": {"id": sha256_hex(b"never uploaded")}, "method": {"name": "hard"}});
    assert_eq!(client.post(format!("{base}/v1/render")).json(&failing).send().await.unwrap().status(), StatusCode::NOT_FOUND);
    let stats: Value = client.get(format!("{base}/v1/stats")).send().await.unwrap().json().await.unwrap();
    let recent = stats["jobs"]["recent"].as_array().unwrap();
    let succeeded: Vec<&Value> = recent.iter().filter(|j| j["outcome"] == "ok").collect();
    assert_eq!(succeeded.len(), 4, "{stats}");
    assert_eq!(recent.iter().filter(|j| j["outcome"] == "not_uploaded").count(), 1);
    assert!(stats["jobs"]["by_method"]["jfa-e"]["p50_ms"].as_f64().unwrap() > 0.0);
    assert!(succeeded[0]["phases"].as_array().unwrap().iter().any(|p| p[0] == "shadow_map"));
    // Without a shared store the service is this daemon: one replica, which answered.
    assert_eq!(stats["cluster"]["scope"], "replica");
    let replicas = stats["cluster"]["replicas"].as_array().unwrap();
    assert_eq!(replicas.len(), 1, "{stats}");
    assert_eq!((replicas[0]["jobs_succeeded"].as_u64(), replicas[0]["jobs_failed"].as_u64()), (Some(4), Some(1)));
    assert_eq!(replicas[0]["replica"], stats["replica"]);
    assert!(recent.iter().all(|j| j["replica"] == stats["replica"]));
    let thumbnail = client.get(format!("{base}/v1/jobs/{}/thumbnail", succeeded[0]["id"].as_str().unwrap())).send().await.unwrap();
    let thumbnail = image::load_from_memory(&thumbnail.bytes().await.unwrap()).expect("a PNG thumbnail");
    assert_eq!(thumbnail.width().max(thumbnail.height()), 160);

    let artifacts = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-artifacts");
    std::fs::create_dir_all(&artifacts).unwrap();
    let screenshot = artifacts.join("dashboard.png");
    std::fs::remove_file(&screenshot).ok();
    let url = format!("{base}/");
    let (dom, shot) = tokio::task::spawn_blocking(move || {
        (common::chromium(&["--dump-dom"], &url), common::chromium(&[&format!("--screenshot={}", screenshot.display())], &url))
    })
    .await
    .unwrap();
    let body = common::body_tag(&dom);
    let attribute = |name: &str| common::attribute(&body, name);
    assert!(attribute("data-polls").parse::<u32>().unwrap_or(0) >= 1, "the page polled /v1/stats: {body}");
    assert_eq!(attribute("data-phase-bars"), "4", "one stacked bar per successful job: {body}");
    assert!(attribute("data-phases").contains("shadow_map"), "{body}");
    assert_eq!(dom.matches("/thumbnail\"").count(), 4, "a thumbnail per successful job");
    assert!(dom.contains("class=\"status ok\""), "the page reports the daemon live");
    assert!(dom.contains("id=\"store\">memory<"), "the job-store tile says the router has no durable store");
    assert_eq!(attribute("data-replicas"), "1", "{body}");
    assert_eq!(attribute("data-jobs-succeeded"), "4", "{body}");
    assert!(dom.contains("answered by "), "the header names the replica");
    // The screenshot shows drawn charts: the accent colour of the bars and lines is there.
    let shot = image::open(&shot).expect("chromium wrote a PNG screenshot").to_rgb8();
    let accent = shot.pixels().filter(|p| p.0[0].abs_diff(0xf0) < 12 && p.0[1].abs_diff(0xb4) < 12 && p.0[2].abs_diff(0x29) < 12).count();
    assert!(accent > 500, "charts drawn in the screenshot ({accent} accent pixels)");
}

/// `penumbra bench-daemon` in miniature: its report is complete, no job failed, and the
/// memory measurement really went through evictions. (The figures themselves are for the
/// closing notes, never asserted.)
#[test]
fn the_daemon_benchmark_runs_and_reports() {
    let out = tempdir::Dir::new();
    let options = penumbra::daemon_bench::BenchOptions {
        out: out.path().to_path_buf(),
        repeat: 2,
        clients: vec![1, 3],
        jobs: 3,
        cache_mib: 2,
        scene_side: 24,
        concurrency: vec![1, 2],
    };
    let report = penumbra::daemon_bench::run(common::engine().gpu(), &options).expect("the benchmark runs");
    assert!(report.overhead.library_median_ms > 0.0 && report.overhead.http_median_ms > 0.0);
    assert_eq!(report.throughput.len(), 2);
    assert!(report.throughput.iter().all(|t| t.other_statuses.is_empty() && t.jobs_per_second > 0.0), "{:?}", report.throughput);
    assert!(report.memory.scenes >= 10 && report.memory.evictions > 0, "{:?}", report.memory);
    assert_eq!(report.by_concurrency.iter().map(|(slots, _)| *slots).collect::<Vec<_>>(), [1, 2]);
    assert!(report.by_concurrency.iter().all(|(_, t)| t.other_statuses.is_empty()), "{:?}", report.by_concurrency);
    let written: Value = serde_json::from_slice(&std::fs::read(out.path().join("daemon.json")).unwrap()).unwrap();
    assert_eq!(written["throughput"][1]["clients"], 3);
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// The embedded job store across a crash: a daemon killed with SIGKILL while one
/// submitted job renders and others wait, restarted on the same data directory, finishes
/// every job it had accepted, and still serves the result it had finished before the kill.
#[tokio::test(flavor = "multi_thread")]
async fn accepted_jobs_survive_sigkill_and_sigterm_and_finish_after_a_restart() {
    let data = tempdir::Dir::new();
    let address = free_address();
    let base = format!("http://{address}");
    let start = || {
        common::daemon::serve_command(&address).arg("--no-warm-up").arg("--data-dir").arg(data.path()).spawn().expect("the daemon starts")
    };
    let client = reqwest::Client::new();
    let ready = || wait_ready(&base);
    let status = |id: String| {
        let request = client.get(format!("{base}/v1/jobs/{id}"));
        async move { request.send().await.unwrap().json::<Value>().await.unwrap()["status"].as_str().unwrap_or("").to_owned() }
    };
    let submit = |job: Value| {
        let request = client.post(format!("{base}/v1/jobs")).json(&job);
        async move {
            let response = request.send().await.unwrap();
            assert_eq!(response.status(), StatusCode::ACCEPTED);
            response.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned()
        }
    };

    let mut daemon = start();
    ready().await;
    let finished = submit(small_job("png")).await;
    while status(finished.clone()).await != "succeeded" {
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let before: Vec<u8> = client.get(format!("{base}/v1/jobs/{finished}/image")).send().await.unwrap().bytes().await.unwrap().to_vec();
    let slow = json!({"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 256, "resolution": 256},
                      "output": {"width": 96, "height": 64}});
    let mut accepted = Vec::new();
    for _ in 0..4 {
        accepted.push(submit(slow.clone()).await);
    }
    // Kill while the first renders and the rest wait.
    for _ in 0..600 {
        if status(accepted[0].clone()).await == "running" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    let waiting = status(accepted[3].clone()).await;
    daemon.kill().unwrap();
    daemon.wait().unwrap();
    assert_eq!(waiting, "queued", "the last job had not started when the daemon was killed");
    assert!(client.get(format!("{base}/healthz")).send().await.is_err(), "the daemon is gone");

    let mut daemon = start();
    ready().await;
    for id in &accepted {
        let mut last = String::new();
        for _ in 0..1200 {
            last = status(id.clone()).await;
            if last == "succeeded" || last == "failed" {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
        assert_eq!(last, "succeeded", "job {id} after the restart");
        let image = client.get(format!("{base}/v1/jobs/{id}/image")).send().await.unwrap();
        assert_eq!(image.headers()[reqwest::header::CONTENT_TYPE], "image/png");
    }
    let after = client.get(format!("{base}/v1/jobs/{finished}/image")).send().await.unwrap();
    assert_eq!(after.status(), StatusCode::OK, "a result finished before the kill is served after it");
    assert_eq!(after.bytes().await.unwrap().to_vec(), before);

    // SIGTERM: the running job finishes, the waiting ones stay queued in the store, the process
    // exits 0; the next start renders them.
    let mut accepted = Vec::new();
    for _ in 0..3 {
        accepted.push(submit(slow.clone()).await);
    }
    for _ in 0..600 {
        if status(accepted[0].clone()).await == "running" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    let terminated = std::process::Command::new("kill").args(["-TERM", &daemon.id().to_string()]).status().unwrap();
    assert!(terminated.success());
    let exit = daemon.wait().unwrap();
    assert!(exit.success(), "a SIGTERM exits 0: {exit:?}");
    let stored = penumbra::store::EmbeddedStore::open(data.path()).unwrap();
    use penumbra::store::JobStore as _;
    assert_eq!(stored.get(&accepted[0]).unwrap().unwrap().status.as_str(), "succeeded", "the running job finished");
    assert_eq!(stored.get(&accepted[2]).unwrap().unwrap().status.as_str(), "queued", "a waiting job stayed queued");
    drop(stored);
    let mut daemon = start();
    ready().await;
    for id in &accepted {
        client.get(format!("{base}/v1/jobs/{id}/events")).send().await.unwrap().text().await.unwrap();
        assert_eq!(status(id.clone()).await, "succeeded", "job {id} after the graceful restart");
    }
    daemon.kill().unwrap();
    daemon.wait().unwrap();
}

/// A stored job that daemons kept dying on is failed with a reason at the next start instead
/// of being tried for ever; a job merely queued at the stop is rendered.
#[tokio::test(flavor = "multi_thread")]
async fn a_job_that_keeps_killing_its_daemon_is_failed_with_a_reason() {
    use penumbra::store::{EmbeddedStore, JobStore};
    let data = tempdir::Dir::new();
    let store = Arc::new(EmbeddedStore::open(data.path()).unwrap());
    store.accept("poison", &small_job("png")).unwrap();
    for _ in 0..penumbra::store::MAX_ATTEMPTS {
        store.start("poison").unwrap();
    }
    store.accept("plain", &small_job("png")).unwrap();
    let shared: Arc<dyn JobStore> = store.clone();
    let (base, _dir, _, state) =
        start_configured(DEFAULT_CACHE_BYTES, |s| s.with_store(penumbra::store::Store::new(shared, "embedded", 0))).await;
    assert_eq!(state.resume_unfinished().await.unwrap(), 1);
    let client = reqwest::Client::new();
    let poison: Value = client.get(format!("{base}/v1/jobs/poison")).send().await.unwrap().json().await.unwrap();
    assert_eq!(poison["status"], "failed");
    assert!(poison["error"]["message"].as_str().unwrap().contains("started 3 times"), "{poison}");
    client.get(format!("{base}/v1/jobs/plain/events")).send().await.unwrap().text().await.unwrap();
    assert_eq!(store.get("plain").unwrap().unwrap().status.as_str(), "succeeded");
}

/// `penumbra submit` against a live server: it uploads the job's local scene and light image
/// once (a second submit uploads nothing), follows the progress to the end and writes the image.
#[tokio::test(flavor = "multi_thread")]
async fn submit_uploads_only_what_the_server_lacks_and_follows_progress() {
    let (base, _dir) = start().await;
    let work = tempdir::Dir::new();
    std::fs::write(work.path().join("scene.glb"), common::as_glb()).unwrap();
    let mut png = std::io::Cursor::new(Vec::new());
    image::RgbaImage::from_fn(4, 2, |x, _| image::Rgba([255, (x * 60) as u8, 40, 255]))
        .write_to(&mut png, image::ImageFormat::Png)
        .unwrap();
    std::fs::write(work.path().join("light.png"), png.into_inner()).unwrap();
    let job = json!({"scene": {"path": "scene.glb"}, "light": {"image": {"path": "light.png"}},
                     "method": {"name": "reference", "samples": 16, "resolution": 256}, "output": {"width": 64, "height": 48}});
    std::fs::write(work.path().join("job.json"), job.to_string()).unwrap();
    let submit = |output: &str| {
        let (job_file, output_file) = (work.path().join("job.json").display().to_string(), work.path().join(output).display().to_string());
        let args = ["submit", &job_file, "--server", &base, "--quiet", "-o", &output_file].map(str::to_owned).to_vec();
        async move {
            let output = tools::cli(args, vec![]).await;
            assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
            serde_json::from_slice::<Value>(&output.stdout).expect("a JSON report on stdout")
        }
    };
    let first = submit("first.png").await;
    assert_eq!(first["uploaded"].as_array().unwrap().len(), 2, "{first}");
    assert!(first["done"].as_u64().unwrap() >= 16 && first["done"] == first["total"], "progress reached 100 %: {first}");
    let second = submit("second.png").await;
    assert_eq!(second["uploaded"], json!([]), "nothing uploaded the second time: {second}");
    assert_eq!(second["reused"], first["uploaded"]);
    let (a, b) = (std::fs::read(work.path().join("first.png")).unwrap(), std::fs::read(work.path().join("second.png")).unwrap());
    assert_eq!(image::load_from_memory(&a).unwrap().width(), 64);
    assert_eq!(a, b, "the same job renders the same image");
    // A job the server refuses: the CLI fails with the server's error, not a hang.
    std::fs::write(work.path().join("bad.json"), json!({"scene": {"builtin": "nope"}}).to_string()).unwrap();
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_penumbra"))
        .args(["submit", &work.path().join("bad.json").display().to_string(), "--server", &base, "--quiet", "-o"])
        .arg(work.path().join("bad.png"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("unknown_builtin"), "{}", String::from_utf8_lossy(&output.stderr));
}

/// Access control: with tokens configured, `/v1` and `/metrics` need one of them
/// (401 `unauthorized` with `WWW-Authenticate` otherwise), `/healthz`, `/readyz` and the
/// dashboard's files stay open, the dashboard works with a token given in its URL fragment,
/// CORS answers only configured origins, and `/v1/limits` lists the limits.
#[tokio::test(flavor = "multi_thread")]
async fn bearer_tokens_guard_the_api_and_cors_is_closed_unless_configured() {
    let tokens = ["first-token-0123456789abcdef", "second-token-0123456789abcdef"];
    let origins = vec!["https://tools.example".to_owned()];
    let (base, _dir, _, _) = start_configured(DEFAULT_CACHE_BYTES, |state| {
        state.with_auth(penumbra::server::auth::Auth::new(&tokens, false)).with_cors_origins(&origins).unwrap()
    })
    .await;
    let client = reqwest::Client::new();
    let get = |path: &str, token: Option<&str>| {
        let mut request = client.get(format!("{base}{path}"));
        if let Some(token) = token {
            request = request.bearer_auth(token);
        }
        request.send()
    };
    for path in ["/v1/methods", "/v1/stats", "/v1/limits", "/metrics"] {
        let refused = get(path, None).await.unwrap();
        assert_eq!(refused.status(), StatusCode::UNAUTHORIZED, "{path}");
        assert!(refused.headers()[reqwest::header::WWW_AUTHENTICATE].to_str().unwrap().starts_with("Bearer"));
        assert_eq!(refused.json::<Value>().await.unwrap()["error"]["code"], "unauthorized");
        assert_eq!(get(path, Some("not-a-token-0123456789")).await.unwrap().status(), StatusCode::UNAUTHORIZED, "{path}");
        for token in tokens {
            assert_eq!(get(path, Some(token)).await.unwrap().status(), StatusCode::OK, "{path}");
        }
    }
    for path in ["/healthz", "/readyz", "/", "/dashboard/app.js"] {
        assert_eq!(get(path, None).await.unwrap().status(), StatusCode::OK, "{path} stays open");
    }
    let render = client.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.unwrap();
    assert_eq!(render.status(), StatusCode::UNAUTHORIZED, "no render without a token");
    let limits: Value = get("/v1/limits", Some(tokens[0])).await.unwrap().json().await.unwrap();
    assert_eq!(limits["max_body_bytes"], 64 * 1024);
    assert!(limits["method_params"]["reference"].is_array() && limits["max_json_depth"].as_u64() > Some(4), "{limits}");

    // CORS: a preflight from the configured origin is answered; another origin gets nothing.
    let preflight = |origin: &str| {
        client
            .request(reqwest::Method::OPTIONS, format!("{base}/v1/render"))
            .header("origin", origin)
            .header("access-control-request-method", "POST")
            .header("access-control-request-headers", "authorization, content-type")
            .send()
    };
    let allowed = preflight("https://tools.example").await.unwrap();
    assert_eq!(allowed.headers()["access-control-allow-origin"], "https://tools.example");
    let other = preflight("https://evil.example").await.unwrap();
    assert!(other.headers().get("access-control-allow-origin").is_none());

    // The dashboard with its token in the URL fragment polls and draws.
    let render = client.post(format!("{base}/v1/render")).bearer_auth(tokens[1]).json(&small_job("png")).send().await.unwrap();
    assert_eq!(render.status(), StatusCode::OK);
    let url = format!("{base}/#token={}", tokens[1]);
    let dom = tokio::task::spawn_blocking(move || common::chromium(&["--dump-dom"], &url)).await.unwrap();
    assert!(dom.contains("class=\"status ok\""), "the dashboard got its stats with the token");
    assert!(!dom.contains("token-form"), "no token was asked for");
}

/// The daemon never writes a token to its logs, even at debug level.
#[test]
fn tokens_never_reach_the_logs() {
    let dir = tempdir::Dir::new();
    let token = "log-probe-token-5f1e0c9a7b";
    std::fs::write(dir.path().join("tokens"), format!("# the probe\n{token}\n")).unwrap();
    let address = free_address();
    let mut daemon = common::daemon::serve_command(&address)
        .args(["--no-warm-up", "--job-store", "memory", "--auth-token-file"])
        .arg(dir.path().join("tokens"))
        .env("PENUMBRA_LOG", "debug")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let client = reqwest::Client::new();
        let base = format!("http://{address}");
        wait_ready(&base).await;
        let ok = client.post(format!("{base}/v1/render")).bearer_auth(token).json(&small_job("png")).send().await.unwrap();
        assert_eq!(ok.status(), StatusCode::OK);
        let refused = client.get(format!("{base}/v1/stats")).bearer_auth(format!("{token}-wrong")).send().await.unwrap();
        assert_eq!(refused.status(), StatusCode::UNAUTHORIZED);
    });
    daemon.kill().unwrap();
    let output = daemon.wait_with_output().unwrap();
    let logs = String::from_utf8_lossy(&output.stderr);
    assert!(logs.contains("bearer tokens required"), "the daemon logged at all: {logs}");
    assert!(!logs.contains(token), "a token reached the logs");
}

/// Every limit is a flag of the real binary, listed by `/v1/limits` (method ranges included)
/// and enforced with a 4xx naming the field; method parameters are checked at submission, so
/// an async job that could only fail later is refused before its 202.
#[tokio::test(flavor = "multi_thread")]
async fn limits_are_flags_listed_and_enforced_with_the_field_named() {
    let flags = [
        ["--max-samples", "64"],
        ["--max-rounds", "4"],
        ["--max-json-depth", "6"],
        ["--max-vertices", "100"],
        ["--max-output-dim", "512"],
        ["--max-texture-bytes", "40000"],
        ["--max-cpu-working-bytes", "2097152"],
    ]
    .concat();
    let (_daemon, base) = serve(&[&["--job-store", "memory"], &flags[..]].concat(), &[("PENUMBRA_MAX_TRIANGLES", "5000")]).await;
    let client = reqwest::Client::new();
    let limits: Value = client.get(format!("{base}/v1/limits")).send().await.unwrap().json().await.unwrap();
    let listed = [("max_samples", 64), ("max_rounds", 4), ("max_json_depth", 6), ("max_vertices", 100), ("max_triangles", 5000)];
    for (name, value) in listed.into_iter().chain([("max_texture_bytes", 40000), ("max_cpu_working_bytes", 2097152)]) {
        assert_eq!(limits[name], value, "{name} in {limits}");
    }
    let max_of = |method: &str, param: &str| {
        limits["method_params"][method].as_array().unwrap().iter().find(|p| p["name"] == param).unwrap()["max"].clone()
    };
    assert_eq!((max_of("reference", "samples"), max_of("jfa-e", "rounds")), (json!(64), json!(4)), "ranges end at the caps");

    let refused = |job: Value, path: &'static str| {
        let request = client.post(format!("{base}{path}")).json(&job);
        async move {
            let (status, error) = refusal(request.send().await.unwrap()).await;
            (status.as_u16(), error["code"].as_str().unwrap_or("").to_owned(), error["field"].as_str().unwrap_or("").to_owned())
        }
    };
    let with_method = |method: Value| {
        let mut job = small_job("png");
        job["method"] = method;
        job
    };
    let limit = |field: &str| (422, "limit_exceeded".to_owned(), field.to_owned());
    for path in ["/v1/render", "/v1/jobs"] {
        assert_eq!(refused(with_method(json!({"name": "reference", "samples": 65})), path).await, limit("method.samples"));
        // The default of 256 samples is over this server's cap: the job must say how many.
        assert_eq!(refused(with_method(json!({"name": "reference"})), path).await, limit("method.samples"));
        assert_eq!(refused(with_method(json!({"name": "jfa-e", "rounds": 5})), path).await, limit("method.rounds"));
        let bad_param = (422, "invalid_field".to_owned(), "method.rounds".to_owned());
        assert_eq!(refused(with_method(json!({"name": "jfa-e", "rounds": "six"})), path).await, bad_param);
        let unknown = (422, "unknown_field".to_owned(), "method.radius".to_owned());
        assert_eq!(refused(with_method(json!({"name": "pcss", "radius": 1})), path).await, unknown);
        let mut wide = small_job("png");
        wide["output"]["width"] = json!(513);
        assert_eq!(refused(wide, path).await, limit("output.width"));
        let mut terrain = small_job("png");
        terrain["scene"] = json!({"builtin": "terrain", "triangles": 5001});
        assert_eq!(refused(terrain, path).await.0, 422);
    }
    let deep = format!(r#"{{"scene": {{"builtin": "torus"}}, "extra": {}{}}}"#, "[".repeat(6), "]".repeat(6));
    let response = client.post(format!("{base}/v1/render")).header("content-type", "application/json").body(deep).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::BAD_REQUEST);
    assert!(response.text().await.unwrap().contains("max_json_depth"));
    // A scene over the vertex cap is refused from its declared counts, naming the field.
    let glb = penumbra::scene::gltf::height_field_glb(11, 1); // 121 vertices.
    let upload = client.post(format!("{base}/v1/scenes")).header("content-type", "model/gltf-binary").body(glb).send().await.unwrap();
    let (status, error) = refusal(upload).await;
    assert_eq!((status, error["code"].as_str()), (StatusCode::UNPROCESSABLE_ENTITY, Some("limit_exceeded")), "{error}");
    assert!(error["message"].as_str().unwrap().contains("max_vertices"), "{error}");
    // Three 64×64 textures decode to 49,152 bytes, past the scene's texture budget (the
    // upload's body is the scene).
    let rgba = image::ColorType::Rgba8;
    let glb = penumbra::scene::gltf::textured_height_field_glb(&[rgba, rgba, rgba], 64);
    let upload = client.post(format!("{base}/v1/scenes")).header("content-type", "model/gltf-binary").body(glb).send().await.unwrap();
    let (status, error) = refusal(upload).await;
    assert_eq!(
        (status, error["code"].as_str(), error["field"].as_str()),
        (StatusCode::UNPROCESSABLE_ENTITY, Some("limit_exceeded"), Some("body")),
        "{error}"
    );
    assert!(error["message"].as_str().unwrap().contains("max_texture_bytes"), "{error}");
    // Within every limit, the same server renders.
    let ok = client.post(format!("{base}/v1/render")).json(&with_method(json!({"name": "reference", "samples": 16}))).send().await.unwrap();
    assert_eq!(ok.status(), StatusCode::OK);
}

/// The output's pixel cap is what the device binds (a frame's per-pixel buffers are one
/// storage binding each, 16 bytes a pixel): `/v1/limits` says the cap that holds, a frame of
/// exactly that many pixels renders, and one more row is refused up front naming `output` —
/// not a job that fails on the device (lavapipe binds 8,388,608 pixels, under the default 16 Mi).
#[tokio::test(flavor = "multi_thread")]
async fn the_output_cap_is_what_the_device_binds() {
    let (_daemon, base) = serve(&["--job-store", "memory"], &[]).await;
    let client = reqwest::Client::new();
    let limits: Value = client.get(format!("{base}/v1/limits")).send().await.unwrap().json().await.unwrap();
    let cap = limits["max_output_pixels"].as_u64().unwrap();
    assert!((4096 * 1024..=16 * 1024 * 1024).contains(&cap), "{limits}");
    let job = |height: u64| json!({"scene": {"builtin": "torus"}, "method": {"name": "hard"}, "output": {"width": 4096, "height": height}});
    let response = client.post(format!("{base}/v1/render")).json(&job(cap / 4096)).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::OK, "a frame of the cap's pixels renders");
    assert!(response.bytes().await.unwrap().starts_with(b"\x89PNG"));
    let response = client.post(format!("{base}/v1/render")).json(&job(cap / 4096 + 1)).send().await.unwrap();
    let (status, error) = refusal(response).await;
    assert_eq!(
        (status, error["code"].as_str(), error["field"].as_str()),
        (StatusCode::UNPROCESSABLE_ENTITY, Some("limit_exceeded"), Some("output")),
        "{error}"
    );
}

/// `penumbra serve ARGS` (no warm-up, a free loopback port, `warn` logs) with extra
/// environment variables, once ready: the daemon (killed when dropped) and its base URL.
async fn serve(args: &[&str], env: &[(&str, &str)]) -> (Daemon, String) {
    let address = free_address();
    let mut command = common::daemon::serve_command(&address);
    command.arg("--no-warm-up").args(args).envs(env.iter().copied());
    let daemon = tokio::task::spawn_blocking(move || Daemon::start(command, &address)).await.unwrap();
    let base = daemon.base.clone();
    (daemon, base)
}

/// A job whose scene fails on the GPU (here a texture wider than the device allows, under an
/// operator's texture limit set above the device's) fails alone, with the field named, while
/// the jobs queued around it succeed; the scene is not cached, and the daemon serves on.
#[tokio::test(flavor = "multi_thread")]
async fn a_scene_that_fails_on_the_gpu_mid_queue_fails_alone() {
    let (_daemon, base) = serve(&["--job-store", "memory", "--max-texture-dim", "100000"], &[]).await;
    let client = reqwest::Client::new();
    let device_max = 16384 * 4; // Wider than any device allows (lavapipe: 16384; NVIDIA: 32768).
    let (gltf, bin) = common::test_gltf_with_texture(device_max + 1, 1);
    let glb = penumbra::scene::gltf::glb(&gltf, &bin);
    let upload = client.post(format!("{base}/v1/scenes")).header("content-type", "model/gltf-binary").body(glb).send().await.unwrap();
    assert_eq!(upload.status(), StatusCode::CREATED, "the file itself is within the configured limits");
    let scene_id = upload.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();

    let mut first = small_job("png");
    first["method"] = json!({"name": "reference", "samples": 64});
    let mut bad = small_job("png");
    bad["scene"] = json!({"id": scene_id});
    let submit = |job: Value| {
        let request = client.post(format!("{base}/v1/jobs")).json(&job);
        async move {
            let response = request.send().await.unwrap();
            assert_eq!(response.status(), StatusCode::ACCEPTED);
            response.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned()
        }
    };
    // Queued behind a reference render: good, bad, good.
    let ids = [submit(first).await, submit(small_job("png")).await, submit(bad.clone()).await, submit(small_job("exr")).await];
    let mut outcomes = Vec::new();
    for id in &ids {
        let events = client.get(format!("{base}/v1/jobs/{id}/events")).send().await.unwrap().text().await.unwrap();
        assert!(events.contains("event: succeeded") || events.contains("event: failed"), "{events}");
        let record: Value = client.get(format!("{base}/v1/jobs/{id}")).send().await.unwrap().json().await.unwrap();
        outcomes.push(record);
    }
    let statuses: Vec<&str> = outcomes.iter().map(|r| r["status"].as_str().unwrap()).collect();
    assert_eq!(statuses, ["succeeded", "succeeded", "failed", "succeeded"], "{outcomes:?}");
    let error = &outcomes[2]["error"];
    assert_eq!(
        (error["code"].as_str(), error["field"].as_str(), error["status"].as_u64()),
        (Some("limit_exceeded"), Some("scene"), Some(422))
    );
    assert!(error["message"].as_str().unwrap().contains("does not fit on this GPU"), "{error}");

    // Not cached as if it had worked: it fails the same way again, synchronously too, and a
    // good job after it renders.
    let again = client.post(format!("{base}/v1/render")).json(&bad).send().await.unwrap();
    assert_eq!(again.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(again.json::<Value>().await.unwrap()["error"]["field"], "scene");
    let good = client.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.unwrap();
    assert_eq!(good.status(), StatusCode::OK);
}

/// `DELETE /v1/jobs/{id}` cancels a submitted job on the embedded store: a running one stops
/// mid-render, a waiting one leaves the queue, both end `cancelled` (record, events, store),
/// the job after them succeeds, a finished job answers 409 and an unknown one 404.
#[tokio::test(flavor = "multi_thread")]
async fn submitted_jobs_can_be_cancelled_waiting_or_running() {
    let data = tempdir::Dir::new();
    let (_daemon, base) = serve(&["--data-dir", data.path().to_str().unwrap()], &[]).await;
    let client = reqwest::Client::new();
    let submit = |job: Value| {
        let request = client.post(format!("{base}/v1/jobs")).json(&job);
        async move { request.send().await.unwrap().json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned() }
    };
    let record = |id: String| {
        let request = client.get(format!("{base}/v1/jobs/{id}"));
        async move { request.send().await.unwrap().json::<Value>().await.unwrap() }
    };
    let cancel = |id: String| client.delete(format!("{base}/v1/jobs/{id}")).send();
    let mut long = small_job("png");
    long["method"] = json!({"name": "reference", "samples": 4096, "resolution": 256});
    let running = submit(long.clone()).await;
    let waiting = submit(long).await;
    let after = submit(small_job("png")).await;
    for _ in 0..600 {
        if record(running.clone()).await["status"] == "running" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    assert_eq!(record(waiting.clone()).await["status"], "queued");
    let early = client.get(format!("{base}/v1/jobs/{waiting}/image")).send().await.unwrap();
    assert_eq!(early.status(), StatusCode::CONFLICT, "no image yet, but the job exists");
    // What can only fail later is refused now: a path on a server that reads none, an
    // upload it does not hold.
    for (scene, status, field) in [
        (json!({"path": "scene.glb"}), StatusCode::FORBIDDEN, "scene.path"),
        (json!({"id": "ab".repeat(32)}), StatusCode::NOT_FOUND, "scene.id"),
    ] {
        let mut job = small_job("png");
        job["scene"] = scene;
        let refused = client.post(format!("{base}/v1/jobs")).json(&job).send().await.unwrap();
        assert_eq!(refused.status(), status);
        assert_eq!(refused.json::<Value>().await.unwrap()["error"]["field"], field);
    }
    for id in [&waiting, &running] {
        let answer = cancel(id.clone()).await.unwrap();
        assert_eq!(answer.status(), StatusCode::ACCEPTED, "{id}");
    }
    for id in [&running, &waiting] {
        let events = client.get(format!("{base}/v1/jobs/{id}/events")).send().await.unwrap().text().await.unwrap();
        assert!(events.contains("event: cancelled"), "{events}");
        let stopped = record(id.clone()).await;
        assert_eq!((&stopped["status"], &stopped["error"]["code"]), (&json!("cancelled"), &json!("cancelled")), "{stopped}");
        let image = client.get(format!("{base}/v1/jobs/{id}/image")).send().await.unwrap();
        assert_eq!(image.status(), StatusCode::CONFLICT, "a cancelled job has no image");
    }
    let events = client.get(format!("{base}/v1/jobs/{after}/events")).send().await.unwrap().text().await.unwrap();
    assert!(events.contains("event: succeeded"), "the next job is served: {events}");
    let finished = cancel(after).await.unwrap();
    assert_eq!(finished.status(), StatusCode::CONFLICT);
    assert_eq!(finished.json::<Value>().await.unwrap()["error"]["code"], "conflict");
    assert_eq!(cancel("0".repeat(32)).await.unwrap().status(), StatusCode::NOT_FOUND);
    wait_for_metrics(&client, &base, |text| cancelled_jobs(text) == 2).await;
}

/// The glTF 2.0 samples Debian ships in `assimp-testmodels` — others' files, valid and
/// deliberately broken — judged by Khronos' gltf-validator (`tests/gltf/validate.js`) and
/// served from `--scene-dir`. Every file the validator passes that requires no extension and
/// holds triangles renders by path on a floor: the validator's triangles plus the floor's two,
/// its textures, a cast shadow in view; and through `penumbra submit` (a `.gltf` and its files
/// packed into one GLB) to the same pixels. Every other file is refused with a 4xx whose
/// message names the problem, or renders with `warnings` naming what was repaired or ignored.
/// The daemon serves a valid job after all of them. The thumbnails of what rendered are
/// tiled into `gltf-corpus.png` under the test's target folder (docs/jobs.md's contact sheet).
#[tokio::test(flavor = "multi_thread")]
async fn the_assimp_gltf2_corpus_renders_with_shadows_or_is_refused_by_name() {
    let corpus = std::env::var_os("PENUMBRA_GLTF_CORPUS").map_or_else(|| "/usr/share/assimp/models/glTF2".into(), std::path::PathBuf::from);
    assert!(corpus.is_dir(), "{} is missing: run deploy/install-test-deps.sh (assimp-testmodels)", corpus.display());
    let tools = std::env::var_os("PENUMBRA_TOOLS")
        .map_or_else(|| std::path::Path::new(&std::env::var("HOME").unwrap()).join(".cache/penumbra-tools"), std::path::PathBuf::from);
    let validator = tools.join("node/node_modules/gltf-validator");
    assert!(validator.is_dir(), "{} is missing: run deploy/install-test-deps.sh", validator.display());
    let mut files = Vec::new();
    let mut folders = vec![corpus.clone()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(folder).unwrap().map(Result::unwrap) {
            let path = entry.path();
            if path.is_dir() {
                folders.push(path);
            } else if path.extension().is_some_and(|e| e == "gltf" || e == "glb") {
                files.push(path);
            }
        }
    }
    files.sort();
    assert!(files.len() >= 40, "the corpus has {} files", files.len());
    let validated = std::process::Command::new("node")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/gltf/validate.js"))
        .args(&files)
        .env("GLTF_VALIDATOR", &validator)
        .output()
        .expect("node runs");
    assert!(validated.status.success(), "{}", String::from_utf8_lossy(&validated.stderr));
    let verdicts: Vec<Value> =
        validated.stdout.split(|&b| b == b'\n').filter(|l| !l.is_empty()).map(|l| serde_json::from_slice(l).unwrap()).collect();
    assert_eq!(verdicts.len(), files.len());

    let (_daemon, base) = serve(&["--scene-dir", corpus.to_str().unwrap()], &[]).await;
    let client = reqwest::Client::new();
    let work = tempdir::Dir::new();
    let (width, height) = (160u32, 120u32);
    let mut thumbnails = Vec::new();
    let (mut rendered, mut refused, mut repaired) = (0, 0, 0);
    for (file, verdict) in files.iter().zip(&verdicts) {
        let relative = file.strip_prefix(&corpus).unwrap().to_str().unwrap();
        let required: Vec<&str> = verdict["required"].as_array().unwrap().iter().map(|r| r.as_str().unwrap()).collect();
        let triangles = verdict["triangles"].as_u64().unwrap();
        let valid = verdict["errors"] == 0;
        let job = json!({"scene": {"path": relative, "floor": true}, "method": {"name": "pcss"},
                         "output": {"width": width, "height": height, "format": "exr"}});
        let response = client.post(format!("{base}/v1/render")).header("accept", "application/json").json(&job).send().await.unwrap();
        let status = response.status();
        let answer: Value = response.json().await.unwrap();
        if !status.is_success() {
            assert!(status.is_client_error(), "{relative}: {status} {answer}");
            let message = answer["error"]["message"].as_str().unwrap();
            assert_eq!(answer["error"]["field"], "scene", "{relative}: {answer}");
            assert!(
                !valid || !required.is_empty() || triangles == 0,
                "{relative}: the validator passes it, it has {triangles} triangles, yet {answer}"
            );
            for extension in &required {
                assert!(message.contains(extension), "{relative}: the refusal does not name {extension}: {message}");
            }
            if valid && required.is_empty() {
                assert!(message.contains("no triangles"), "{relative}: {message}");
            }
            refused += 1;
            continue;
        }
        let warnings = answer["warnings"].as_array().unwrap();
        if !valid {
            // Rendered despite the validator's errors: only with the repair said.
            assert!(!warnings.is_empty(), "{relative}: the validator finds {} and penumbra says nothing: {answer}", verdict["codes"]);
            repaired += 1;
        } else {
            assert!(required.is_empty(), "{relative} requires {required:?} and rendered");
            // The validator counts each mesh once; penumbra draws each node's instance of it.
            let drawn = answer["timings"]["scene_triangles"].as_u64().unwrap() - 2; // the floor
            if meshes_instanced_once(file) {
                assert_eq!(drawn, triangles, "{relative}: triangles");
            } else {
                assert!(drawn > triangles, "{relative}: {drawn} triangles drawn, {triangles} in its meshes");
            }
            assert_eq!(
                answer["timings"]["scene_textures"].as_u64().unwrap() > 0,
                verdict["textures"].as_bool().unwrap(),
                "{relative}: textures"
            );
        }
        let image = client.get(format!("{base}{}", answer["image"].as_str().unwrap())).send().await.unwrap().bytes().await.unwrap();
        let (_, _, channels) = common::decode_exr(&image);
        // A cast shadow in view: pixels the scene darkens by half or more (V is 1 where E0 = 0,
        // so faces turned from the light do not count).
        let shadowed = (0..(width * height) as usize)
            .filter(|&i| ["visibility.R", "visibility.G", "visibility.B"].iter().any(|c| channels[*c][i] < 0.5))
            .count();
        assert!(shadowed * 200 >= (width * height) as usize, "{relative}: {shadowed} shadowed pixels");
        thumbnails.push(image::RgbaImage::from_fn(width, height, |x, y| {
            let i = (y * width + x) as usize;
            let [r, g, b] = ["R", "G", "B"].map(|c| (channels[c][i].clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0) as u8);
            image::Rgba([r, g, b, 255])
        }));
        rendered += 1;

        if valid {
            // The same scene through the client, packed into one GLB and uploaded.
            let job =
                json!({"scene": {"path": file, "floor": true}, "method": {"name": "pcss"}, "output": {"width": width, "height": height}});
            let job_file = work.path().join("job.json");
            std::fs::write(&job_file, job.to_string()).unwrap();
            let out = work.path().join("submitted.exr");
            let args = [job_file.as_os_str(), "--server".as_ref(), base.as_ref(), "--quiet".as_ref(), "-o".as_ref(), out.as_os_str()];
            let args: Vec<std::ffi::OsString> = args.iter().map(|a| a.to_os_string()).collect();
            let output = tokio::task::spawn_blocking(move || {
                std::process::Command::new(env!("CARGO_BIN_EXE_penumbra")).arg("submit").args(args).output().unwrap()
            })
            .await
            .unwrap();
            assert!(output.status.success(), "{relative} through submit: {}", String::from_utf8_lossy(&output.stderr));
            let (_, _, submitted) = common::decode_exr(&std::fs::read(&out).unwrap());
            for channel in ["R", "G", "B", "visibility.R"] {
                let worst = channels[channel].iter().zip(&submitted[channel]).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(worst <= 1e-5, "{relative}: submitted and by-path renders differ by {worst} in {channel}");
            }
        }
    }
    eprintln!("glTF corpus: {rendered} rendered ({repaired} of them repaired, with warnings), {refused} refused");
    assert!(rendered >= 20 && refused >= 10 && repaired >= 3, "rendered {rendered}, refused {refused}, repaired {repaired}");
    // The daemon serves on after all of them.
    let response = client.post(format!("{base}/v1/render")).json(&small_job("png")).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::OK);

    let columns = 6;
    let rows = thumbnails.len().div_ceil(columns) as u32;
    let mut sheet = image::RgbaImage::from_pixel(columns as u32 * width, rows * height, image::Rgba([255, 255, 255, 255]));
    for (k, thumbnail) in thumbnails.iter().enumerate() {
        image::imageops::replace(&mut sheet, thumbnail, (k % columns) as i64 * width as i64, (k / columns) as i64 * height as i64);
    }
    sheet.save(std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("gltf-corpus.png")).unwrap();
}

/// Whether no mesh of a glTF or GLB file is named by two nodes.
fn meshes_instanced_once(file: &std::path::Path) -> bool {
    let bytes = std::fs::read(file).unwrap();
    let json = if bytes.starts_with(b"glTF") {
        let length = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        &bytes[20..20 + length]
    } else {
        &bytes[..]
    };
    let document: Value = serde_json::from_slice(json).unwrap();
    let meshes: Vec<u64> = document["nodes"].as_array().into_iter().flatten().filter_map(|n| n["mesh"].as_u64()).collect();
    meshes.iter().collect::<std::collections::HashSet<_>>().len() == meshes.len()
}

/// A `.gltf` read by path names its files by URI relative to it (percent-encoded), read from
/// beside it inside `--scene-dir` only: `..` out of the directory, absolute paths, `file:`,
/// network URIs and symlinks leading out are refused with a 403 naming the URI, and the same
/// document uploaded is refused as not self-contained (contract §3).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn relative_uris_are_read_inside_the_scene_directory_only() {
    let (base, dir) = start().await;
    let outside = tempdir::Dir::new();
    let (document, bin) = common::test_gltf();
    let model = dir.path().join("model");
    std::fs::create_dir_all(&model).unwrap();
    std::fs::write(model.join("mesh data.bin"), &bin).unwrap();
    let secret = outside.path().join("secret.bin");
    std::fs::write(&secret, &bin).unwrap();
    std::os::unix::fs::symlink(&secret, model.join("link.bin")).unwrap();
    let outside_name = outside.path().file_name().unwrap().to_str().unwrap().to_owned();
    let with_uri = |uri: &str| {
        let mut document = document.clone();
        document["buffers"][0]["uri"] = uri.into();
        serde_json::to_vec(&document).unwrap()
    };
    let client = reqwest::Client::new();
    let render = |name: String| {
        let client = client.clone();
        let job = json!({"scene": {"path": format!("model/{name}"), "floor": true}, "output": {"width": 64, "height": 48}});
        let url = format!("{base}/v1/render");
        async move { client.post(url).json(&job).send().await.unwrap() }
    };

    std::fs::write(model.join("ok.gltf"), with_uri("mesh%20data.bin")).unwrap();
    let response = render("ok.gltf".into()).await;
    assert_eq!(response.status(), StatusCode::OK);
    // Cached while its files stay as they are; a changed .bin is a new scene.
    let cached = || async {
        let job = json!({"scene": {"path": "model/ok.gltf", "floor": true}, "output": {"width": 64, "height": 48}});
        let response = client.post(format!("{base}/v1/render")).header("accept", "application/json").json(&job).send().await.unwrap();
        response.json::<Value>().await.unwrap()["timings"]["scene_cached"].as_bool().unwrap()
    };
    assert!(cached().await);
    std::fs::write(model.join("mesh data.bin"), [&bin[..], &[0u8; 4]].concat()).unwrap();
    assert!(!cached().await, "the .bin changed");
    assert!(cached().await);

    let escapes = [
        format!("../../{outside_name}/secret.bin"),
        format!("..%2F..%2F{outside_name}%2Fsecret.bin"),
        secret.display().to_string(),
        format!("file://{}", secret.display()),
        "http://127.0.0.1:9/secret.bin".to_owned(),
        "//127.0.0.1/secret.bin".to_owned(),
        "link.bin".to_owned(),
    ];
    for (k, uri) in escapes.iter().enumerate() {
        let name = format!("escape-{k}.gltf");
        std::fs::write(model.join(&name), with_uri(uri)).unwrap();
        let response = render(name).await;
        assert_eq!(response.status(), StatusCode::FORBIDDEN, "{uri}");
        let body: Value = response.json().await.unwrap();
        assert_eq!((body["error"]["code"].as_str(), body["error"]["field"].as_str()), (Some("path_not_allowed"), Some("scene")), "{uri}");
        assert!(body["error"]["message"].as_str().unwrap().contains(&format!("`{uri}`")), "{uri}: {body}");
    }

    let response = client.post(format!("{base}/v1/scenes")).body(with_uri("mesh%20data.bin")).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::UNPROCESSABLE_ENTITY);
    let body: Value = response.json().await.unwrap();
    assert!(body["error"]["message"].as_str().unwrap().contains("self-contained"), "{body}");
    // Packed into one GLB it uploads, and the receipt says what penumbra will ignore.
    let mut document: Value = serde_json::from_slice(&with_uri("mesh%20data.bin")).unwrap();
    document["extensionsUsed"] = json!(["KHR_texture_transform"]);
    let packed = penumbra::scene::gltf::pack(&serde_json::to_vec(&document).unwrap(), &model, &Limits::default(), "scene").unwrap();
    let response = client.post(format!("{base}/v1/scenes")).body(packed).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::CREATED);
    let receipt: Value = response.json().await.unwrap();
    assert!(receipt["warnings"][0].as_str().unwrap().contains("KHR_texture_transform"), "{receipt}");
}

/// Contract §3: a texture never stops a shadow, and the answer says how the scene was staged.
/// A file whose image lies outside `--scene-dir` renders, with a warning naming the image and
/// nothing read from outside; the JSON answer and the job record name the camera, light and
/// floor used and which of them were fitted; sent back as the job's own camera and light, they
/// render the same pixels, and nothing is fitted any more.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_texture_never_stops_a_shadow_and_the_staging_is_said() {
    let (base, dir) = start().await;
    let outside = tempdir::Dir::new();
    let (mut document, bin) = common::test_gltf();
    let model = dir.path().join("model");
    std::fs::create_dir_all(&model).unwrap();
    std::fs::write(model.join("mesh.bin"), &bin).unwrap();
    let png = image::RgbaImage::from_pixel(2, 2, image::Rgba([255, 0, 0, 255]));
    png.save(outside.path().join("secret.png")).unwrap();
    let escape = format!("../../{}/secret.png", outside.path().file_name().unwrap().to_str().unwrap());
    document["buffers"][0]["uri"] = "mesh.bin".into();
    document["images"] = json!([{"uri": escape}]);
    std::fs::write(model.join("textured.gltf"), serde_json::to_vec(&document).unwrap()).unwrap();

    let client = reqwest::Client::new();
    let render = |job: Value| {
        let (client, base) = (client.clone(), base.clone());
        async move {
            let response = client.post(format!("{base}/v1/render")).header("accept", "application/json").json(&job).send().await.unwrap();
            assert_eq!(response.status(), StatusCode::OK);
            let answer: Value = response.json().await.unwrap();
            let image = client.get(format!("{base}{}", answer["image"].as_str().unwrap())).send().await.unwrap().bytes().await.unwrap();
            (answer, image)
        }
    };
    let staged = json!({"scene": {"path": "model/textured.gltf", "floor": {"albedo": [0.5, 0.5, 0.5], "margin": 1.5}},
                        "method": {"name": "pcss"}, "output": {"width": 96, "height": 64, "format": "exr"}});
    let (answer, image) = render(staged.clone()).await;
    let warnings: Vec<&str> = answer["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap()).collect();
    assert!(warnings.iter().any(|w| w.contains(&format!("(`{escape}`)")) && w.contains("outside the directory")), "{warnings:?}");
    assert_eq!(answer["timings"]["scene_textures"], 0, "nothing read from outside --scene-dir");

    let staging = &answer["staging"];
    let fitted: Vec<&str> = staging["fitted"].as_array().unwrap().iter().map(|f| f.as_str().unwrap()).collect();
    assert!(fitted.contains(&"camera.eye") && fitted.contains(&"light.center") && fitted.contains(&"light.image"), "{staging}");
    assert_eq!(staging["floor"]["albedo"], json!([0.5, 0.5, 0.5]));
    assert_eq!(staging["floor"]["margin"], json!(1.5));
    assert!(staging["floor"]["height"].as_f64().unwrap() < 0.5, "under the model: {staging}");
    assert_eq!(staging["light"]["image"], json!({"builtin": "white"}));
    // The same in the record of a submitted job.
    let submitted = client.post(format!("{base}/v1/jobs")).json(&staged).send().await.unwrap();
    assert_eq!(submitted.status(), StatusCode::ACCEPTED);
    let id = submitted.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let record = loop {
        let record: Value = client.get(format!("{base}/v1/jobs/{id}")).send().await.unwrap().json().await.unwrap();
        if record["status"] != "queued" && record["status"] != "running" {
            break record;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    };
    assert_eq!(record["staging"], *staging, "{record}");

    // Given back as the job's own camera and light: the same image, nothing fitted.
    let mut explicit = staged.clone();
    let (camera, light) = (&staging["camera"], &staging["light"]);
    explicit["camera"] = json!({"eye": camera["eye"], "target": camera["target"], "up": camera["up"], "fov_y_deg": camera["fov_y_deg"],
                                "near": camera["near"], "far": camera["far"]});
    explicit["light"] = light.clone();
    let (again, again_image) = render(explicit).await;
    assert_eq!(again["staging"]["fitted"], json!([]), "{again}");
    assert_eq!(again["staging"]["camera"], staging["camera"]);
    assert_eq!(again["staging"]["light"], staging["light"]);
    let (_, _, first) = common::decode_exr(&image);
    let (_, _, second) = common::decode_exr(&again_image);
    assert_eq!(first["R"], second["R"], "the staging reproduces the image");
}

/// `job` rendered synchronously, answered as JSON.
async fn render_json(client: &reqwest::Client, base: &str, job: &Value) -> Value {
    client.post(format!("{base}/v1/render")).header("accept", "application/json").json(job).send().await.unwrap().json().await.unwrap()
}

/// `auto` (contract §5): the model in `/v1/methods`, estimates that render nothing, a budget
/// resolved to the method the estimate names — answered with the choice, its prediction and
/// the measured time, synchronously and submitted — and budgets nothing meets, or out of
/// range, refused with the field named.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn auto_chooses_by_the_model_and_estimates_render_nothing() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    let methods: Value = client.get(format!("{base}/v1/methods")).send().await.unwrap().json().await.unwrap();
    assert_eq!(methods["model"]["status"], "default", "{}", methods["model"]);
    let candidates = methods["model"]["candidates"].as_array().unwrap().len();
    assert!(candidates >= 12, "{}", methods["model"]);

    let estimate = |job: Value| {
        let client = client.clone();
        let base = base.clone();
        async move {
            let response = client.post(format!("{base}/v1/estimate")).json(&job).send().await.unwrap();
            let status = response.status();
            (status, response.json::<Value>().await.unwrap())
        }
    };
    let job = |method: Value| json!({"scene": {"builtin": "torus"}, "output": {"width": 96, "height": 64}, "method": method});
    let (status, plain) = estimate(job(json!({"name": "wedges"}))).await;
    assert_eq!(status, StatusCode::OK, "{plain}");
    assert_eq!(plain["predictions"].as_array().unwrap().len(), candidates);
    assert_eq!(plain["job"]["label"], "wedges", "{plain}");
    assert_eq!(plain["features"]["triangles_known"], true);
    assert_eq!(plain["features"]["pixels"], 96 * 64);
    // The torus fills its view: whole maps. A view of a few columns on a wide floor: cropped.
    assert_eq!(plain["features"]["map_share"], 1.0, "{plain}");
    assert_eq!(plain["features"]["pace"], 1.0, "nothing rendered yet: {plain}");
    let (_, columns) = estimate(json!({"scene": {"builtin": "columns"}, "method": {"name": "wedges"}})).await;
    let share = columns["features"]["map_share"].as_f64().unwrap();
    assert!(share > 0.0 && share <= 0.25, "{columns}");
    let wedges_ms = plain["job"]["predicted"]["ms"].as_f64().unwrap();
    assert!(wedges_ms > 0.0);
    // Nothing was rendered for it.
    let stats: Value = client.get(format!("{base}/v1/stats")).send().await.unwrap().json().await.unwrap();
    assert_eq!(stats["jobs"].as_array().map_or(0, Vec::len), 0, "{}", stats["jobs"]);

    // A time budget: the estimate's choice is what renders, and the answer says so.
    let budget = json!({"name": "auto", "max_ms": wedges_ms * 4.0});
    let (_, planned) = estimate(job(budget.clone())).await;
    let chosen = planned["auto"]["label"].as_str().expect("a choice").to_owned();
    let predicted_ms = planned["auto"]["predicted"]["ms"].as_f64().unwrap();
    assert!(predicted_ms * 1.25 <= wedges_ms * 4.0, "{planned}");
    let response = client.post(format!("{base}/v1/render")).json(&job(budget.clone())).send().await.unwrap();
    assert_eq!(response.status(), StatusCode::OK);
    assert_eq!(response.headers()["x-penumbra-auto-method"], chosen.as_str());
    let timing = response.headers()["server-timing"].to_str().unwrap();
    assert!(timing.contains(&format!("auto;desc=\"{chosen}\"")), "{timing}");
    let answer = render_json(&client, &base, &job(budget.clone())).await;
    assert_eq!(answer["auto"]["label"], chosen.as_str(), "{answer}");
    assert_eq!(answer["method"], answer["auto"]["method"]["name"]);
    assert_eq!(answer["auto"]["model"], "default");
    assert!(answer["auto"]["measured_ms"].as_f64().unwrap() > 0.0);

    // An error budget, compared: the measured error comes with it.
    let mut compared = job(json!({"name": "auto", "max_error": 0.05}));
    compared["compare"] = json!(true);
    let answer = render_json(&client, &base, &compared).await;
    assert!(answer["auto"]["predicted"]["error"].as_f64().unwrap() * 1.25 <= 0.05, "{answer}");
    assert!(answer["quality"]["visibility"]["penumbra"]["mae"].is_number(), "{answer}");

    // Submitted: the record names the choice.
    let accepted = client.post(format!("{base}/v1/jobs")).json(&job(budget)).send().await.unwrap();
    assert_eq!(accepted.status(), StatusCode::ACCEPTED);
    let links: Value = accepted.json().await.unwrap();
    client.get(format!("{base}{}", links["events"].as_str().unwrap())).send().await.unwrap().text().await.unwrap();
    let record: Value = client.get(format!("{base}{}", links["record"].as_str().unwrap())).send().await.unwrap().json().await.unwrap();
    assert_eq!(record["status"], "succeeded", "{record}");
    assert_eq!(record["auto"]["label"], chosen.as_str(), "{record}");

    // The four jobs rendered set the model's pace (their measured ÷ predicted times), and every
    // time predicted since follows it.
    let methods: Value = client.get(format!("{base}/v1/methods")).send().await.unwrap().json().await.unwrap();
    let pace = &methods["model"]["pace"];
    assert_eq!(pace["renders"], 4, "{pace}");
    let factor = pace["factor"].as_f64().unwrap();
    // Within the pace's bounds (contract §5: [0.25, 4]).
    assert!((0.25..=4.0).contains(&factor), "{pace}");
    let (_, paced) = estimate(job(json!({"name": "wedges"}))).await;
    assert_eq!(paced["features"]["pace"].as_f64(), Some(factor), "{paced}");
    let paced_ms = paced["job"]["predicted"]["ms"].as_f64().unwrap();
    assert!((paced_ms - wedges_ms * factor).abs() <= 1e-9 * paced_ms, "{paced_ms} against {wedges_ms} × {factor}");

    // Budgets nothing meets: 422 naming the field and the closest choice; estimates say why.
    let (status, unmet) = estimate(job(json!({"name": "auto", "max_ms": 0.001}))).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(unmet["unmet"]["field"], "method.max_ms", "{unmet}");
    for (method, field, code) in [
        (json!({"name": "auto", "max_ms": 0.001}), "method.max_ms", "budget_unmet"),
        (json!({"name": "auto", "max_error": 1e-7}), "method.max_error", "budget_unmet"),
        (json!({"name": "auto", "max_error": 1.5}), "method.max_error", "invalid_field"),
        (json!({"name": "auto", "max_ms": -1}), "method.max_ms", "invalid_field"),
        (json!({"name": "auto", "max_ms": 1e12}), "method.max_ms", "invalid_field"),
        (json!({"name": "auto"}), "method.max_ms", "invalid_field"),
        (json!({"name": "auto", "max_ms": 100, "samples": 4}), "method.samples", "unknown_field"),
    ] {
        for route in ["render", "jobs", "estimate"] {
            if code == "budget_unmet" && route == "estimate" {
                continue;
            }
            let (status, error) = refusal(client.post(format!("{base}/v1/{route}")).json(&job(method.clone())).send().await.unwrap()).await;
            assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{route} {method}");
            assert_eq!((error["code"].as_str(), error["field"].as_str()), (Some(code), Some(field)), "{route} {error}");
            if code == "budget_unmet" {
                assert!(error["message"].as_str().unwrap().contains("closest"), "{error}");
            }
        }
    }
}

/// A daemon that finds its device's model in the data directory uses it instead of measuring
/// again; one for another build is not read.
#[tokio::test(flavor = "multi_thread")]
async fn a_stored_model_for_this_adapter_and_build_is_read_at_start() {
    let data = tempdir::Dir::new();
    let (probe, base) = serve(&[], &[]).await;
    let ready: Value = reqwest::get(format!("{base}/readyz")).await.unwrap().json().await.unwrap();
    drop(probe);
    let build = format!("{}+{}", env!("CARGO_PKG_VERSION"), &sha256_hex(&std::fs::read(env!("CARGO_BIN_EXE_penumbra")).unwrap())[..12]);
    let key = penumbra::model::ModelKey {
        adapter: ready["adapter"]["name"].as_str().unwrap().to_owned(),
        driver: ready["adapter"]["driver"].as_str().unwrap().to_owned(),
        build,
    };
    let mut model = penumbra::model::Model::shipped();
    model.key = key.clone();
    model.source = "measured".into();
    model.measure_seconds = 4242.0;
    penumbra::model::save(data.path(), &model).unwrap();
    let stale = penumbra::model::Model { key: penumbra::model::ModelKey { build: "0.0.0+old".into(), ..key }, ..model };
    penumbra::model::save(data.path(), &stale).unwrap();
    let data_dir = data.path().to_str().unwrap();
    let (_daemon, base) = serve(&["--data-dir", data_dir, "--job-store", "memory"], &[("PENUMBRA_MODEL", "measure")]).await;
    let mut shown = Value::Null;
    for _ in 0..100 {
        shown = reqwest::get(format!("{base}/v1/methods")).await.unwrap().json::<Value>().await.unwrap()["model"].clone();
        if shown["status"] == "stored" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    assert_eq!(shown["status"], "stored", "{shown}");
    assert_eq!(shown["measure_seconds"], 4242.0);
}

/// A daemon measures its device's model in the background (here the quick suite) while it
/// answers `/readyz` 200 and `auto` jobs with the shipped model; once measured, `auto` says so,
/// and the next start reads the model from the data directory instead of measuring again.
#[tokio::test(flavor = "multi_thread")]
async fn the_model_is_measured_in_the_background_and_kept_for_the_next_start() {
    let data = tempdir::Dir::new();
    let data_dir = data.path().to_str().unwrap().to_owned();
    let flags = ["--data-dir", data_dir.as_str(), "--job-store", "memory"];
    let (daemon, base) = serve(&flags, &[("PENUMBRA_MODEL", "quick")]).await;
    let client = reqwest::Client::new();
    let model = |client: reqwest::Client, base: String| async move {
        client.get(format!("{base}/v1/methods")).send().await.unwrap().json::<Value>().await.unwrap()["model"].clone()
    };
    let job = json!({"scene": {"builtin": "torus"}, "output": {"width": 64, "height": 48}, "method": {"name": "auto", "max_ms": 5000}});
    let mut seen = Vec::new();
    let started = std::time::Instant::now();
    while started.elapsed() < std::time::Duration::from_secs(300) {
        let shown = model(client.clone(), base.clone()).await;
        let status = shown["status"].as_str().unwrap().to_owned();
        if !seen.contains(&status) {
            seen.push(status.clone());
        }
        assert_eq!(client.get(format!("{base}/readyz")).send().await.unwrap().status(), StatusCode::OK, "ready while {status}");
        if status == "measured" || status == "failed" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(250)).await;
    }
    assert_eq!(seen.last().map(String::as_str), Some("measured"), "{seen:?}");
    assert!(seen.iter().any(|s| s == "measuring"), "{seen:?}");
    let answer = render_json(&client, &base, &job).await;
    assert_eq!(answer["auto"]["model"], "measured", "{answer}");
    drop(daemon);
    let stored = std::fs::read_dir(data.path().join("models")).unwrap().count();
    assert_eq!(stored, 1);
    let (_again, base) = serve(&flags, &[("PENUMBRA_MODEL", "quick")]).await;
    let mut shown = Value::Null;
    for _ in 0..100 {
        shown = model(client.clone(), base.clone()).await;
        if shown["status"] != "default" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    assert_eq!(shown["status"], "stored", "{shown}");
}

/// The server-sent events of a finished job's stream: (name, data) in order.
async fn read_events(client: &reqwest::Client, url: &str) -> Vec<(String, Value)> {
    let text = client.get(url).send().await.unwrap().text().await.unwrap();
    text.split("\n\n")
        .filter(|block| block.contains("data:"))
        .map(|block| {
            let name = block.lines().find_map(|l| l.strip_prefix("event: ")).unwrap_or_default().to_owned();
            let data = block.lines().find_map(|l| l.strip_prefix("data: ")).unwrap();
            (name, serde_json::from_str(data).unwrap())
        })
        .collect()
}

/// Progressive jobs (contract §5): a first image from a fast method, then the reference in
/// rounds of 16, 32, 64 samples, each an SSE `round` event with its samples, its error
/// estimate and its image; the final image is the reference of those samples and that seed,
/// byte for byte; the rounds stop at the error or the time asked for; bad budgets are 422s
/// naming their field, and `penumbra submit --progressive` writes each round over its output.
#[tokio::test(flavor = "multi_thread")]
async fn a_progressive_job_refines_in_rounds_and_ends_as_the_reference_of_its_samples() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    let job = |progressive: Value| {
        json!({"scene": {"builtin": "torus"}, "output": {"width": 96, "height": 64},
               "method": {"name": "reference", "samples": 64, "seed": 3}, "progressive": progressive})
    };
    let submit = |job: Value| {
        let (client, base) = (client.clone(), base.clone());
        async move {
            let accepted = client.post(format!("{base}/v1/jobs")).json(&job).send().await.unwrap();
            assert_eq!(accepted.status(), StatusCode::ACCEPTED);
            let links: Value = accepted.json().await.unwrap();
            let events = read_events(&client, &format!("{base}{}", links["events"].as_str().unwrap())).await;
            let record: Value =
                client.get(format!("{base}{}", links["record"].as_str().unwrap())).send().await.unwrap().json().await.unwrap();
            (events, record)
        }
    };

    // Every sample asked for: four rounds, each an event, the last the job's image.
    let (events, record) = submit(job(json!({"max_error": 1e-6}))).await;
    assert_eq!(record["status"], "succeeded", "{record}");
    let rounds: Vec<&Value> = events.iter().filter(|(name, _)| name == "round").map(|(_, e)| &e["round"]).collect();
    assert_eq!(rounds.iter().map(|r| r["round"].as_u64().unwrap()).collect::<Vec<_>>(), [0, 1, 2, 3], "{events:?}");
    assert_eq!(rounds.iter().map(|r| r["samples"].as_u64().unwrap()).collect::<Vec<_>>(), [0, 16, 32, 64]);
    assert_eq!(rounds[0]["predicted"], true, "the first image's error is the model's");
    assert_ne!(rounds[0]["method"], "reference");
    assert!(rounds[1..].iter().all(|r| r["predicted"] == false && r["error_estimate"].as_f64().unwrap() > 0.0), "{rounds:?}");
    assert!(rounds[3]["error_estimate"].as_f64() < rounds[1]["error_estimate"].as_f64(), "the estimate falls: {rounds:?}");
    assert!(rounds.iter().enumerate().all(|(k, r)| r["image"].as_str().unwrap().ends_with(&format!("/rounds/{k}"))));
    assert_eq!(events.last().unwrap().0, "succeeded");
    let progressive = &record["progressive"];
    assert_eq!(progressive["stopped"], "samples", "{record}");
    assert_eq!(progressive["rounds"].as_array().unwrap().len(), 4);
    assert_eq!(progressive["equivalent"], json!({"name": "reference", "samples": 64, "seed": 3, "engine": "cpu"}));
    // The final image is that reference's, rendered once.
    let id = record["id"].as_str().unwrap();
    let image = client.get(format!("{base}/v1/jobs/{id}/image")).send().await.unwrap().bytes().await.unwrap();
    let once = json!({"scene": {"builtin": "torus"}, "output": {"width": 96, "height": 64}, "method": progressive["equivalent"]});
    let rendered = client.post(format!("{base}/v1/render")).json(&once).send().await.unwrap().bytes().await.unwrap();
    assert!(image == rendered, "the progressive job's final image is the reference of its samples, byte for byte");
    // Round images are kept only while the job runs.
    let gone = client.get(format!("{base}/v1/jobs/{id}/rounds/1")).send().await.unwrap();
    assert_eq!(gone.status(), StatusCode::NOT_FOUND);

    // An error budget: it stops at the first round whose estimate meets it.
    let (_, record) = submit(job(json!({"max_error": 0.2}))).await;
    assert_eq!(record["progressive"]["stopped"], "max_error", "{record}");
    let last = record["progressive"]["rounds"].as_array().unwrap().last().unwrap().clone();
    assert!(last["error_estimate"].as_f64().unwrap() <= 0.2 && last["samples"] == 16, "{record}");
    // A time budget spent by the first image: no reference round starts.
    let (_, record) = submit(job(json!({"max_ms": 1}))).await;
    assert_eq!(record["status"], "succeeded", "{record}");
    assert_eq!(record["progressive"]["stopped"], "max_ms", "{record}");
    assert_eq!(record["progressive"]["rounds"].as_array().unwrap().len(), 1);
    assert_ne!(record["progressive"]["equivalent"]["name"], "reference");

    // Bad budgets, and what a progressive job cannot be.
    let mut compared = job(json!({"max_error": 0.01}));
    compared["compare"] = json!(true);
    let mut pcss = job(json!({"max_error": 0.01}));
    pcss["method"] = json!({"name": "pcss"});
    for (body, route, field) in [
        (job(json!({})), "jobs", "progressive.max_error"),
        (job(json!({"max_error": 1.5})), "jobs", "progressive.max_error"),
        (job(json!({"max_ms": -3})), "jobs", "progressive.max_ms"),
        (job(json!({"max_ms": 1e12})), "jobs", "progressive.max_ms"),
        (compared, "jobs", "compare"),
        (pcss, "jobs", "method.name"),
        (job(json!({"max_error": 0.01})), "render", "progressive"),
    ] {
        let (status, error) = refusal(client.post(format!("{base}/v1/{route}")).json(&body).send().await.unwrap()).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{route} {body}");
        assert_eq!(error["field"], field, "{route} {error}");
    }

    // The client follows the rounds, writing each over its output.
    let work = tempdir::Dir::new();
    let mut cli_job = job(json!({}));
    cli_job.as_object_mut().unwrap().remove("progressive");
    std::fs::write(work.path().join("job.json"), cli_job.to_string()).unwrap();
    let output = work.path().join("refined.png");
    let (job_file, output_file) = (work.path().join("job.json").display().to_string(), output.display().to_string());
    let args = ["submit", &job_file, "--server", &base, "--quiet", "--progressive", "--max-error", "1e-6", "-o", &output_file];
    let ran = tools::cli(args.map(str::to_owned).to_vec(), vec![]).await;
    assert!(ran.status.success(), "{}", String::from_utf8_lossy(&ran.stderr));
    let report: Value = serde_json::from_slice(&ran.stdout).unwrap();
    assert_eq!(report["rounds"].as_array().unwrap().len(), 4, "{report}");
    assert!(std::fs::read(&output).unwrap() == rendered, "the file ends as the final image");
    assert!(String::from_utf8_lossy(&ran.stderr).contains("after 4 rounds"), "{}", String::from_utf8_lossy(&ran.stderr));
}

/// The dashboard shows a running progressive job refining: its latest round's image and
/// estimated error, fetched while the job runs (headless Chromium).
#[tokio::test(flavor = "multi_thread")]
async fn the_dashboard_shows_a_progressive_job_refining() {
    let (base, _dir) = start().await;
    let client = reqwest::Client::new();
    // Every sample a reference may take, at an error nothing reaches: it runs until cancelled.
    let job = json!({"scene": {"builtin": "crowd"}, "output": {"width": 320, "height": 240},
                     "method": {"name": "reference", "samples": 4096}, "progressive": {"max_error": 1e-6}});
    let accepted: Value = client.post(format!("{base}/v1/jobs")).json(&job).send().await.unwrap().json().await.unwrap();
    let record = format!("{base}{}", accepted["record"].as_str().unwrap());
    let id = accepted["id"].as_str().unwrap().to_owned();
    // Bounded: the first reference round of a small frame comes within seconds.
    let mut round = Value::Null;
    for _ in 0..600 {
        let now: Value = client.get(&record).send().await.unwrap().json().await.unwrap();
        assert!(now["status"].as_str().is_some_and(|s| s == "queued" || s == "running"), "{now}");
        if now["round"]["round"].as_u64().is_some_and(|r| r >= 1) {
            round = now["round"].clone();
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    assert!(round.is_object(), "a reference round was published");
    let image = client.get(format!("{base}{}", round["image"].as_str().unwrap())).send().await.unwrap();
    assert_eq!(image.status(), StatusCode::OK, "a running job's round image is served");
    assert_eq!(image.headers()[reqwest::header::CONTENT_TYPE], "image/png");

    let url = format!("{base}/");
    let dom = tokio::task::spawn_blocking(move || common::chromium(&["--dump-dom"], &url)).await.unwrap();
    let body = common::body_tag(&dom);
    assert!(common::attribute(&body, "data-refining").starts_with(&format!("{id}:")), "{body}");
    assert!(dom.contains("id=\"refining-section\"") && !dom.contains("id=\"refining-section\" hidden"), "shown");
    assert!(dom.contains("estimated error 0."), "the round's caption: {dom}");
    assert!(dom.contains("<img alt=\"round "), "the round's image");
    assert_eq!(client.delete(&record).send().await.unwrap().status(), StatusCode::ACCEPTED);
}
