//! `penumbra submit`: a job rendered on a remote penumbra. It uploads the job's local scenes
//! and light images only when the server lacks them (`HEAD`, then `PUT` under the SHA-256 it
//! computed), submits the job under a fresh `Idempotency-Key` (so that its own retries never
//! make a second job), follows its server-sent events with a progress bar, and downloads the
//! result. Ctrl-C cancels the remote job (`DELETE`) unless `--detach`.

use std::path::{Path, PathBuf};

use futures_util::StreamExt;
use serde::Serialize;
use serde_json::Value;

use super::{Client, ClientError, ConnectOptions};
use crate::upload_store::content_id;

/// The header that carries a job's scene id (or built-in name), so that a balancer in front
/// of several replicas can route every job of a scene to the replica that has it cached.
pub const SCENE_HEADER: &str = "x-penumbra-scene";

#[derive(Debug, Clone, clap::Args)]
pub struct SubmitOptions {
    /// The job (JSON, see api/examples/). `{"path": ...}` scenes and light images are read
    /// here, relative to the job file, and uploaded; the server never sees the path.
    pub job: PathBuf,
    #[command(flatten)]
    pub connect: ConnectOptions,
    /// Where to write the image; `.exr` asks for EXR, anything else PNG.
    #[arg(short, long, required_unless_present_any = ["detach", "estimate"])]
    pub output: Option<PathBuf>,
    /// Render nothing: print what the job is predicted to cost and how far from the truth on
    /// the daemon's device (`POST /v1/estimate`; for `auto`, the method it would choose).
    #[arg(long, conflicts_with = "detach")]
    pub estimate: bool,
    /// Return once the job is accepted (its id on stdout; `penumbra jobs wait ID` later), and
    /// never cancel it.
    #[arg(long)]
    pub detach: bool,
    /// No progress bar (for scripts and logs).
    #[arg(long)]
    pub quiet: bool,
    /// A progressive job (contract §5): write each round's image over the output as it comes.
    /// The job's `progressive` budget is the job file's, or `--max-error` / `--max-ms`.
    #[arg(long, conflicts_with_all = ["detach", "estimate"], requires = "output")]
    pub progressive: bool,
    /// With `--progressive`: stop refining once the estimated penumbra error is at most this.
    #[arg(long, requires = "progressive")]
    pub max_error: Option<f64>,
    /// With `--progressive`: start no round that would end past this many milliseconds.
    #[arg(long, requires = "progressive")]
    pub max_ms: Option<f64>,
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
    /// Requests repeated after a 429, 503 or 507 or a connection error.
    pub retries: u32,
    /// A progressive job's rounds as its events announced them, each written over the output.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub rounds: Vec<Value>,
}

impl SubmitReport {
    /// Nothing done yet for job `id` (empty before it is accepted).
    pub(super) fn new(id: &str) -> Self {
        Self { id: id.to_owned(), uploaded: vec![], reused: vec![], done: 0, total: 0, output_bytes: 0, retries: 0, rounds: vec![] }
    }
}

/// Submits the job and waits for its image (or, with `--detach`, for its acceptance).
/// `progress(done, total)` is called on every event. Ctrl-C after the job was accepted cancels
/// it on the server unless `--detach`.
pub async fn submit(options: &SubmitOptions, progress: &(dyn Fn(u64, u64) + Sync)) -> Result<SubmitReport, ClientError> {
    let mut client = Client::new(&options.connect)?;
    let mut report = SubmitReport::new("");
    let (job, scene) = prepare(options, &mut client, &mut report).await?;

    // One key for every attempt of this submission: a retry after a lost answer gets the job
    // the first attempt created.
    let key = uuid::Uuid::new_v4().to_string();
    let submitted = |http: &reqwest::Client, base: &str| {
        http.post(format!("{base}/v1/jobs")).header(SCENE_HEADER, &scene).header("idempotency-key", &key).json(&job)
    };
    let accepted = client.json(submitted).await?;
    report.id = accepted["id"].as_str().ok_or_else(|| ClientError::Job(format!("no id in the answer: {accepted}")))?.to_owned();
    if options.detach {
        report.retries = client.retries;
        return Ok(report);
    }
    let output = options.output.clone().expect("clap requires -o without --detach");
    let finished = tokio::select! {
        finished = follow_and_fetch(&mut client, &mut report, &scene, &output, progress) => finished,
        _ = tokio::signal::ctrl_c() => {
            let outcome = super::jobs::cancel_quietly(&options.connect, &report.id).await;
            return Err(ClientError::Interrupted { id: report.id.clone(), outcome });
        }
    };
    finished?;
    report.retries = client.retries;
    Ok(report)
}

/// `penumbra submit --estimate`: the job prepared as for a submission (its files uploaded
/// where the server lacks them) and estimated, not rendered: the server's answer.
pub async fn estimate(options: &SubmitOptions) -> Result<Value, ClientError> {
    let mut client = Client::new(&options.connect)?;
    let (job, scene) = prepare(options, &mut client, &mut SubmitReport::new("")).await?;
    client.json(|http, base| http.post(format!("{base}/v1/estimate")).header(SCENE_HEADER, &scene).json(&job)).await
}

/// An estimate as people read it: each candidate's predicted time and error, the job's own
/// or `auto`'s choice marked, and why a budget cannot be met.
pub fn estimate_table(estimate: &Value) -> String {
    let chosen = estimate["auto"]["label"].as_str().or(estimate["job"]["label"].as_str()).unwrap_or_default();
    let model = &estimate["model"];
    let mut out = format!(
        "predicted on {} by the {} model (status {})\n{:<24} {:>10} {:>10}\n",
        model["adapter"].as_str().unwrap_or("?"),
        model["source"].as_str().unwrap_or("?"),
        model["status"].as_str().unwrap_or("?"),
        "method",
        "ms",
        "error"
    );
    for p in estimate["predictions"].as_array().into_iter().flatten() {
        let label = p["label"].as_str().unwrap_or_default();
        let mark = if label == chosen { " <" } else { "" };
        out.push_str(&format!(
            "{label:<24} {:>10.0} {:>10.4}{mark}\n",
            p["ms"].as_f64().unwrap_or(f64::NAN),
            p["error"].as_f64().unwrap_or(f64::NAN)
        ));
    }
    if let Some(message) = estimate["unmet"]["message"].as_str() {
        out.push_str(&format!("{}: {message}\n", estimate["unmet"]["field"].as_str().unwrap_or("budget")));
    }
    out
}

/// The job file read, its local files uploaded where the server lacks them (the paths become
/// content ids), its format set by the output's extension; with the routing key of its scene.
async fn prepare(options: &SubmitOptions, client: &mut Client, report: &mut SubmitReport) -> Result<(Value, String), ClientError> {
    let text = std::fs::read(&options.job).map_err(|source| ClientError::Read { path: options.job.clone(), source })?;
    let mut job: Value = serde_json::from_slice(&text)?;
    let base_dir = options.job.parent().map(Path::to_path_buf).unwrap_or_default();

    // Local assets become content ids, uploaded only when the server lacks them.
    let assets = [("/scene", "scenes"), ("/light/image", "lights")];
    for (pointer, collection) in assets {
        let Some(path) = job.pointer(pointer).and_then(|a| a.get("path")).and_then(Value::as_str).map(str::to_owned) else { continue };
        let path = base_dir.join(path);
        let mut bytes = std::fs::read(&path).map_err(|source| ClientError::Read { path: path.clone(), source })?;
        if collection == "scenes" {
            // An upload is self-contained (contract §3): a .gltf and its files go as one GLB.
            let folder = path.parent().unwrap_or(Path::new("."));
            bytes = crate::scene::gltf::pack(&bytes, folder, &crate::job::Limits::default(), "scene.path")
                .map_err(|e| ClientError::Job(format!("cannot pack {} into a GLB: {}", path.display(), e.message)))?;
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
    if options.output.as_ref().and_then(|o| o.extension()).is_some_and(|e| e.eq_ignore_ascii_case("exr")) {
        let output = job.as_object_mut().ok_or_else(|| ClientError::Job("the job is not a JSON object".into()))?.entry("output");
        output.or_insert_with(|| serde_json::json!({}))["format"] = "exr".into();
    }
    if options.progressive {
        let object = job.as_object_mut().ok_or_else(|| ClientError::Job("the job is not a JSON object".into()))?;
        let budget = object.entry("progressive").or_insert_with(|| serde_json::json!({}));
        for (key, value) in [("max_error", options.max_error), ("max_ms", options.max_ms)] {
            if let Some(value) = value {
                budget[key] = value.into();
            }
        }
    }
    let scene = routing_key(&job);
    Ok((job, scene))
}

/// Follows the job's events to the end, then downloads the image to `output`.
async fn follow_and_fetch(
    client: &mut Client,
    report: &mut SubmitReport,
    scene: &str,
    output: &Path,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(), ClientError> {
    let id = report.id.clone();
    succeeded(follow(client, report, Some(scene), progress, Some(output)).await?)?;
    report.output_bytes = download(client, &id, Some(scene), output).await?;
    Ok(())
}

/// Follows job `report.id`'s events to its final one, reporting progress; a dropped stream (a
/// replica going away) is reopened. `scene` routes the requests (`SCENE_HEADER`). A
/// progressive job's rounds are written over `rounds_to` as they come.
pub(super) async fn follow(
    client: &mut Client,
    report: &mut SubmitReport,
    scene: Option<&str>,
    progress: &(dyn Fn(u64, u64) + Sync),
    rounds_to: Option<&Path>,
) -> Result<Value, ClientError> {
    let events = format!("{}/events", job_path(&report.id));
    loop {
        let response = expect_success(client.send(|http, base| routed(http.get(format!("{base}{events}")), scene)).await?).await?;
        match follow_events(response, report, progress, rounds_to.map(|path| (&mut *client, scene, path))).await {
            Some(event) => return Ok(event),
            None => client.backoff().await?,
        }
    }
}

/// A final event or record that says `succeeded`, else the job's failure.
pub(super) fn succeeded(job: Value) -> Result<Value, ClientError> {
    if job["status"] == "succeeded" {
        return Ok(job);
    }
    let status = job["status"].as_str().unwrap_or("failed").to_owned();
    Err(ClientError::Failed { status, error: job["error"].clone() })
}

/// Downloads job `id`'s image to `output`: its length.
pub(super) async fn download(client: &mut Client, id: &str, scene: Option<&str>, output: &Path) -> Result<u64, ClientError> {
    download_to(client, &format!("{}/image", job_path(id)), scene, output).await
}

/// Downloads the image at `url` (a path on the server) over `output`, whole or not at all (a
/// viewer watching the file never reads half an image): its length.
async fn download_to(client: &mut Client, url: &str, scene: Option<&str>, output: &Path) -> Result<u64, ClientError> {
    let response = client.send(|http, base| routed(http.get(format!("{base}{url}")), scene)).await?;
    let bytes = expect_success(response).await?.bytes().await.map_err(|e| ClientError::Job(e.to_string()))?;
    let mut partial = output.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    std::fs::write(&partial, &bytes).map_err(|source| ClientError::Write { path: partial.clone(), source })?;
    std::fs::rename(&partial, output).map_err(|source| ClientError::Write { path: output.to_owned(), source })?;
    Ok(bytes.len() as u64)
}

/// A job's record, `/v1/jobs/ID`: ids are hex, but a typed one is escaped rather than trusted.
pub(super) fn job_path(id: &str) -> String {
    format!("/v1/jobs/{}", percent_encoding::utf8_percent_encode(id, percent_encoding::NON_ALPHANUMERIC))
}

/// `request` with the routing header, when there is a scene to route by.
fn routed(request: reqwest::RequestBuilder, scene: Option<&str>) -> reqwest::RequestBuilder {
    match scene {
        Some(scene) => request.header(SCENE_HEADER, scene),
        None => request,
    }
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
/// the stream without one (None). With `rounds`, each new round of a progressive job is
/// downloaded over its path.
pub(super) async fn follow_events(
    response: reqwest::Response,
    report: &mut SubmitReport,
    progress: &(dyn Fn(u64, u64) + Sync),
    mut rounds: Option<(&mut Client, Option<&str>, &Path)>,
) -> Option<Value> {
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
            let round = &event["round"];
            let new_round = round.is_object() && report.rounds.last().is_none_or(|last| last["round"] != round["round"]);
            if let (true, Some((client, scene, path))) = (new_round, rounds.as_mut()) {
                report.rounds.push(round.clone());
                // A round the job has moved past may be gone: its last is the job's image.
                if let Some(image) = round["image"].as_str() {
                    let _ = download_to(client, image, *scene, path).await;
                }
            }
            if matches!(event["status"].as_str(), Some("succeeded" | "failed" | "cancelled")) {
                return Some(event);
            }
        }
    }
    None
}

pub(super) async fn expect_success(response: reqwest::Response) -> Result<reqwest::Response, ClientError> {
    if response.status().is_success() {
        return Ok(response);
    }
    let status = response.status().as_u16();
    let body = response.text().await.unwrap_or_default();
    Err(ClientError::Server { status, body })
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
}
