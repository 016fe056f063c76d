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
    let child = Child(
        Command::new("redis-server")
            .args(["--port", &port.to_string(), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no"])
            .stdout(std::process::Stdio::null())
            .spawn()
            .expect("redis-server (apt-get install redis-server)"),
    );
    (port, child)
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
        let ping = || {
            Command::new("redis-cli").args(["-p", &redis_port.to_string(), "PING"]).output().is_ok_and(|o| o.stdout.starts_with(b"PONG"))
        };
        assert!(wait_until(Duration::from_secs(20), ping).is_some(), "redis-server did not start");

        let ports: Vec<u16> = (0..replicas).map(|_| free_port()).collect();
        let children = ports
            .iter()
            .map(|port| {
                Some(Child(
                    Command::new(env!("CARGO_BIN_EXE_penumbra"))
                        .args(["serve", "--no-warm-up", "--listen", &format!("127.0.0.1:{port}"), "--claim-idle-secs", "2"])
                        .args(["--job-store", &format!("redis://127.0.0.1:{redis_port}/0")])
                        .env_remove("HOSTNAME")
                        .env("PENUMBRA_LOG", "warn")
                        .stderr(std::process::Stdio::null())
                        .spawn()
                        .unwrap(),
                ))
            })
            .collect();
        for port in &ports {
            let ready = || http("GET", &format!("http://127.0.0.1:{port}/readyz"), None).is_some_and(|(s, _)| s == 200);
            assert!(wait_until(Duration::from_secs(60), ready).is_some(), "replica on {port} not ready");
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
        let binary = if Path::new("/usr/sbin/nginx").exists() { "/usr/sbin/nginx" } else { "nginx" };
        let nginx = Nginx(
            Command::new(binary)
                .arg("-p")
                .arg(work.join("nginx"))
                .arg("-c")
                .arg(work.join("nginx/nginx.conf"))
                .args(["-g", "daemon off;"])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .expect("nginx (apt-get install nginx)"),
        );
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

/// The cluster on loopback (issue 10): Debian's `redis-server`, three replicas sharing it as
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
    let long = r#"{"scene": {"builtin": "occluder"}, "method": {"name": "reference", "samples": 4096, "resolution": 1024}, "output": {"width": 128, "height": 96}}"#;
    let id = cluster.submit(long, "builtin:occluder");
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

/// The figures of the deploy issue's closing note, printed, never asserted (run by hand:
/// `cargo test --release --test deploy -- --ignored --nocapture cluster_figures`): what a
/// small job costs through nginx and Redis against one replica on the embedded store, how
/// many jobs per second each store sustains on its own, and the scene-cache hit rate across
/// three replicas with consistent hashing against round robin (30 scenes × 10 jobs).
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
    let _single = Child(
        Command::new(env!("CARGO_BIN_EXE_penumbra"))
            .args(["serve", "--no-warm-up", "--listen", &format!("127.0.0.1:{port}"), "--data-dir"])
            .arg(&data)
            .env("PENUMBRA_LOG", "warn")
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    assert!(wait_until(Duration::from_secs(60), || http("GET", &format!("{direct}/readyz"), None).is_some_and(|(s, _)| s == 200)).is_some());
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
            let id = penumbra::uploads::content_id(&bytes);
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
        let store = penumbra::store::RedisStore::open(&url, Duration::from_secs(60), Duration::from_millis(500)).ok()?;
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
    let _replica = Child(
        Command::new(env!("CARGO_BIN_EXE_penumbra"))
            .args(["serve", "--no-warm-up", "--listen", &format!("127.0.0.1:{port}"), "--claim-idle-secs", "1", "--job-store", &url])
            .env("PENUMBRA_LOG", "warn")
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    let failed = wait_until(Duration::from_secs(60), || store.get("poison").unwrap().is_some_and(|j| j.status == "failed"));
    assert!(failed.is_some(), "the poison job was not failed: {:?}", store.get("poison").unwrap());
    let record = store.get("poison").unwrap().unwrap();
    assert_eq!(record.attempts, penumbra::store::MAX_ATTEMPTS, "it was not rendered again");
    assert!(record.error.unwrap()["message"].as_str().unwrap().contains("started 3 times"));
    // Any replica serves the failure, with the reason.
    let (status, body) = http("GET", &format!("http://127.0.0.1:{port}/v1/jobs/poison"), None).unwrap();
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&body).contains("started 3 times"));
}
