//! Hardening on the real tools: `cargo fuzz` (libFuzzer, `--sanitizer none` on the stable
//! toolchain) runs each fuzz target for a bounded time from the seed corpus in
//! `fuzz/seeds/` (the job parser and validator, the glTF/GLB loader, the light-image
//! decoder). Any crash fails the test and leaves its input in `fuzz/artifacts/TARGET/`: it
//! then becomes a regression test in `tests/api.rs` or the module's own tests.

mod common;

use std::path::Path;
use std::process::Command;

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The test virtual environment (`$PENUMBRA_TOOLS`, default ~/.cache/penumbra-tools), as
/// `deploy/install-test-deps.sh` makes it.
fn tools_dir() -> std::path::PathBuf {
    std::env::var_os("PENUMBRA_TOOLS")
        .filter(|d| !d.is_empty())
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::path::PathBuf::from(std::env::var_os("HOME").expect("HOME")).join(".cache/penumbra-tools"))
}

/// Seconds per target: `PENUMBRA_FUZZ_SECS`, default 45 (docs/testing.md's long form: 600).
fn fuzz_seconds() -> u64 {
    std::env::var("PENUMBRA_FUZZ_SECS").ok().and_then(|s| s.parse().ok()).unwrap_or(45)
}

#[test]
fn fuzz_targets_survive_their_time_budget() {
    let fuzz = |args: &[&str]| {
        let output = Command::new("cargo")
            .arg("fuzz")
            .args(args)
            .current_dir(repo())
            .output()
            .unwrap_or_else(|e| panic!("cannot run cargo fuzz ({e}): cargo install cargo-fuzz"));
        let text = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
        (output.status.success(), text)
    };
    let (built, log) = fuzz(&["build", "--sanitizer", "none"]);
    assert!(built, "cargo fuzz build failed:\n{log}");
    let seconds = fuzz_seconds().to_string();
    for target in ["job", "scene", "light_image"] {
        // A scratch corpus (what libFuzzer adds) apart from the committed seeds.
        let corpus = std::env::temp_dir().join(format!("penumbra-fuzz-{}-{target}", std::process::id()));
        std::fs::create_dir_all(&corpus).unwrap();
        let seeds = repo().join("fuzz/seeds").join(target);
        let max_time = format!("-max_total_time={seconds}");
        let (ok, log) = fuzz(&[
            "run",
            "--sanitizer",
            "none",
            target,
            corpus.to_str().unwrap(),
            seeds.to_str().unwrap(),
            "--",
            &max_time,
            "-rss_limit_mb=3072",
            "-timeout=20",
            "-max_len=65536",
        ]);
        std::fs::remove_dir_all(&corpus).ok();
        let stats = log.lines().filter(|l| l.contains("Done ") || l.starts_with("#") && l.contains("DONE")).collect::<Vec<_>>().join("\n");
        eprintln!("fuzz {target}: {stats}");
        assert!(
            ok,
            "fuzz target {target} crashed:\n{}",
            log.lines().rev().take(60).collect::<Vec<_>>().into_iter().rev().collect::<Vec<_>>().join("\n")
        );
    }
}

/// API conformance: `schemathesis` drives every operation of `api/openapi.json` against the
/// real daemon — examples, coverage, fuzzed and stateful sequences — and checks that nothing
/// answers 5xx and every response matches the document (status, content type, headers,
/// schema), with no warning that the document allows what the server refuses. Its hooks
/// (`tests/schemathesis_hooks.py`) give the uploads bytes that decode and ids that match,
/// which a schema cannot say. Excluded: `positive_data_acceptance`, since a schema cannot say
/// "a field of view that is not denormal" or "width × height within the pixel limit", so
/// schema-valid requests may rightly get a 422; `use_after_free`, since `DELETE
/// /v1/jobs/{id}` cancels a job and its record stays to say so; the response-time check's
/// 10 s default, a timed assertion (a render shares two cores with the fuzzers beside it),
/// raised to the request timeout; and the event streams,
/// which stay open by design. The stateful phase follows the links from `submitJob`: the
/// daemon's access log shows job records, images and cancellations answered for real ids.
#[test]
fn the_api_conforms_to_its_openapi_document_under_schemathesis() {
    let schemathesis = tools_dir().join("bin/schemathesis");
    assert!(schemathesis.exists(), "{} is missing: run ./deploy/install-test-deps.sh", schemathesis.display());
    let log = std::env::temp_dir().join(format!("penumbra-schemathesis-{}.log", std::process::id()));
    let address = common::daemon::free_address();
    let mut command = common::daemon::serve_command(&address);
    command.args(["--no-warm-up", "--job-store", "memory"]).env("PENUMBRA_LOG", "info").stderr(std::fs::File::create(&log).unwrap());
    let daemon = common::daemon::Daemon::start(command, &address);
    let base = daemon.base.clone();
    let examples = std::env::var("PENUMBRA_SCHEMATHESIS_EXAMPLES").unwrap_or_else(|_| "25".into());
    let output = Command::new(&schemathesis)
        .arg("run")
        .arg(repo().join("api/openapi.json"))
        .args(["--url", &base, "--max-examples", &examples, "--checks", "all"])
        .args(["--exclude-checks", "positive_data_acceptance,use_after_free", "--max-response-time", "60"])
        .args(["--generation-deterministic", "--request-timeout", "60", "--exclude-path-regex", "/events$", "--no-color"])
        .env("SCHEMATHESIS_HOOKS", repo().join("tests/schemathesis_hooks.py"))
        .output()
        .unwrap();
    drop(daemon);
    let report = String::from_utf8_lossy(&output.stdout);
    let summary: Vec<&str> =
        report.lines().filter(|l| l.contains("generated") || l.contains("Tested:") || l.contains("API Links")).collect();
    eprintln!("schemathesis: {}", summary.join(" | "));
    assert!(output.status.success(), "schemathesis found failures:\n{report}\n{}", String::from_utf8_lossy(&output.stderr));
    assert!(!report.contains("Schema validation mismatch"), "the document allows what the server refuses:\n{report}");
    let access = std::fs::read_to_string(&log).unwrap();
    std::fs::remove_file(&log).ok();
    let answered = |route: &str, status: &str| {
        access
            .lines()
            .any(|l| l.contains("penumbra::access") && l.contains(&format!("route=\"{route}\"")) && l.contains(&format!("status={status}")))
    };
    assert!(answered("/v1/jobs/{id}", "200"), "the stateful phase never read a submitted job's record");
    assert!(answered("/v1/jobs/{id}", "202"), "the stateful phase never cancelled a submitted job");
}

/// A client generated from `api/openapi.json` by a real generator (`openapi-python-client`)
/// uses the document's names: it submits a job (`submit_job`, with an Idempotency-Key),
/// follows it (`get_job`), lists it (`list_jobs`) and downloads its image (`get_job_image`)
/// from the real daemon, with typed models (`Job`, `MethodPcss`, `ListJobsMethod`).
#[test]
fn a_client_generated_from_the_document_renders_a_job() {
    let generator = tools_dir().join("bin/openapi-python-client");
    assert!(generator.exists(), "{} is missing: run ./deploy/install-test-deps.sh", generator.display());
    let work = std::env::temp_dir().join(format!("penumbra-generated-client-{}", std::process::id()));
    std::fs::remove_dir_all(&work).ok();
    std::fs::create_dir_all(&work).unwrap();
    let generated = Command::new(&generator)
        .args(["generate", "--meta", "none", "--path"])
        .arg(repo().join("api/openapi.json"))
        .arg("--output-path")
        .arg(work.join("penumbra_client"))
        .current_dir(&work)
        .output()
        .unwrap();
    assert!(generated.status.success(), "generation failed:\n{}", String::from_utf8_lossy(&generated.stdout));
    let daemon = common::daemon::Daemon::spawn(&["--no-warm-up", "--job-store", "memory"]);
    let script = r#"
import sys, time
from penumbra_client import Client
from penumbra_client.api.jobs import submit_job, get_job, list_jobs, get_job_image
from penumbra_client.models import Job, ListJobsMethod, MethodPcss, Output

client = Client(base_url=sys.argv[1], raise_on_unexpected_status=True)
job = Job(scene={"builtin": "torus"}, method=MethodPcss(name="pcss", search_taps=6), output=Output(width=64, height=48))
accepted = submit_job.sync(client=client, body=job, idempotency_key="generated-client-1")
again = submit_job.sync(client=client, body=job, idempotency_key="generated-client-1")
assert accepted.id == again.id, (accepted, again)
for _ in range(600):
    record = get_job.sync(client=client, id=accepted.id)
    if record.status in ("succeeded", "failed", "cancelled"):
        break
    time.sleep(0.1)
assert record.status == "succeeded", record
assert record.image_sha256, record
page = list_jobs.sync(client=client, method=ListJobsMethod("pcss"), limit=10)
assert [j.id for j in page.jobs] == [accepted.id], page
# The generator leaves binary answers unparsed: the raw response carries the bytes.
raw = Client(base_url=sys.argv[1])
image = get_job_image.sync_detailed(client=raw, id=accepted.id)
assert image.status_code == 200 and image.content[1:4] == b"PNG", image.status_code
print("generated client:", accepted.id, len(image.content), "bytes")
"#;
    let run =
        Command::new(tools_dir().join("bin/python")).arg("-c").arg(script).arg(&daemon.base).env("PYTHONPATH", &work).output().unwrap();
    drop(daemon);
    std::fs::remove_dir_all(&work).ok();
    assert!(
        run.status.success(),
        "the generated client failed:\n{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
}

/// Load, bounded: `deploy/load.py` drives the real daemon on loopback with 16
/// clients mixing methods, sizes, uploads and async jobs; every answer is 200/201/202 or the
/// documented 429, the daemon exits cleanly, and its resident memory does not climb once
/// warm (the upload cache is kept small, so it is full early; warm is 10 s and 150 renders,
/// whichever comes later, for a machine this suite's other tests keep busy). The report and plot are kept in
/// `target/test-artifacts/load/` (figures for notes come from the 5-minute form; no timing is
/// asserted).
#[test]
fn sixteen_clients_get_only_documented_answers() {
    let python = tools_dir().join("bin/python");
    assert!(python.exists(), "{} is missing: run ./deploy/install-test-deps.sh", python.display());
    let out = repo().join("target/test-artifacts/load");
    let seconds = std::env::var("PENUMBRA_LOAD_SECS").unwrap_or_else(|_| "45".into());
    let output = Command::new(python)
        .arg(repo().join("deploy/load.py"))
        .args(["--binary", env!("CARGO_BIN_EXE_penumbra"), "--clients", "16", "--seconds", &seconds, "--warm-up-seconds", "10", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "load run failed:\n{text}\n{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("load.json")).unwrap()).unwrap();
    assert_eq!(report["unexpected"], 0, "{report}");
    assert!(report["renders_per_second"].as_f64() > Some(0.0));
    // Floors, not peaks, are compared (a render's buffers come and go). A leak of the order
    // of a frame (≥ 100 KiB per render, ≈ 150 renders between the quarters) would show; small
    // ones need the long form, whose plot shows the floor over minutes.
    let growth = report["rss_after_warm_up_bytes"]["floor_growth"].as_i64().unwrap();
    assert!(growth < 16 << 20, "resident memory floor grew {} MiB after warm-up: {report}", growth >> 20);
    assert!(out.join("load.png").exists());
}
