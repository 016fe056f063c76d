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

/// API conformance: `schemathesis` drives every operation of `api/openapi.json`
/// against the real daemon — examples, coverage, fuzzed and stateful sequences — and checks
/// that nothing answers 5xx and every response matches the document (status, content type,
/// headers, schema). Excluded: `positive_data_acceptance`, since a schema cannot say "a glTF
/// that decodes" or "a field of view that is not denormal", so schema-valid requests may
/// rightly get a 422; and the event streams, which stay open by design.
#[test]
fn the_api_conforms_to_its_openapi_document_under_schemathesis() {
    let schemathesis = tools_dir().join("bin/schemathesis");
    assert!(schemathesis.exists(), "{} is missing: run ./deploy/install-test-deps.sh", schemathesis.display());
    let daemon = common::daemon::Daemon::spawn(&["--no-warm-up", "--job-store", "memory"]);
    let base = daemon.base.clone();
    let examples = std::env::var("PENUMBRA_SCHEMATHESIS_EXAMPLES").unwrap_or_else(|_| "25".into());
    let output = Command::new(&schemathesis)
        .arg("run")
        .arg(repo().join("api/openapi.json"))
        .args(["--url", &base, "--max-examples", &examples, "--checks", "all", "--exclude-checks", "positive_data_acceptance"])
        .args(["--generation-deterministic", "--request-timeout", "60", "--exclude-path-regex", "/events$", "--no-color"])
        .env("SCHEMATHESIS_HOOKS", "")
        .output()
        .unwrap();
    drop(daemon);
    let report = String::from_utf8_lossy(&output.stdout);
    let summary: Vec<&str> =
        report.lines().filter(|l| l.contains("generated") || l.contains("Tested:") || l.contains("Selected:")).collect();
    eprintln!("schemathesis: {}", summary.join(" | "));
    assert!(output.status.success(), "schemathesis found failures:\n{report}\n{}", String::from_utf8_lossy(&output.stderr));
}

/// Load, bounded: `deploy/load.py` drives the real daemon on loopback with 16
/// clients mixing methods, sizes, uploads and async jobs; every answer is 200/201/202 or the
/// documented 429, the daemon exits cleanly, and its resident memory does not climb once
/// warm (the upload cache is kept small, so it is full early). The report and plot are kept in
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
