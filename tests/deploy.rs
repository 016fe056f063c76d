//! Deployment, on the real tools: the Dockerfile under hadolint (error level), the
//! Kubernetes manifests under kubernetes-validate (strict, a recent Kubernetes), and the
//! container image built by `deploy/build-image.sh` — it becomes ready, renders a job sent
//! over loopback, and on `docker stop` finishes its running job and exits 0. The tools come
//! from `deploy/install-test-deps.sh` (the README's test command runs it first).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A tool from the test virtual environment (`$PENUMBRA_TOOLS`, default ~/.cache/penumbra-tools).
fn tool(name: &str) -> PathBuf {
    let dir = std::env::var_os("PENUMBRA_TOOLS")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(std::env::var_os("HOME").expect("HOME")).join(".cache/penumbra-tools"));
    let path = dir.join("bin").join(name);
    assert!(path.exists(), "{} is missing: run ./deploy/install-test-deps.sh", path.display());
    path
}

fn run(command: &mut Command) -> String {
    let output = command.output().unwrap_or_else(|e| panic!("cannot run {command:?}: {e}"));
    let text = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "{command:?} failed:\n{text}");
    text
}

#[test]
fn the_dockerfile_passes_hadolint_at_error_level() {
    run(Command::new(tool("hadolint")).args(["--failure-threshold", "error"]).arg(repo().join("deploy/Dockerfile")));
}

#[test]
fn the_kubernetes_manifests_validate_strictly() {
    let dir = repo().join("deploy/k8s");
    let mut manifests: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml") && !p.ends_with("kustomization.yaml"))
        .collect();
    manifests.sort();
    assert!(manifests.len() >= 7, "{manifests:?}");
    let report = run(Command::new(tool("kubernetes-validate")).args(["--strict", "--kubernetes-version", "1.34.0"]).args(&manifests));
    // Every resource the kustomization lists is among the validated files.
    let kustomization = std::fs::read_to_string(dir.join("kustomization.yaml")).unwrap();
    for listed in kustomization.lines().filter_map(|l| l.trim().strip_prefix("- ")) {
        assert!(dir.join(listed).exists(), "kustomization lists a missing {listed}");
    }
    for kind in [
        "deployment/penumbra",
        "deployment/penumbra-gpu",
        "service/penumbra",
        "horizontalpodautoscaler/penumbra",
        "poddisruptionbudget/penumbra",
    ] {
        assert!(report.contains(&format!("passed for resource {kind} ")), "{kind} not validated:\n{report}");
    }
}

/// Removes the test's container however the test ends.
struct Container(String);

impl Drop for Container {
    fn drop(&mut self) {
        let _ = Command::new("docker").args(["rm", "-f", &self.0]).output();
    }
}

fn docker(args: &[&str]) -> String {
    run(Command::new("docker").args(args)).trim().to_owned()
}

/// A blocking HTTP exchange over loopback (the test has no async runtime).
fn http(method: &str, url: &str, body: Option<&str>) -> Option<(u16, Vec<u8>)> {
    let mut command = Command::new("curl");
    command.args(["-s", "-m", "30", "-X", method, "-o", "-", "-w", "\n%{http_code}", url]);
    if let Some(body) = body {
        command.args(["-H", "content-type: application/json", "-d", body]);
    }
    let output = command.output().ok()?;
    let text = output.stdout;
    let split = text.iter().rposition(|&b| b == b'\n')?;
    let status = std::str::from_utf8(&text[split + 1..]).ok()?.trim().parse().ok()?;
    Some((status, text[..split].to_vec()))
}

fn wait_until(limit: Duration, mut ready: impl FnMut() -> bool) -> Option<Duration> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if ready() {
            return Some(start.elapsed());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    None
}

#[test]
fn the_container_image_builds_serves_and_stops_gracefully() {
    run(Command::new(repo().join("deploy/build-image.sh")).arg("penumbra:test").env("PENUMBRA_BINARY", env!("CARGO_BIN_EXE_penumbra")));
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let base = format!("http://127.0.0.1:{port}");
    let name = format!("penumbra-test-{}", std::process::id());
    let started = Instant::now();
    docker(&[
        "run",
        "-d",
        "--name",
        &name,
        "--network",
        "host",
        "--cpus",
        "2",
        "--stop-timeout",
        "120",
        "-e",
        &format!("PENUMBRA_LISTEN=127.0.0.1:{port}"),
        "penumbra:test",
    ]);
    let _container = Container(name.clone());
    let ready = wait_until(Duration::from_secs(120), || http("GET", &format!("{base}/readyz"), None).is_some_and(|(s, _)| s == 200));
    assert!(ready.is_some(), "the container never became ready:\n{}", docker(&["logs", &name]));
    eprintln!("cold start: container start to /readyz in {:.1} s", started.elapsed().as_secs_f64());
    let logs = docker(&["logs", &name]);
    assert!(logs.contains("lavapipe_threads=\"2\""), "LP_NUM_THREADS follows the CPU limit:\n{logs}");
    assert_eq!(docker(&["exec", &name, "id", "-u"]), "10001", "the daemon runs as a non-root user");

    let (status, png) =
        http("POST", &format!("{base}/v1/render"), Some(r#"{"scene": {"builtin": "torus"}, "output": {"width": 128, "height": 96}}"#))
            .unwrap();
    assert_eq!(status, 200);
    assert!(png.starts_with(b"\x89PNG"), "a PNG over loopback");

    // A slow job running when `docker stop` sends SIGTERM finishes; the process exits 0.
    let job = r#"{"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 512, "resolution": 256}, "output": {"width": 160, "height": 120}}"#;
    let (status, accepted) = http("POST", &format!("{base}/v1/jobs"), Some(job)).unwrap();
    assert_eq!(status, 202);
    let id = serde_json::from_slice::<serde_json::Value>(&accepted).unwrap()["id"].as_str().unwrap().to_owned();
    let record = |base: &str| {
        http("GET", &format!("{base}/v1/jobs/{id}"), None).map(|(_, b)| serde_json::from_slice::<serde_json::Value>(&b).unwrap_or_default())
    };
    assert!(wait_until(Duration::from_secs(60), || record(&base).is_some_and(|r| r["status"] == "running")).is_some());
    docker(&["stop", &name]);
    assert_eq!(docker(&["inspect", "--format", "{{.State.ExitCode}}", &name]), "0", "{}", docker(&["logs", &name]));
    // The same container (same data volume) started again has the job's result.
    docker(&["start", &name]);
    assert!(wait_until(Duration::from_secs(120), || http("GET", &format!("{base}/readyz"), None).is_some_and(|(s, _)| s == 200)).is_some());
    let finished = record(&base).unwrap();
    assert_eq!(finished["status"], "succeeded", "the running job finished before the stop: {finished}");
    let (status, image) = http("GET", &format!("{base}/v1/jobs/{id}/image"), None).unwrap();
    assert!(status == 200 && image.starts_with(b"\x89PNG"));
}
