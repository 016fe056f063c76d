//! The edge tools touch, over real HTTP: idempotent submission, the job listing, ETags and
//! 304s, request ids in answers and logs, problem details, the OpenAPI document generated
//! from the code, and the `penumbra submit` / `penumbra jobs` client against a daemon that
//! needs a token.

use super::*;

use penumbra::store::{EmbeddedStore, JobStore, Store};

/// A daemon in-process on `store` (None: in memory).
async fn start_on(store: Option<Arc<dyn JobStore>>) -> (String, tempdir::Dir, Arc<AppState>) {
    let (base, dir, _, state) = start_configured(DEFAULT_CACHE_BYTES, |state| match store {
        Some(store) => state.with_store(Store::new(store, "embedded", 0)),
        None => state,
    })
    .await;
    (base, dir, state)
}

/// `POST /v1/jobs` with headers: status, headers and JSON body.
async fn post_job(
    client: &reqwest::Client,
    base: &str,
    job: &Value,
    headers: &[(&str, &str)],
) -> (StatusCode, reqwest::header::HeaderMap, Value) {
    let mut request = client.post(format!("{base}/v1/jobs")).body(job.to_string()).header("content-type", "application/json");
    for (name, value) in headers {
        request = request.header(*name, *value);
    }
    let response = request.send().await.unwrap();
    let (status, headers) = (response.status(), response.headers().clone());
    (status, headers, response.json().await.unwrap_or(Value::Null))
}

/// Waits until a submitted job has finished; its record.
async fn finished(client: &reqwest::Client, base: &str, id: &str) -> Value {
    client.get(format!("{base}/v1/jobs/{id}/events")).send().await.unwrap().text().await.unwrap();
    client.get(format!("{base}/v1/jobs/{id}")).send().await.unwrap().json().await.unwrap()
}

async fn listed(client: &reqwest::Client, base: &str, query: &str) -> (StatusCode, Value) {
    let response = client.get(format!("{base}/v1/jobs{query}")).send().await.unwrap();
    (response.status(), response.json().await.unwrap())
}

/// The same key and body make one job — sent again, sent by eight twins at once, sent after a
/// restart on the embedded store — and another body under the key is refused naming it; a
/// malformed key is refused, naming the header.
#[tokio::test(flavor = "multi_thread")]
async fn an_idempotency_key_makes_one_job_in_memory_and_in_the_embedded_store() {
    let data = tempdir::Dir::new();
    let embedded: Arc<dyn JobStore> = Arc::new(EmbeddedStore::open(data.path()).unwrap());
    let client = reqwest::Client::new();
    for store in [None, Some(embedded.clone())] {
        let (base, _dir, _) = start_on(store.clone()).await;
        let job = small_job("png");
        let (status, headers, first) = post_job(&client, &base, &job, &[("idempotency-key", "retry-safe-1")]).await;
        assert_eq!(status, StatusCode::ACCEPTED, "{first}");
        assert!(headers.get("idempotent-replayed").is_none());
        let id = first["id"].as_str().unwrap().to_owned();
        // The same job, spaced and ordered otherwise: the first job, nothing new.
        let reordered: Value = serde_json::from_str(&format!(
            " {{ \"output\": {}, \"light\": {}, \"scene\": {} }}",
            job["output"], job["light"], job["scene"]
        ))
        .unwrap();
        let (status, headers, again) = post_job(&client, &base, &reordered, &[("idempotency-key", "retry-safe-1")]).await;
        assert_eq!((status, again["id"].as_str()), (StatusCode::ACCEPTED, Some(id.as_str())));
        assert_eq!(headers["idempotent-replayed"], "true");
        assert_eq!(headers[reqwest::header::LOCATION].to_str().unwrap(), format!("/v1/jobs/{id}"));
        // Eight twins at once: one job.
        let twins = (0..8).map(|_| {
            let (client, base, job) = (client.clone(), base.clone(), job.clone());
            tokio::spawn(async move { post_job(&client, &base, &job, &[("idempotency-key", "twins-2")]).await })
        });
        let mut ids = std::collections::HashSet::new();
        for twin in twins {
            let (status, _, body) = twin.await.unwrap();
            assert_eq!(status, StatusCode::ACCEPTED, "{body}");
            ids.insert(body["id"].as_str().unwrap().to_owned());
        }
        assert_eq!(ids.len(), 1, "twins made {ids:?}");
        let (_, page) = listed(&client, &base, "?limit=500").await;
        let twin = ids.iter().next().unwrap();
        assert_eq!(page["jobs"].as_array().unwrap().iter().filter(|j| j["id"] == *twin || j["id"] == id).count(), 2);
        // Another body under a used key.
        let mut other = job.clone();
        other["output"]["width"] = json!(80);
        let (status, _, refused) = post_job(&client, &base, &other, &[("idempotency-key", "retry-safe-1")]).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
        assert_eq!(
            (refused["error"]["code"].as_str(), refused["error"]["field"].as_str()),
            (Some("idempotency_key_reused"), Some("Idempotency-Key"))
        );
        assert!(refused["error"]["message"].as_str().unwrap().contains("retry-safe-1"), "{refused}");
        // Malformed keys: refused, never stored.
        let long = "k".repeat(256);
        for bad in ["", long.as_str(), "two words"] {
            let (status, _, body) = post_job(&client, &base, &job, &[("idempotency-key", bad)]).await;
            assert_eq!(status, StatusCode::BAD_REQUEST, "{bad:?}: {body}");
            assert_eq!(
                (body["error"]["code"].as_str(), body["error"]["field"].as_str()),
                (Some("invalid_parameter"), Some("Idempotency-Key"))
            );
        }
        finished(&client, &base, &id).await;
        finished(&client, &base, twin).await;
    }
    // A restarted daemon on the same store still knows the key.
    let (base, _dir, _) = start_on(Some(embedded.clone())).await;
    let (_, headers, again) = post_job(&client, &base, &small_job("png"), &[("idempotency-key", "retry-safe-1")]).await;
    assert_eq!(headers["idempotent-replayed"], "true");
    assert_eq!(again["status"], "succeeded", "the key's job, as it is now: {again}");
}

/// `GET /v1/jobs`: newest first, in pages that continue where they ended, filtered by status
/// and method, with every bad parameter refused by name.
#[tokio::test(flavor = "multi_thread")]
async fn jobs_are_listed_newest_first_filtered_and_paged() {
    let data = tempdir::Dir::new();
    let client = reqwest::Client::new();
    for store in [None, Some(Arc::new(EmbeddedStore::open(data.path()).unwrap()) as Arc<dyn JobStore>)] {
        let (base, _dir, _) = start_on(store).await;
        let mut ids = Vec::new();
        for n in 0..5 {
            let mut job = small_job("png");
            job["method"] = json!({"name": if n % 2 == 0 { "hard" } else { "pcss" }});
            let (status, _, body) = post_job(&client, &base, &job, &[("x-request-id", &format!("list-{n}"))]).await;
            assert_eq!(status, StatusCode::ACCEPTED);
            ids.push(body["id"].as_str().unwrap().to_owned());
            // Distinct submission times, so that newest-first is the order of submission.
            tokio::time::sleep(std::time::Duration::from_millis(3)).await;
        }
        for id in &ids {
            finished(&client, &base, id).await;
        }
        let mut seen = Vec::new();
        let mut query = "?limit=2".to_owned();
        loop {
            let (status, page) = listed(&client, &base, &query).await;
            assert_eq!(status, StatusCode::OK, "{page}");
            let jobs = page["jobs"].as_array().unwrap();
            assert!(jobs.len() <= 2);
            seen.extend(jobs.iter().map(|j| j["id"].as_str().unwrap().to_owned()));
            match page["next_cursor"].as_str() {
                Some(cursor) => query = format!("?limit=2&cursor={cursor}"),
                None => break,
            }
        }
        let newest_first: Vec<String> = ids.iter().rev().cloned().collect();
        assert_eq!(seen, newest_first);
        let (_, pcss) = listed(&client, &base, "?method=pcss&status=succeeded").await;
        let pcss: Vec<&Value> = pcss["jobs"].as_array().unwrap().iter().collect();
        assert_eq!(pcss.len(), 2);
        assert!(pcss.iter().all(|j| j["method"] == "pcss"
            && j["status"] == "succeeded"
            && j["record"] == format!("/v1/jobs/{}", j["id"].as_str().unwrap())));
        assert_eq!(pcss[0]["request_id"], "list-3");
        let (_, none) = listed(&client, &base, "?status=failed").await;
        assert_eq!(none["jobs"], json!([]));
        for (query, field) in [
            ("?status=done", "status"),
            ("?method=nope", "method"),
            ("?limit=0", "limit"),
            ("?limit=501", "limit"),
            ("?limit=two", "limit"),
            ("?cursor=not-ours", "cursor"),
            ("?limit=1&limit=2", "limit"),
            ("?sort=asc", "sort"),
        ] {
            let (status, body) = listed(&client, &base, query).await;
            assert_eq!(status, StatusCode::BAD_REQUEST, "{query}: {body}");
            assert_eq!(
                (body["error"]["code"].as_str(), body["error"]["field"].as_str()),
                (Some("invalid_parameter"), Some(field)),
                "{query}"
            );
        }
    }
}

/// Results and uploads never change under their URL: a strong `ETag` (the bytes' SHA-256),
/// `Cache-Control: immutable`, and 304 for an `If-None-Match` that names it — from memory
/// and, after a restart, from the embedded store.
#[tokio::test(flavor = "multi_thread")]
async fn results_and_uploads_answer_304_to_their_etag() {
    let data = tempdir::Dir::new();
    let store: Arc<dyn JobStore> = Arc::new(EmbeddedStore::open(data.path()).unwrap());
    let client = reqwest::Client::new();
    let (base, _dir, _) = start_on(Some(store.clone())).await;
    let (_, _, accepted) = post_job(&client, &base, &small_job("png"), &[]).await;
    let id = accepted["id"].as_str().unwrap().to_owned();
    let record = finished(&client, &base, &id).await;
    let digest = record["image_sha256"].as_str().expect("the record names the image's digest").to_owned();
    let get = |path: String, etag: Option<String>| {
        let mut request = client.get(format!("{base}{path}"));
        if let Some(etag) = etag {
            request = request.header("if-none-match", etag);
        }
        request.send()
    };
    let image = get(format!("/v1/jobs/{id}/image"), None).await.unwrap();
    assert_eq!(image.headers()["etag"].to_str().unwrap(), format!("\"{digest}\""));
    assert!(image.headers()["cache-control"].to_str().unwrap().contains("immutable"));
    assert_eq!(sha256_hex(&image.bytes().await.unwrap()), digest, "the ETag is the bytes' SHA-256");
    for tag in [format!("\"{digest}\""), format!("W/\"{digest}\""), format!("\"other\", \"{digest}\""), "*".to_owned()] {
        let cached = get(format!("/v1/jobs/{id}/image"), Some(tag.clone())).await.unwrap();
        assert_eq!(cached.status(), StatusCode::NOT_MODIFIED, "{tag}");
        assert!(cached.bytes().await.unwrap().is_empty());
    }
    assert_eq!(get(format!("/v1/jobs/{id}/image"), Some("\"stale\"".into())).await.unwrap().status(), StatusCode::OK);
    let thumbnail = get(format!("/v1/jobs/{id}/thumbnail"), None).await.unwrap();
    let thumbnail_tag = thumbnail.headers()["etag"].to_str().unwrap().to_owned();
    assert_ne!(thumbnail_tag, format!("\"{digest}\""), "a thumbnail is other bytes");
    assert_eq!(get(format!("/v1/jobs/{id}/thumbnail"), Some(thumbnail_tag)).await.unwrap().status(), StatusCode::NOT_MODIFIED);

    // An upload: HEAD says its ETag and length.
    let light = common::png_light(8);
    let upload: Value = client.post(format!("{base}/v1/lights")).body(light.clone()).send().await.unwrap().json().await.unwrap();
    let upload_id = upload["id"].as_str().unwrap();
    let head = client.head(format!("{base}/v1/lights/{upload_id}")).send().await.unwrap();
    assert_eq!(head.status(), StatusCode::OK);
    assert_eq!(head.headers()["etag"].to_str().unwrap(), format!("\"{upload_id}\""));
    assert_eq!(head.headers()["content-length"].to_str().unwrap(), light.len().to_string());
    let cached =
        client.head(format!("{base}/v1/lights/{upload_id}")).header("if-none-match", format!("\"{upload_id}\"")).send().await.unwrap();
    assert_eq!(cached.status(), StatusCode::NOT_MODIFIED);

    // After a restart the image comes from the store, with the same ETag.
    let (base, _dir, _) = start_on(Some(store)).await;
    let image = client.get(format!("{base}/v1/jobs/{id}/image")).send().await.unwrap();
    assert_eq!(image.headers()["etag"].to_str().unwrap(), format!("\"{digest}\""));
    let cached = client.get(format!("{base}/v1/jobs/{id}/image")).header("if-none-match", format!("\"{digest}\"")).send().await.unwrap();
    assert_eq!(cached.status(), StatusCode::NOT_MODIFIED);
}

/// Every answer names its request (`x-request-id`: the client's when well formed, a valid
/// `traceparent`'s trace id, else a new one), errors included; a client that asks gets RFC
/// 9457 problem details; a refusal that a retry may cure says when.
#[tokio::test(flavor = "multi_thread")]
async fn every_answer_names_its_request_and_errors_come_as_problem_details_when_asked() {
    let (base, _dir, state) = start_on(None).await;
    let client = reqwest::Client::new();
    let id_of = |response: &reqwest::Response| response.headers()["x-request-id"].to_str().unwrap().to_owned();
    let ok = client.get(format!("{base}/v1/methods")).header("x-request-id", "tool-7.run:3").send().await.unwrap();
    assert_eq!(id_of(&ok), "tool-7.run:3");
    let traced = client
        .get(format!("{base}/healthz"))
        .header("traceparent", "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01")
        .send()
        .await
        .unwrap();
    assert_eq!(id_of(&traced), "4bf92f3577b34da6a3ce929d0e0e4736");
    let replaced = client.get(format!("{base}/healthz")).header("x-request-id", "x".repeat(200)).send().await.unwrap();
    assert!(id_of(&replaced).len() == 32 && !id_of(&replaced).contains("xxx"), "an over-long id is replaced");
    let missing = client.get(format!("{base}/nowhere")).send().await.unwrap();
    assert_eq!(missing.status(), StatusCode::NOT_FOUND);
    assert_eq!(id_of(&missing).len(), 32);

    // The error body as it always was, or problem details when asked.
    let bad = json!({"scene": {"builtin": "torus"}, "camera": {"fov_y_deg": 500}});
    let plain = client.post(format!("{base}/v1/render")).json(&bad).send().await.unwrap();
    assert_eq!(plain.headers()["content-type"], "application/json");
    let plain: Value = plain.json().await.unwrap();
    assert_eq!(plain["error"]["field"], "camera.fov_y_deg");
    let problem = client
        .post(format!("{base}/v1/render"))
        .header("accept", "application/problem+json")
        .header("x-request-id", "problem-1")
        .json(&bad)
        .send()
        .await
        .unwrap();
    assert_eq!(problem.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(problem.headers()["content-type"], "application/problem+json");
    let problem: Value = problem.json().await.unwrap();
    assert_eq!(problem["type"], "urn:penumbra:error:invalid_field");
    assert_eq!((problem["status"].as_u64(), problem["title"].as_str()), (Some(422), Some("Unprocessable Entity")));
    assert_eq!(
        (problem["code"].as_str(), problem["field"].as_str(), problem["request_id"].as_str()),
        (Some("invalid_field"), Some("camera.fov_y_deg"), Some("problem-1"))
    );
    assert_eq!(problem["detail"], plain["error"]["message"]);

    // Stopping: 503 with Retry-After.
    state.begin_shutdown();
    let (status, headers, body) = post_job(&client, &base, &small_job("png"), &[]).await;
    assert_eq!((status, body["error"]["code"].as_str()), (StatusCode::SERVICE_UNAVAILABLE, Some("shutting_down")));
    assert!(headers["retry-after"].to_str().unwrap().parse::<u32>().unwrap() > 0);
}

/// The access log has one line per request (method, route template, status, bytes, duration,
/// request id), JSON under `--log-format json`; a submitted job's lines name the request
/// that submitted it, and its listing keeps the id.
#[tokio::test(flavor = "multi_thread")]
async fn request_ids_reach_the_access_log_and_the_jobs_log_lines() {
    let address = free_address();
    let mut command = common::daemon::serve_command(&address);
    command
        .args(["--no-warm-up", "--job-store", "memory", "--log-format", "json"])
        .env("PENUMBRA_LOG", "info")
        .stderr(std::process::Stdio::piped());
    let daemon = tokio::task::spawn_blocking(move || Daemon::start(command, &address)).await.unwrap();
    let base = daemon.base.clone();
    let client = reqwest::Client::new();
    let (_, _, accepted) = post_job(&client, &base, &small_job("png"), &[("x-request-id", "trace-me-42")]).await;
    let id = accepted["id"].as_str().unwrap().to_owned();
    finished(&client, &base, &id).await;
    let (_, page) = listed(&client, &base, "").await;
    assert_eq!(page["jobs"][0]["request_id"], "trace-me-42");
    let record: Value = client.get(format!("{base}/v1/jobs/{id}")).send().await.unwrap().json().await.unwrap();
    assert_eq!((record["status"].as_str(), record["request_id"].as_str()), (Some("succeeded"), Some("trace-me-42")));
    client.get(format!("{base}/v1/jobs/{id}/nothing-here")).send().await.unwrap();
    let mut daemon = daemon;
    daemon.child.kill().unwrap();
    let mut logs = String::new();
    std::io::Read::read_to_string(daemon.child.stderr.as_mut().unwrap(), &mut logs).unwrap();
    let lines: Vec<Value> = logs.lines().filter_map(|l| serde_json::from_str(l).ok()).collect();
    assert!(!lines.is_empty(), "JSON log lines: {logs}");
    let access: Vec<&Value> = lines.iter().filter(|l| l["target"] == "penumbra::access").collect();
    let submitted = access.iter().find(|l| l["span"]["request_id"] == "trace-me-42").expect("the submission's access line");
    let fields = &submitted["fields"];
    assert_eq!(
        (fields["method"].as_str(), fields["route"].as_str(), fields["status"].as_u64()),
        (Some("POST"), Some("/v1/jobs"), Some(202))
    );
    assert!(fields["duration_ms"].as_f64().is_some() && fields["bytes"].as_str().is_some(), "{submitted}");
    let unrouted = access.iter().find(|l| l["fields"]["status"] == 404).expect("the 404's access line");
    assert_eq!(unrouted["fields"]["route"], "(no route)", "an unmatched path is not logged as sent");
    let job_lines: Vec<&Value> = lines.iter().filter(|l| l.to_string().contains(&id) && l["target"] != "penumbra::access").collect();
    assert!(
        !job_lines.is_empty() && job_lines.iter().all(|l| l.to_string().contains("trace-me-42")),
        "the job's lines name its request: {job_lines:?}"
    );
}

/// The document is what the code generates (methods, built-ins, examples), every operation
/// has a unique `operationId` and a tag, and `/v1/methods` (names, parameters, defaults,
/// choices) and `/v1/limits` (ranges under the default caps) agree with the document's
/// methods. `PENUMBRA_BLESS=1` rewrites the generated parts.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openapi_document_is_generated_from_the_code() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/api/openapi.json");
    let text = std::fs::read_to_string(path).unwrap();
    let doc: Value = serde_json::from_str(&text).unwrap();
    let mut examples: Vec<(String, Value)> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/api/examples"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| (p.file_stem().unwrap().to_string_lossy().into_owned(), serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap()))
        .collect();
    examples.sort_by(|a, b| a.0.cmp(&b.0));
    let mut generated = doc.clone();
    penumbra::server::openapi::generate(&mut generated, &examples);
    if std::env::var("PENUMBRA_BLESS").is_ok_and(|v| v == "1") {
        std::fs::write(path, serde_json::to_string_pretty(&generated).unwrap() + "\n").unwrap();
    } else {
        assert!(doc == generated, "api/openapi.json is not what the code generates: run PENUMBRA_BLESS=1 cargo test --release --test api openapi_document_is_generated");
    }
    let mut ids = std::collections::HashSet::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (verb, operation) in item.as_object().unwrap() {
            let id = operation["operationId"].as_str().unwrap_or_else(|| panic!("{verb} {path} has no operationId"));
            assert!(ids.insert(id.to_owned()), "operationId {id} twice");
            assert!(["render", "jobs", "uploads", "service"].contains(&operation["tags"][0].as_str().unwrap_or("")), "{verb} {path}: tag");
        }
    }
    let (base, _dir) = start().await;
    let catalogue: Value = reqwest::get(format!("{base}/v1/methods")).await.unwrap().json().await.unwrap();
    let limits: Value = reqwest::get(format!("{base}/v1/limits")).await.unwrap().json().await.unwrap();
    let schemas = &generated["components"]["schemas"];
    let branches = schemas["Method"]["oneOf"].as_array().unwrap();
    // Every method of the catalogue, and `auto`.
    assert_eq!(branches.len(), catalogue["methods"].as_array().unwrap().len() + 1);
    for method in catalogue["methods"].as_array().unwrap() {
        let reference = schemas["Method"]["discriminator"]["mapping"][method["name"].as_str().unwrap()].as_str().unwrap();
        let schema = &schemas[reference.trim_start_matches("#/components/schemas/")];
        assert_eq!(schema["properties"]["name"]["const"], method["name"]);
        let params = method["params"].as_array().unwrap();
        assert_eq!(schema["properties"].as_object().unwrap().len(), params.len() + 1, "{}", method["name"]);
        let capped = limits["method_params"][method["name"].as_str().unwrap()].as_array().unwrap();
        for (param, capped) in params.iter().zip(capped) {
            let typed = &schema["properties"][param["name"].as_str().unwrap()];
            assert_eq!(typed["default"], param["default"], "{}.{}", method["name"], param["name"]);
            let range = (capped.get("min").unwrap_or(&Value::Null), capped.get("max").unwrap_or(&Value::Null));
            assert_eq!((&typed["minimum"], &typed["maximum"]), range, "{}.{}", method["name"], param["name"]);
            if let Some(options) = param.get("options") {
                assert_eq!(&typed["enum"], options);
            }
        }
    }
    assert_eq!(schemas["SceneRef"]["properties"]["builtin"]["enum"], catalogue["scenes"]);
    assert_eq!(schemas["LightImageRef"]["properties"]["builtin"]["enum"], catalogue["light_images"]);
}

/// `penumbra` run with `args` (and environment), off the async workers: its output.
pub(super) async fn cli(args: Vec<String>, env: Vec<(&'static str, String)>) -> std::process::Output {
    tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_penumbra"))
            .args(&args)
            .env_remove("PENUMBRA_TOKEN")
            .env_remove("PENUMBRA_SERVER")
            .envs(env)
            .output()
            .unwrap()
    })
    .await
    .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The client against a daemon that needs a token: `submit` with the token from a file or
/// the environment (a wrong one: one line, a non-zero exit), `--detach`, retries through a
/// full queue (429 and its `Retry-After`) without a second job, `jobs list | show | wait |
/// cancel` as tables and JSON, and Ctrl-C cancelling the remote job.
#[tokio::test(flavor = "multi_thread")]
async fn the_client_submits_lists_waits_and_cancels_with_a_token() {
    let work = tempdir::Dir::new();
    let token = "client-token-0123456789abcdef";
    let tokens = work.path().join("tokens");
    std::fs::write(&tokens, format!("# a token\n{token}\n")).unwrap();
    let data = work.path().join("data");
    let (daemon, base) = serve(
        &["--auth-token-file", tokens.to_str().unwrap(), "--data-dir", data.to_str().unwrap(), "--queue", "1", "--concurrency", "1"],
        &[],
    )
    .await;
    let job_file = work.path().join("job.json");
    std::fs::write(&job_file, small_job("png").to_string()).unwrap();
    let path = |name: &str| work.path().join(name).display().to_string();
    let args = |extra: &[&str]| -> Vec<String> {
        let mut args: Vec<String> = extra.iter().map(|a| a.to_string()).collect();
        args.extend(["--server".to_owned(), base.clone()]);
        args
    };
    let with_file = vec![("PENUMBRA_TOKEN_FILE", tokens.display().to_string())];

    // The token from a file, then from the environment.
    let output = cli(args(&["submit", &job_file.display().to_string(), "--quiet", "-o", &path("a.png")]), with_file.clone()).await;
    assert!(output.status.success(), "{}", text(&output.stderr));
    let first: Value = serde_json::from_slice(&output.stdout).unwrap();
    let output = cli(
        args(&["submit", &job_file.display().to_string(), "--quiet", "-o", &path("b.png")]),
        vec![("PENUMBRA_TOKEN", token.to_owned())],
    )
    .await;
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert_eq!(std::fs::read(path("a.png")).unwrap(), std::fs::read(path("b.png")).unwrap());

    // A wrong token, or none: one line, a non-zero exit, and the token never printed.
    for env in [vec![("PENUMBRA_TOKEN", "wrong-token-0123456789abcdef".to_owned())], vec![]] {
        let output = cli(args(&["submit", &job_file.display().to_string(), "--quiet", "-o", &path("c.png")]), env).await;
        let stderr = text(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{stderr}");
        assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
        assert!(stderr.contains("401") && !stderr.contains("panicked") && !stderr.contains("wrong-token"), "{stderr}");
    }

    // A full queue: a slow job holds the one place; the client waits out the 429s it gets
    // (Retry-After) and its retries make no second job.
    let slow = json!({"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 1024, "resolution": 512}, "output": {"width": 160, "height": 120}});
    let client = reqwest::Client::new();
    let blocker = client.post(format!("{base}/v1/jobs")).bearer_auth(token).json(&slow).send().await.unwrap();
    assert_eq!(blocker.status(), StatusCode::ACCEPTED);
    let blocker: Value = blocker.json().await.unwrap();
    let output =
        cli(args(&["submit", &job_file.display().to_string(), "--quiet", "--retries", "60", "-o", &path("d.png")]), with_file.clone())
            .await;
    assert!(output.status.success(), "{}", text(&output.stderr));
    let retried: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert!(retried["retries"].as_u64().unwrap() >= 1, "the queue was full at first: {retried}");
    let listed = cli(args(&["jobs", "list", "--json", "--limit", "500"]), with_file.clone()).await;
    assert!(listed.status.success(), "{}", text(&listed.stderr));
    let jobs: Vec<Value> = serde_json::from_slice(&listed.stdout).unwrap();
    assert_eq!(jobs.len(), 4, "two submits, the blocker and the retried one: {jobs:?}");
    assert_eq!(jobs[0]["id"], retried["id"], "newest first");
    assert!(jobs.iter().any(|j| j["id"] == first["id"]));

    // People get a table; show, wait (downloading) and cancel by id.
    let table = cli(args(&["jobs", "list", "--status", "succeeded"]), with_file.clone()).await;
    let table = text(&table.stdout);
    assert!(table.starts_with("ID") && table.contains(first["id"].as_str().unwrap()) && table.contains("succeeded"), "{table}");
    let id = first["id"].as_str().unwrap();
    let show = cli(args(&["jobs", "show", id]), with_file.clone()).await;
    assert!(text(&show.stdout).contains("succeeded"), "{}", text(&show.stdout));
    let wait = cli(args(&["jobs", "wait", id, "-o", &path("e.png")]), with_file.clone()).await;
    assert!(wait.status.success(), "{}", text(&wait.stderr));
    assert_eq!(std::fs::read(path("e.png")).unwrap(), std::fs::read(path("a.png")).unwrap());
    let cancel = cli(args(&["jobs", "cancel", id]), with_file.clone()).await;
    assert_eq!(cancel.status.code(), Some(2), "a finished job cannot be cancelled");
    assert!(text(&cancel.stderr).contains("409"), "{}", text(&cancel.stderr));

    // --detach returns at acceptance; Ctrl-C on a following submit cancels its job.
    let slow_file = work.path().join("slow.json");
    std::fs::write(&slow_file, slow.to_string()).unwrap();
    let detached =
        cli(args(&["submit", &slow_file.display().to_string(), "--detach", "--quiet", "--retries", "60"]), with_file.clone()).await;
    assert!(detached.status.success(), "{}", text(&detached.stderr));
    let detached: Value = serde_json::from_slice(&detached.stdout).unwrap();
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_penumbra"));
    command
        .args(args(&["submit", &slow_file.display().to_string(), "--quiet", "--retries", "120", "-o", &path("f.png")]))
        .envs(with_file.clone());
    let child = command.stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped()).spawn().unwrap();
    let known = [blocker["id"].clone(), detached["id"].clone()];
    let interrupted = loop {
        let page: Value = client.get(format!("{base}/v1/jobs")).bearer_auth(token).send().await.unwrap().json().await.unwrap();
        if let Some(job) =
            page["jobs"].as_array().unwrap().iter().find(|j| !known.contains(&j["id"]) && !jobs.iter().any(|k| k["id"] == j["id"]))
        {
            break job["id"].as_str().unwrap().to_owned();
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    };
    // SAFETY: kill(2) on our own child's pid with SIGINT; no memory is touched.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
    let output = tokio::task::spawn_blocking(move || child.wait_with_output().unwrap()).await.unwrap();
    assert_eq!(output.status.code(), Some(130), "{}", text(&output.stderr));
    assert!(text(&output.stderr).contains("cancelled on the server"), "{}", text(&output.stderr));
    // A running job stops at its next batch: its events end with `cancelled`.
    let events = client.get(format!("{base}/v1/jobs/{interrupted}/events")).bearer_auth(token).send().await.unwrap().text().await.unwrap();
    assert!(events.contains("event: cancelled"), "{events}");
    for id in known {
        client.delete(format!("{base}/v1/jobs/{}", id.as_str().unwrap())).bearer_auth(token).send().await.unwrap();
    }
    drop(daemon);
}
