//! What comes with a submitted job besides the job (contract §3 "Submitting"): its
//! idempotency key and the fingerprint of its body, and how submitted jobs are listed — the
//! filters, the opaque cursor of a page, and the summary each listed job gets.

use base64::Engine as _;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::JobStatus;
use crate::error::{ErrorCode, JobError, JobResult};

/// The header a client names a submission with, so that sending it again creates nothing.
pub const IDEMPOTENCY_KEY: &str = "idempotency-key";

/// Longest idempotency key, bytes (a UUID is 36; room for a client's own scheme).
pub const MAX_IDEMPOTENCY_KEY: usize = 255;

/// A checked idempotency key: 1 to 255 visible ASCII characters. Anything else is refused
/// (400 naming the header), never stored as it came.
pub fn idempotency_key(value: &[u8]) -> JobResult<String> {
    let visible = value.iter().all(|b| (0x21..=0x7e).contains(b));
    if value.is_empty() || value.len() > MAX_IDEMPOTENCY_KEY || !visible {
        let message = format!("an Idempotency-Key is 1 to {MAX_IDEMPOTENCY_KEY} visible ASCII characters");
        return Err(JobError::field(ErrorCode::InvalidParameter, "Idempotency-Key", message));
    }
    Ok(String::from_utf8_lossy(value).into_owned())
}

/// The fingerprint of a job's body: SHA-256 of its JSON re-serialized (object keys sorted,
/// no whitespace), so that the same job sent again matches whatever its spacing or key order.
pub fn fingerprint(sent: &serde_json::Value) -> String {
    let canonical = serde_json::to_vec(sent).expect("a Value serializes");
    hex(&Sha256::digest(&canonical))
}

/// The stored form of a key, hashed: fixed length, and safe as a file or Redis key name.
pub fn key_digest(key: &str) -> String {
    hex(&Sha256::digest(key.as_bytes()))
}

/// Milliseconds since the Unix epoch, now.
pub fn unix_ms() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_millis() as u64).unwrap_or(0)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Idempotency keys kept unless configured (`--idempotency-keys`).
pub const DEFAULT_MAX_KEYS: usize = 100_000;

/// What an idempotency key holds: the job its first submission created, that submission's
/// body fingerprint, and when the key is forgotten.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyedJob {
    pub id: String,
    pub fingerprint: String,
    pub expires_unix_ms: u64,
}

/// Most jobs one listing page holds, and the default.
pub const MAX_PAGE: usize = 500;
pub const DEFAULT_PAGE: usize = 50;

/// `GET /v1/jobs`'s filters.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct JobFilter {
    pub status: Option<JobStatus>,
    pub method: Option<String>,
}

impl JobFilter {
    pub fn admits(&self, status: JobStatus, method: &str) -> bool {
        self.status.is_none_or(|s| s == status) && self.method.as_deref().is_none_or(|m| m == method)
    }
}

/// Where a listing page ended: the last job's submission time and id. Jobs are listed newest
/// first, ties by id descending, so the position is a total order every replica agrees on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cursor {
    pub submitted_unix_ms: u64,
    pub id: String,
}

impl Cursor {
    /// Whether a job at (`submitted_unix_ms`, `id`) comes after this position.
    pub fn precedes(&self, submitted_unix_ms: u64, id: &str) -> bool {
        (submitted_unix_ms, id) < (self.submitted_unix_ms, self.id.as_str())
    }

    /// The cursor as clients see it: opaque, URL-safe.
    pub fn encode(&self) -> String {
        base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(format!("{}.{}", self.submitted_unix_ms, self.id))
    }

    /// A cursor a client sent back; anything this server did not make is refused, naming
    /// `cursor`.
    pub fn decode(text: &str) -> JobResult<Self> {
        let invalid =
            || JobError::field(ErrorCode::InvalidParameter, "cursor", "not a cursor this server gave (use next_cursor as it came)");
        if text.len() > 128 {
            return Err(invalid());
        }
        let bytes = base64::engine::general_purpose::URL_SAFE_NO_PAD.decode(text).map_err(|_| invalid())?;
        let text = String::from_utf8(bytes).map_err(|_| invalid())?;
        let (ms, id) = text.split_once('.').ok_or_else(invalid)?;
        let is_job_id = id.len() == 32 && id.bytes().all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase());
        if !is_job_id {
            return Err(invalid());
        }
        Ok(Self { submitted_unix_ms: ms.parse().map_err(|_| invalid())?, id: id.to_owned() })
    }
}

/// One job as `GET /v1/jobs` lists it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ListedJob {
    pub id: String,
    pub status: JobStatus,
    pub method: String,
    pub submitted_unix_ms: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub finished_unix_ms: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub request_id: Option<String>,
    pub record: String,
}

impl ListedJob {
    pub fn new(id: &str, status: JobStatus, method: &str, submitted_unix_ms: u64) -> Self {
        let record = format!("/v1/jobs/{id}");
        Self { id: id.to_owned(), status, method: method.to_owned(), submitted_unix_ms, finished_unix_ms: None, request_id: None, record }
    }

    pub fn cursor(&self) -> Cursor {
        Cursor { submitted_unix_ms: self.submitted_unix_ms, id: self.id.clone() }
    }
}

/// Sorts jobs newest first (ties by id, descending), keeps those after `after` that the
/// filter admits, and cuts a page of `limit`: the page, and the cursor of the next one when
/// more remain.
pub fn page(mut jobs: Vec<ListedJob>, filter: &JobFilter, after: Option<&Cursor>, limit: usize) -> (Vec<ListedJob>, Option<Cursor>) {
    jobs.retain(|j| filter.admits(j.status, &j.method) && after.is_none_or(|c| c.precedes(j.submitted_unix_ms, &j.id)));
    jobs.sort_by(|a, b| (b.submitted_unix_ms, &b.id).cmp(&(a.submitted_unix_ms, &a.id)));
    let more = jobs.len() > limit;
    jobs.truncate(limit);
    let next = if more { jobs.last().map(ListedJob::cursor) } else { None };
    (jobs, next)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_bounded_visible_ascii() {
        assert_eq!(idempotency_key(b"4b1f-retry.7").unwrap(), "4b1f-retry.7");
        assert!(idempotency_key(&[b'k'; MAX_IDEMPOTENCY_KEY]).is_ok());
        for bad in [&b""[..], &[b'k'; MAX_IDEMPOTENCY_KEY + 1], b"two words", b"tab\there", "é".as_bytes()] {
            let error = idempotency_key(bad).unwrap_err();
            assert_eq!((error.code, error.field.as_deref()), (ErrorCode::InvalidParameter, Some("Idempotency-Key")));
        }
    }

    #[test]
    fn fingerprints_ignore_spacing_and_key_order() {
        let a: serde_json::Value = serde_json::from_str(r#"{"scene": {"builtin": "torus"}, "method": {"name": "hard"}}"#).unwrap();
        let b: serde_json::Value = serde_json::from_str(r#"{"method":{"name":"hard"},"scene":{"builtin":"torus"}}"#).unwrap();
        let c: serde_json::Value = serde_json::from_str(r#"{"method":{"name":"pcss"},"scene":{"builtin":"torus"}}"#).unwrap();
        assert_eq!(fingerprint(&a), fingerprint(&b));
        assert_ne!(fingerprint(&a), fingerprint(&c));
    }

    #[test]
    fn cursors_round_trip_and_foreign_ones_are_refused() {
        let cursor = Cursor { submitted_unix_ms: 1_700_000_000_123, id: "0123456789abcdef0123456789abcdef".into() };
        assert_eq!(Cursor::decode(&cursor.encode()).unwrap(), cursor);
        let forged = base64::engine::general_purpose::URL_SAFE_NO_PAD.encode("12.../etc/passwd");
        for bad in ["", "not base64!", &forged, &"A".repeat(200)] {
            assert_eq!(Cursor::decode(bad).unwrap_err().field.as_deref(), Some("cursor"), "{bad}");
        }
    }

    #[test]
    fn pages_are_newest_first_and_continue_where_they_ended() {
        let id = |n: u8| format!("{n:032x}");
        let jobs: Vec<ListedJob> = (0..7u8)
            .map(|n| {
                ListedJob::new(&id(n), if n % 2 == 0 { JobStatus::Succeeded } else { JobStatus::Failed }, "hard", 1000 + u64::from(n / 2))
            })
            .collect();
        let all = JobFilter::default();
        let (first, next) = page(jobs.clone(), &all, None, 3);
        assert_eq!(first.iter().map(|j| j.id.clone()).collect::<Vec<_>>(), [id(6), id(5), id(4)]);
        let (second, next) = page(jobs.clone(), &all, next.as_ref(), 3);
        assert_eq!(second.iter().map(|j| j.id.clone()).collect::<Vec<_>>(), [id(3), id(2), id(1)]);
        let (last, next) = page(jobs.clone(), &all, next.as_ref(), 3);
        assert_eq!((last.len(), next), (1, None));
        let failed = JobFilter { status: Some(JobStatus::Failed), method: None };
        assert_eq!(page(jobs.clone(), &failed, None, 10).0.len(), 3);
        let other = JobFilter { status: None, method: Some("pcss".into()) };
        assert!(page(jobs, &other, None, 10).0.is_empty());
    }
}
