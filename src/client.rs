//! `penumbra submit`: the client scripts and tools use to render on a remote penumbra. It
//! uploads the job's local scenes and light images only when the server lacks them (`HEAD`,
//! then `PUT` under the SHA-256 it computed), submits the job asynchronously, follows its
//! server-sent events with a progress bar, honours `429 Retry-After`, retries connection
//! errors with exponential backoff, and downloads the result.

use std::path::{Path, PathBuf};
use std::time::Duration;

use futures_util::StreamExt;
use serde::Serialize;
use serde_json::Value;

use crate::upload_store::content_id;

/// The header that carries a job's scene id (or built-in name), so that a balancer in front
/// of several replicas can route every job of a scene to the replica that has it cached.
pub const SCENE_HEADER: &str = "x-penumbra-scene";

#[derive(Debug, Clone, clap::Args)]
pub struct SubmitOptions {
    /// The job (JSON, see api/examples/). `{"path": ...}` scenes and light images are read
    /// here, relative to the job file, and uploaded; the server never sees the path.
    pub job: PathBuf,
    /// The server's base URL.
    #[arg(long, env = "PENUMBRA_SERVER", default_value = "http://127.0.0.1:8080")]
    pub server: String,
    /// Where to write the image; `.exr` asks for EXR, anything else PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Attempts for each request on connection errors and 429/503 answers.
    #[arg(long, default_value_t = 8)]
    pub retries: u32,
    /// No progress bar (for scripts and logs).
    #[arg(long)]
    pub quiet: bool,
}

/// What a submission did.
#[derive(Debug, Clone, Serialize)]
pub struct SubmitReport {
    pub id: String,
    /// Content ids uploaded by this submission (empty when the server had everything).
    pub uploaded: Vec<String>,
    /// Content ids the server already held.
    pub reused: Vec<String>,
    /// The last progress event: steps done of all.
    pub done: u64,
    pub total: u64,
    pub output_bytes: u64,
    /// Requests repeated after a 429, a 503 or a connection error.
    pub retries: u32,
}

/// Reasons a submission fails, with what the server said.
#[derive(Debug, thiserror::Error)]
pub enum SubmitError {
    #[error("cannot read {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("the job file is not JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("{0}")]
    Job(String),
    #[error("the server answered {status}: {body}")]
    Server { status: u16, body: String },
    #[error("the job failed: {0}")]
    Failed(Value),
    #[error("cannot reach the server after {attempts} attempts: {last}")]
    Unreachable { attempts: u32, last: String },
    #[error("cannot write {path}: {source}")]
    Write { path: PathBuf, source: std::io::Error },
}

/// Submits the job and waits for its image. `progress(done, total)` is called on every event.
pub async fn submit(options: &SubmitOptions, progress: &(dyn Fn(u64, u64) + Sync)) -> Result<SubmitReport, SubmitError> {
    let text = std::fs::read(&options.job).map_err(|source| SubmitError::Read { path: options.job.clone(), source })?;
    let mut job: Value = serde_json::from_slice(&text)?;
    let base_dir = options.job.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut client = Client {
        http: reqwest::Client::new(),
        base: options.server.trim_end_matches('/').to_owned(),
        attempts: options.retries.max(1),
        retries: 0,
    };
    let mut report = SubmitReport { id: String::new(), uploaded: vec![], reused: vec![], done: 0, total: 0, output_bytes: 0, retries: 0 };

    // Local assets become content ids, uploaded only when the server lacks them.
    let assets = [("/scene", "scenes"), ("/light/image", "lights")];
    for (pointer, collection) in assets {
        let Some(path) = job.pointer(pointer).and_then(|a| a.get("path")).and_then(Value::as_str).map(str::to_owned) else { continue };
        let path = base_dir.join(path);
        let mut bytes = std::fs::read(&path).map_err(|source| SubmitError::Read { path: path.clone(), source })?;
        if collection == "scenes" {
            // An upload is self-contained (contract §3): a .gltf and its files go as one GLB.
            let folder = path.parent().unwrap_or(Path::new("."));
            bytes = crate::scene::gltf::pack(&bytes, folder, &crate::job::Limits::default(), "scene.path")
                .map_err(|e| SubmitError::Job(format!("cannot pack {} into a GLB: {}", path.display(), e.message)))?;
        }
        let id = content_id(&bytes);
        let url = format!("/v1/{collection}/{id}");
        if client.send(|http, base| http.head(format!("{base}{url}"))).await?.status() == reqwest::StatusCode::OK {
            report.reused.push(id.clone());
        } else {
            let response = client.send(|http, base| http.put(format!("{base}{url}")).body(bytes.clone())).await?;
            expect_success(response).await?;
            report.uploaded.push(id.clone());
        }
        // The path becomes the id; the rest of the reference (a scene's `floor`) stays.
        let reference = job.pointer_mut(pointer).and_then(Value::as_object_mut).expect("an object with a path: read above");
        reference.remove("path");
        reference.insert("id".into(), id.into());
    }
    if options.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")) {
        let output = job.as_object_mut().ok_or_else(|| SubmitError::Job("the job is not a JSON object".into()))?.entry("output");
        output.or_insert_with(|| serde_json::json!({}))["format"] = "exr".into();
    }
    let scene = routing_key(&job);

    let response = client.send(|http, base| http.post(format!("{base}/v1/jobs")).header(SCENE_HEADER, &scene).json(&job)).await?;
    let accepted: Value = expect_success(response).await?.json().await.map_err(|e| SubmitError::Job(e.to_string()))?;
    report.id = accepted["id"].as_str().ok_or_else(|| SubmitError::Job(format!("no id in the answer: {accepted}")))?.to_owned();

    // Follow the events to the end; a dropped stream (a replica going away) is reopened.
    let events = format!("/v1/jobs/{}/events", report.id);
    let final_event = loop {
        let response = client.send(|http, base| http.get(format!("{base}{events}")).header(SCENE_HEADER, &scene)).await?;
        let response = expect_success(response).await?;
        match follow_events(response, &mut report, progress).await {
            Some(event) => break event,
            None => client.backoff().await?,
        }
    };
    if final_event["status"] != "succeeded" {
        return Err(SubmitError::Failed(final_event["error"].clone()));
    }

    let image = format!("/v1/jobs/{}/image", report.id);
    let response = client.send(|http, base| http.get(format!("{base}{image}")).header(SCENE_HEADER, &scene)).await?;
    let bytes = expect_success(response).await?.bytes().await.map_err(|e| SubmitError::Job(e.to_string()))?;
    std::fs::write(&options.output, &bytes).map_err(|source| SubmitError::Write { path: options.output.clone(), source })?;
    report.output_bytes = bytes.len() as u64;
    report.retries = client.retries;
    Ok(report)
}

/// The scene a job renders, as the routing header carries it: an id, or `builtin:NAME`.
fn routing_key(job: &Value) -> String {
    let scene = &job["scene"];
    match (scene["id"].as_str(), scene["builtin"].as_str()) {
        (Some(id), _) => id.to_owned(),
        (None, Some(name)) => format!("builtin:{name}"),
        _ => String::new(),
    }
}

/// Reads server-sent events, reporting progress, until a final one (returned) or the end of
/// the stream without one (None).
async fn follow_events(response: reqwest::Response, report: &mut SubmitReport, progress: &(dyn Fn(u64, u64) + Sync)) -> Option<Value> {
    let mut stream = response.bytes_stream();
    let mut buffer = String::new();
    while let Some(Ok(chunk)) = stream.next().await {
        buffer.push_str(&String::from_utf8_lossy(&chunk));
        while let Some(end) = buffer.find("\n\n") {
            let block: String = buffer.drain(..end + 2).collect();
            let Some(data) = block.lines().find_map(|line| line.strip_prefix("data:")) else { continue };
            let Ok(event) = serde_json::from_str::<Value>(data.trim()) else { continue };
            report.done = event["done"].as_u64().unwrap_or(report.done);
            report.total = event["total"].as_u64().unwrap_or(report.total);
            progress(report.done, report.total);
            if matches!(event["status"].as_str(), Some("succeeded" | "failed" | "cancelled")) {
                return Some(event);
            }
        }
    }
    None
}

async fn expect_success(response: reqwest::Response) -> Result<reqwest::Response, SubmitError> {
    if response.status().is_success() {
        return Ok(response);
    }
    let status = response.status().as_u16();
    let body = response.text().await.unwrap_or_default();
    Err(SubmitError::Server { status, body })
}

/// An HTTP client that repeats a request on connection errors (exponential backoff from
/// 100 ms, capped at 5 s), on 429 (after `Retry-After`) and on 503, up to `attempts` times.
struct Client {
    http: reqwest::Client,
    base: String,
    attempts: u32,
    retries: u32,
}

impl Client {
    async fn send(
        &mut self,
        request: impl Fn(&reqwest::Client, &str) -> reqwest::RequestBuilder,
    ) -> Result<reqwest::Response, SubmitError> {
        let mut last = String::new();
        for attempt in 0..self.attempts {
            if attempt > 0 {
                self.retries += 1;
            }
            match request(&self.http, &self.base).send().await {
                Ok(response) if response.status() == reqwest::StatusCode::TOO_MANY_REQUESTS => {
                    let wait = response
                        .headers()
                        .get(reqwest::header::RETRY_AFTER)
                        .and_then(|v| v.to_str().ok())
                        .and_then(|v| v.parse::<f64>().ok())
                        .unwrap_or(1.0);
                    last = "429 queue_full".into();
                    tokio::time::sleep(Duration::from_secs_f64(wait.clamp(0.0, 60.0))).await;
                }
                Ok(response) if response.status() == reqwest::StatusCode::SERVICE_UNAVAILABLE => {
                    last = "503".into();
                    tokio::time::sleep(backoff(attempt)).await;
                }
                Ok(response) => return Ok(response),
                Err(error) => {
                    last = error.to_string();
                    tokio::time::sleep(backoff(attempt)).await;
                }
            }
        }
        Err(SubmitError::Unreachable { attempts: self.attempts, last })
    }

    /// Waits before reopening a dropped stream; fails once the attempts are spent.
    async fn backoff(&mut self) -> Result<(), SubmitError> {
        self.retries += 1;
        if self.retries >= self.attempts * 4 {
            return Err(SubmitError::Unreachable { attempts: self.retries, last: "the event stream kept ending early".into() });
        }
        tokio::time::sleep(backoff(self.retries.min(6))).await;
        Ok(())
    }
}

fn backoff(attempt: u32) -> Duration {
    Duration::from_millis(100u64 << attempt.min(6)).min(Duration::from_secs(5))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn routing_keys_name_the_scene() {
        assert_eq!(routing_key(&serde_json::json!({"scene": {"id": "ab12"}})), "ab12");
        assert_eq!(routing_key(&serde_json::json!({"scene": {"builtin": "torus"}})), "builtin:torus");
        assert_eq!(routing_key(&serde_json::json!({})), "");
    }

    #[test]
    fn backoff_grows_and_is_capped() {
        assert!(backoff(0) < backoff(1) && backoff(1) < backoff(3));
        assert_eq!(backoff(30), Duration::from_secs(5));
    }
}
