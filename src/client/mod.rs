//! The client tools use to talk to a remote penumbra (`penumbra submit`, `penumbra jobs`):
//! one connection setup — the server's URL (`http://` or `https://` through rustls, with the
//! system's roots and an optional private CA), a bearer token from a file or the environment
//! (sent as a sensitive header, never printed) — and one way to send a request, retried on
//! connection errors and on 429, 503 and 507 with jittered exponential backoff that honours
//! `Retry-After`.

mod jobs;
mod submit;

use std::path::{Path, PathBuf};
use std::time::Duration;

use reqwest::header::{HeaderMap, HeaderValue, AUTHORIZATION, RETRY_AFTER};
use reqwest::StatusCode;

pub use jobs::{run_jobs, JobsCommand};
use submit::expect_success;
pub use submit::{estimate, estimate_table, submit, SubmitOptions, SubmitReport, SCENE_HEADER};

/// Where the server is and how to reach it: shared by every subcommand that talks to one.
#[derive(Debug, Clone, clap::Args)]
pub struct ConnectOptions {
    /// The server's base URL (`http://` or `https://`).
    #[arg(long, global = true, env = "PENUMBRA_SERVER", default_value = "http://127.0.0.1:8080")]
    pub server: String,
    /// A file whose first line is the bearer token (for a daemon started with
    /// `--auth-token-file`); `PENUMBRA_TOKEN` gives the token itself instead.
    #[arg(long, global = true, env = "PENUMBRA_TOKEN_FILE")]
    pub token_file: Option<PathBuf>,
    /// A PEM file of CA certificates trusted besides the system's (a private CA in front of
    /// the daemon).
    #[arg(long, global = true, env = "PENUMBRA_CA_CERT")]
    pub ca_cert: Option<PathBuf>,
    /// Attempts for each request on connection errors and 429/503/507 answers.
    #[arg(long, global = true, default_value_t = 8)]
    pub retries: u32,
}

/// Why a call to the server failed, in one line a person can act on.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot read {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{0}")]
    Setup(String),
    #[error("the job file is not JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("{0}")]
    Job(String),
    #[error("the server refused the token (401 unauthorized): give a valid one with --token-file or PENUMBRA_TOKEN")]
    Unauthorized,
    #[error("the server answered {status}: {body}")]
    Server { status: u16, body: String },
    #[error("the job {status}: {error}")]
    Failed { status: String, error: serde_json::Value },
    #[error("cannot reach the server after {attempts} attempts: {last}")]
    Unreachable { attempts: u32, last: String },
    #[error("interrupted: job {id} {outcome}")]
    Interrupted { id: String, outcome: String },
    #[error("cannot write {path}: {source}")]
    Write { path: PathBuf, source: std::io::Error },
}

/// A connection to one server: the HTTP client (TLS, token) and its retry policy. Counts the
/// requests it repeated.
pub struct Client {
    http: reqwest::Client,
    base: String,
    attempts: u32,
    pub retries: u32,
}

impl Client {
    pub fn new(options: &ConnectOptions) -> Result<Self, ClientError> {
        let base = options.server.trim_end_matches('/').to_owned();
        if !(base.starts_with("http://") || base.starts_with("https://")) {
            return Err(ClientError::Setup(format!("--server `{base}` is not an http:// or https:// URL")));
        }
        let mut headers = HeaderMap::new();
        if let Some(token) = token(options.token_file.as_deref())? {
            let mut value = HeaderValue::from_str(&format!("Bearer {token}"))
                .map_err(|_| ClientError::Setup("the token holds characters a header cannot carry".into()))?;
            // Kept out of reqwest's debug output and HTTP/2 header tables.
            value.set_sensitive(true);
            headers.insert(AUTHORIZATION, value);
        }
        let mut builder = reqwest::Client::builder().default_headers(headers).connect_timeout(Duration::from_secs(10));
        if let Some(path) = &options.ca_cert {
            let pem = std::fs::read(path).map_err(|source| ClientError::Read { path: path.clone(), source })?;
            let certificates = reqwest::Certificate::from_pem_bundle(&pem)
                .map_err(|e| ClientError::Setup(format!("{} is not a PEM certificate bundle: {e}", path.display())))?;
            if certificates.is_empty() {
                return Err(ClientError::Setup(format!("{} holds no PEM certificate", path.display())));
            }
            for certificate in certificates {
                builder = builder.add_root_certificate(certificate);
            }
        }
        let http = builder.build().map_err(|e| ClientError::Setup(format!("cannot set up the HTTP client: {}", chain(&e))))?;
        Ok(Self { http, base, attempts: options.retries.max(1), retries: 0 })
    }

    /// Sends the request `build` makes (again on each attempt) until an answer that is not
    /// worth retrying: a connection error, 429, 503 or 507 waits and tries again, up to the
    /// attempts; 401 is `Unauthorized`.
    pub async fn send(
        &mut self,
        build: impl Fn(&reqwest::Client, &str) -> reqwest::RequestBuilder,
    ) -> Result<reqwest::Response, ClientError> {
        let mut last = String::new();
        for attempt in 0..self.attempts {
            if attempt > 0 {
                self.retries += 1;
            }
            let wait = match build(&self.http, &self.base).send().await {
                Ok(response) if response.status() == StatusCode::UNAUTHORIZED => return Err(ClientError::Unauthorized),
                Ok(response) if retried(response.status()) => {
                    last = response.status().to_string();
                    retry_after(response.headers()).unwrap_or_else(|| backoff(attempt))
                }
                Ok(response) => return Ok(response),
                Err(error) => {
                    last = chain(&error);
                    // A certificate the client does not trust will not become trusted.
                    if last.contains("certificate") {
                        return Err(ClientError::Unreachable { attempts: attempt + 1, last });
                    }
                    backoff(attempt)
                }
            };
            if attempt + 1 < self.attempts {
                tokio::time::sleep(wait).await;
            }
        }
        Err(ClientError::Unreachable { attempts: self.attempts, last })
    }

    /// `send`, then the answer as JSON when it is a success; the server's error otherwise.
    pub async fn json(
        &mut self,
        build: impl Fn(&reqwest::Client, &str) -> reqwest::RequestBuilder,
    ) -> Result<serde_json::Value, ClientError> {
        let response = expect_success(self.send(build).await?).await?;
        response.json().await.map_err(|e| ClientError::Job(format!("the answer is not JSON: {}", chain(&e))))
    }

    /// Waits before reopening a dropped stream; fails once the attempts are spent.
    pub async fn backoff(&mut self) -> Result<(), ClientError> {
        self.retries += 1;
        if self.retries >= self.attempts * 4 {
            return Err(ClientError::Unreachable { attempts: self.retries, last: "the event stream kept ending early".into() });
        }
        tokio::time::sleep(backoff(self.retries.min(6))).await;
        Ok(())
    }
}

/// Answers a retry may cure: the queue full (429), the service or its store away for a
/// moment (503), the store's disk full until old results go (507).
fn retried(status: StatusCode) -> bool {
    matches!(status, StatusCode::TOO_MANY_REQUESTS | StatusCode::SERVICE_UNAVAILABLE | StatusCode::INSUFFICIENT_STORAGE)
}

/// The wait a `Retry-After` of seconds asks for, at most a minute.
fn retry_after(headers: &HeaderMap) -> Option<Duration> {
    let seconds = headers.get(RETRY_AFTER)?.to_str().ok()?.trim().parse::<f64>().ok()?;
    (seconds.is_finite() && seconds >= 0.0).then(|| Duration::from_secs_f64(seconds.min(60.0)))
}

/// The wait before attempt `attempt + 1`: exponential from 100 ms, capped at 5 s, with full
/// jitter over its upper half, so that clients that failed together do not return together.
fn backoff(attempt: u32) -> Duration {
    let ceiling = Duration::from_millis(100u64 << attempt.min(6)).min(Duration::from_secs(5));
    let unit = (uuid::Uuid::new_v4().as_u128() % 1_000_000) as f64 / 1_000_000.0;
    ceiling.mul_f64(0.5 + 0.5 * unit)
}

/// The token: `PENUMBRA_TOKEN`, else the first line of `--token-file` that is neither blank nor
/// a `#` comment (the daemon's token file format).
fn token(file: Option<&Path>) -> Result<Option<String>, ClientError> {
    if let Some(token) = std::env::var("PENUMBRA_TOKEN").ok().map(|t| t.trim().to_owned()).filter(|t| !t.is_empty()) {
        return Ok(Some(token));
    }
    let Some(path) = file else { return Ok(None) };
    let text = std::fs::read_to_string(path).map_err(|source| ClientError::Read { path: path.to_owned(), source })?;
    let token = text.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#'));
    token.map(|t| Some(t.to_owned())).ok_or_else(|| ClientError::Setup(format!("the token file {} holds no token", path.display())))
}

/// An error with its causes, in one line (reqwest's own text leaves out the TLS reason).
fn chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let cause_text = cause.to_string();
        if !text.contains(&cause_text) {
            text = format!("{text}: {cause_text}");
        }
        source = cause.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_grows_is_capped_and_jittered() {
        for attempt in 0..10 {
            let ceiling = Duration::from_millis(100u64 << attempt.min(6)).min(Duration::from_secs(5));
            let wait = backoff(attempt);
            assert!(wait >= ceiling / 2 && wait <= ceiling, "attempt {attempt}: {wait:?} of {ceiling:?}");
        }
        let draws: std::collections::HashSet<Duration> = (0..20).map(|_| backoff(3)).collect();
        assert!(draws.len() > 1, "jittered");
    }

    #[test]
    fn retry_after_is_read_in_seconds_and_bounded() {
        let headers = |v: &str| HeaderMap::from_iter([(RETRY_AFTER, HeaderValue::from_str(v).unwrap())]);
        assert_eq!(retry_after(&headers("2")), Some(Duration::from_secs(2)));
        assert_eq!(retry_after(&headers("0.5")), Some(Duration::from_millis(500)));
        assert_eq!(retry_after(&headers("86400")), Some(Duration::from_secs(60)));
        assert_eq!(retry_after(&headers("-1")), None);
        assert_eq!(retry_after(&headers("Wed, 21 Oct 2015 07:28:00 GMT")), None);
        assert!(retried(StatusCode::INSUFFICIENT_STORAGE) && !retried(StatusCode::UNPROCESSABLE_ENTITY));
    }
}
