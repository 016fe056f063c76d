//! `penumbra jobs`: the submitted jobs of a remote penumbra — `list` (newest first, filtered,
//! every page followed up to `--limit`), `show ID`, `cancel ID`, `wait ID` — as a table for
//! people, or JSON (`--json`) for scripts.

use std::path::PathBuf;

use serde_json::{json, Value};

use super::submit::{download, follow, job_path, succeeded};
use super::{Client, ClientError, ConnectOptions, SubmitReport};

#[derive(Debug, Clone, clap::Args)]
pub struct JobsCommand {
    #[command(subcommand)]
    pub action: JobsAction,
    #[command(flatten)]
    pub connect: ConnectOptions,
    /// JSON on stdout instead of a table.
    #[arg(long, global = true)]
    pub json: bool,
}

#[derive(Debug, Clone, clap::Subcommand)]
pub enum JobsAction {
    /// The newest jobs first.
    List {
        /// Only jobs in this state: queued, running, succeeded, failed, cancelled.
        #[arg(long)]
        status: Option<String>,
        /// Only jobs of this method.
        #[arg(long)]
        method: Option<String>,
        /// Most jobs shown (pages of up to 500 are followed to reach it).
        #[arg(long, default_value_t = 50)]
        limit: usize,
    },
    /// One job's record.
    Show { id: String },
    /// Cancels a job that has not finished.
    Cancel { id: String },
    /// Waits until a job finishes; exits non-zero unless it succeeded.
    Wait {
        id: String,
        /// Also download its image here.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
}

/// Runs a `penumbra jobs` action; what it prints goes to stdout.
pub async fn run_jobs(command: &JobsCommand) -> Result<String, ClientError> {
    let mut client = Client::new(&command.connect)?;
    match &command.action {
        JobsAction::List { status, method, limit } => {
            let jobs = list(&mut client, status.as_deref(), method.as_deref(), *limit).await?;
            Ok(if command.json { serde_json::to_string_pretty(&jobs)? } else { table(&jobs, crate::job::submission::unix_ms()) })
        }
        JobsAction::Show { id } => {
            let url = job_path(id);
            let job = client.json(|http, base| http.get(format!("{base}{url}"))).await?;
            Ok(if command.json { serde_json::to_string_pretty(&job)? } else { summary(&job) })
        }
        JobsAction::Cancel { id } => {
            let url = job_path(id);
            let job = client.json(|http, base| http.delete(format!("{base}{url}"))).await?;
            Ok(if command.json {
                serde_json::to_string_pretty(&job)?
            } else {
                format!("cancelling {id}: {}", job["status"].as_str().unwrap_or("?"))
            })
        }
        JobsAction::Wait { id, output } => {
            follow(&mut client, &mut SubmitReport::new(id), None, &|_, _| {}, None).await?;
            let url = job_path(id);
            let job = succeeded(client.json(|http, base| http.get(format!("{base}{url}"))).await?)?;
            if let Some(path) = output {
                download(&mut client, id, None, path).await?;
            }
            Ok(if command.json { serde_json::to_string_pretty(&job)? } else { summary(&job) })
        }
    }
}

/// Pages of `GET /v1/jobs` followed until `limit` jobs or the last page.
async fn list(client: &mut Client, status: Option<&str>, method: Option<&str>, limit: usize) -> Result<Vec<Value>, ClientError> {
    let mut jobs = Vec::new();
    let mut cursor: Option<String> = None;
    while jobs.len() < limit {
        let mut query = vec![("limit", (limit - jobs.len()).min(500).to_string())];
        query.extend(status.map(|s| ("status", s.to_owned())));
        query.extend(method.map(|m| ("method", m.to_owned())));
        query.extend(cursor.clone().map(|c| ("cursor", c)));
        let page = client.json(|http, base| http.get(format!("{base}/v1/jobs")).query(&query)).await?;
        jobs.extend(page["jobs"].as_array().cloned().unwrap_or_default());
        match page["next_cursor"].as_str() {
            Some(next) => cursor = Some(next.to_owned()),
            None => break,
        }
    }
    Ok(jobs)
}

/// Asks the server to cancel a job (Ctrl-C during `submit`): what became of it, in words.
pub(super) async fn cancel_quietly(connect: &ConnectOptions, id: &str) -> String {
    let mut connect = connect.clone();
    connect.retries = connect.retries.min(3);
    let Ok(mut client) = Client::new(&connect) else { return "was left running (no connection to cancel it)".into() };
    let url = job_path(id);
    match client.json(|http, base| http.delete(format!("{base}{url}"))).await {
        Ok(_) => "was cancelled on the server".into(),
        Err(ClientError::Server { status: 409, .. }) => "had already finished".into(),
        Err(error) => format!("may still run on the server (cancelling failed: {error})"),
    }
}

/// Listed jobs as a table: id, status, method, age.
fn table(jobs: &[Value], now_ms: u64) -> String {
    let mut lines = vec![format!("{:<32}  {:<9}  {:<9}  {:>6}", "ID", "STATUS", "METHOD", "AGE")];
    for job in jobs {
        let age = now_ms.saturating_sub(job["submitted_unix_ms"].as_u64().unwrap_or(now_ms)) / 1000;
        lines.push(format!(
            "{:<32}  {:<9}  {:<9}  {:>6}",
            job["id"].as_str().unwrap_or("?"),
            job["status"].as_str().unwrap_or("?"),
            job["method"].as_str().unwrap_or("?"),
            human_age(age)
        ));
    }
    if jobs.is_empty() {
        lines.push("(no jobs)".into());
    }
    lines.join("\n")
}

/// Seconds as the largest unit that fits: `42s`, `7m`, `3h`, `2d`.
fn human_age(seconds: u64) -> String {
    match seconds {
        s if s < 60 => format!("{s}s"),
        s if s < 3600 => format!("{}m", s / 60),
        s if s < 86400 => format!("{}h", s / 3600),
        s => format!("{}d", s / 86400),
    }
}

/// One job's record in a few lines.
fn summary(job: &Value) -> String {
    let mut lines =
        vec![format!("id      {}", job["id"].as_str().unwrap_or("?")), format!("status  {}", job["status"].as_str().unwrap_or("?"))];
    if let Some(method) = job["method"].as_str() {
        lines.push(format!("method  {method}"));
    }
    if let Some(total) = job["timings"]["total_ms"].as_f64() {
        lines.push(format!("render  {total:.1} ms"));
    }
    if let Some(image) = job["image"].as_str() {
        lines.push(format!("image   {image} ({} bytes)", job["bytes"]));
    }
    if !job["error"].is_null() {
        lines.push(format!("error   {}", json!(job["error"])));
    }
    lines.join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_listing_reads_as_a_table() {
        let jobs = [json!({"id": "0123456789abcdef0123456789abcdef", "status": "succeeded", "method": "pcss", "submitted_unix_ms": 1_000})];
        let text = table(&jobs, 7_000 + 3_600_000);
        assert!(text.lines().next().unwrap().starts_with("ID"));
        assert!(text.contains("0123456789abcdef0123456789abcdef  succeeded  pcss") && text.trim_end().ends_with("1h"), "{text}");
        assert_eq!(table(&[], 0).lines().nth(1), Some("(no jobs)"));
        assert_eq!((human_age(59), human_age(60), human_age(86400 * 3)), ("59s".into(), "1m".into(), "3d".into()));
        assert_eq!(super::super::submit::job_path("../x"), "/v1/jobs/%2E%2E%2Fx");
    }
}
