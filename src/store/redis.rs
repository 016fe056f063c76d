//! The shared job store on Redis (`--job-store redis://HOST:PORT/DB`), for several replicas
//! acting as one service. The queue is a stream (`penumbra:queue`) with one consumer group
//! (`workers`): a replica's worker takes an entry with `XREADGROUP`, keeps it claimed while it
//! renders (an `XCLAIM` of its own entry every few seconds resets the entry's idle time), and
//! acknowledges and deletes it when the job is stored. An entry idle for longer than
//! `CLAIM_IDLE` belongs to a replica that died: `XAUTOCLAIM` hands it to the next worker that
//! asks. Job records (`penumbra:job:ID`, JSON) and result images (`penumbra:image:ID`) get a
//! TTL once finished; uploads (`penumbra:upload:KIND:SHA256`) are stored once for every
//! replica, each of which keeps its own LRU cache in front. Every accepted job's id is in a
//! sorted set by submission time (`penumbra:jobs`), which `GET /v1/jobs` reads on any replica
//! (ids whose record expired are dropped from it as they are met); an idempotency key is
//! `penumbra:key:SHA256` with its own TTL. Each replica reports itself every few seconds
//! (`penumbra:replica:NAME`, expiring, named in `penumbra:replicas`) and pushes every job it
//! finishes onto a capped list (`penumbra:recent`): the cluster view of `/v1/stats`. A cancellation is a key of its
//! own (`penumbra:cancel:ID`), written once and only read after: record updates are
//! read-modify-write, so a progress report could otherwise overwrite a `cancelled` status.
//!
//! Outages: a connection that fails is dropped, and the next call opens a new one (creating
//! the consumer group again if a Redis restarted without its data lost it); every failure to
//! reach Redis is `StoreError::Unavailable`, which the server answers with 503 and retries.
//! A replica may start before Redis does.

use std::sync::Mutex;
use std::time::Duration;

use redis::{Commands, Connection};
use serde_json::Value;

use super::{unix_ms, Backlog, JobStore, ReplicaReport, StoreError, StoreResult, StoredJob};
use crate::job::submission::{key_digest, Cursor, JobFilter, KeyedJob, ListedJob};
use crate::job::summary::JobSummary;
use crate::job::JobStatus;
use crate::upload_store::Kind;

const QUEUE: &str = "penumbra:queue";
const GROUP: &str = "workers";
/// Accepted jobs' ids scored by submission time (ms): the listing's index.
const INDEX: &str = "penumbra:jobs";
/// Live replicas' names scored by when their last report expires (ms); each report is
/// `penumbra:replica:NAME` with the same expiry.
const REPLICAS: &str = "penumbra:replicas";
/// The service's last finished jobs (JSON summaries, newest first), for every replica's
/// `/v1/stats`.
const RECENT: &str = "penumbra:recent";
/// Most index entries one listing reads before it answers with what it found and a cursor:
/// a filter that admits few jobs pages through the index instead of reading all of it.
const MAX_LIST_SCAN: usize = 2000;

/// How long a taken job may go without a heartbeat before another replica claims it, unless
/// configured (`--claim-idle-secs`); workers renew their claim five times as often.
pub const CLAIM_IDLE: Duration = Duration::from_secs(15);
/// Uploads live at least this long after their last use.
const UPLOAD_TTL: Duration = Duration::from_secs(7 * 24 * 3600);

pub struct RedisStore {
    client: redis::Client,
    /// Idle connections; a worker blocked in `XREADGROUP` holds its own meanwhile.
    pool: Mutex<Vec<Connection>>,
    /// How long finished records and images stay.
    ttl: Duration,
    /// Idle time after which a taken job is another replica's to claim.
    claim_idle: Duration,
}

fn job_key(id: &str) -> String {
    format!("penumbra:job:{id}")
}

fn cancel_key(id: &str) -> String {
    format!("penumbra:cancel:{id}")
}

fn image_key(id: &str) -> String {
    format!("penumbra:image:{id}")
}

fn idempotency_key(key: &str) -> String {
    format!("penumbra:key:{}", key_digest(key))
}

/// A running progressive job's round images, a field each (`put_round`).
fn rounds_key(id: &str) -> String {
    format!("penumbra:rounds:{id}")
}

fn replica_key(replica: &str) -> String {
    format!("penumbra:replica:{replica}")
}

fn upload_key(kind: Kind, id: &str) -> String {
    let kind = match kind {
        Kind::Scene => "scene",
        Kind::Light => "light",
    };
    format!("penumbra:upload:{kind}:{id}")
}

/// Records a job, queues it and indexes it, unless a record with its id exists: one atomic
/// step, so that neither a record without a queue entry nor an overwritten record can result.
/// KEYS: record, queue, index; ARGV: record JSON, id, submission ms.
const ACCEPT: &str = r#"
if redis.call('SET', KEYS[1], ARGV[1], 'NX') then
  redis.call('XADD', KEYS[2], '*', 'id', ARGV[2])
  redis.call('ZADD', KEYS[3], ARGV[3], ARGV[2])
  return 1
end
return 0
"#;

/// `ACCEPT` under an idempotency key, in the same atomic step: a key that names a job whose
/// record is still there is answered (its JSON) and nothing is written, so of two twins on two
/// replicas one job results. KEYS: record, queue, index, key; ARGV: as `ACCEPT`, then the
/// key's JSON and its TTL (ms).
const ACCEPT_KEYED: &str = r#"
local held = redis.call('GET', KEYS[4])
if held and redis.call('EXISTS', 'penumbra:job:' .. cjson.decode(held)['id']) == 1 then
  return held
end
if redis.call('SET', KEYS[1], ARGV[1], 'NX') then
  redis.call('SET', KEYS[4], ARGV[4], 'PX', ARGV[5])
  redis.call('XADD', KEYS[2], '*', 'id', ARGV[2])
  redis.call('ZADD', KEYS[3], ARGV[3], ARGV[2])
  return 1
end
return 0
"#;

/// `url` with its password (if any) hidden, for messages.
fn redacted(url: &str) -> String {
    match (url.find("://"), url.rfind('@')) {
        (Some(scheme), Some(at)) if at > scheme => format!("{}://***{}", &url[..scheme], &url[at..]),
        _ => url.to_owned(),
    }
}

/// A Redis error as a store error: not reaching Redis, Redis refusing this replica's password
/// (a Secret rotated on one side only), or Redis not ready to serve (loading its data after a
/// restart, unable to persist, a lost consumer group), is transient; Redis out of memory is
/// `Full`.
fn classify(error: redis::RedisError) -> StoreError {
    let transient_codes = ["LOADING", "MASTERDOWN", "TRYAGAIN", "BUSY", "MISCONF", "NOGROUP", "READONLY", "NOAUTH", "WRONGPASS"];
    if error.code() == Some("OOM") {
        StoreError::Full(error.to_string())
    } else if error.kind() == redis::ErrorKind::AuthenticationFailed
        || error.is_io_error()
        || error.is_connection_refusal()
        || error.is_connection_dropped()
        || error.is_timeout()
        || error.code().is_some_and(|code| transient_codes.contains(&code))
    {
        StoreError::Unavailable(error.to_string())
    } else {
        StoreError::Other(error.into())
    }
}

impl RedisStore {
    /// A store on the Redis at `url`. Redis need not be up yet: the queue's consumer group is
    /// created on each new connection, so a replica that starts first, or outlives a Redis
    /// restart, finds it once Redis answers.
    /// `ca_cert`: for a `rediss://` URL, a PEM file of the authorities that signed Redis's
    /// certificate, trusted instead of the system's roots (a private CA is the usual case).
    pub fn open(url: &str, ca_cert: Option<&std::path::Path>, ttl: Duration, claim_idle: Duration) -> anyhow::Result<Self> {
        let bad_url = |e: redis::RedisError| anyhow::anyhow!("bad Redis URL `{}`: {e}", redacted(url));
        let client = match ca_cert {
            Some(path) => {
                anyhow::ensure!(url.starts_with("rediss://"), "--redis-ca-cert needs a rediss:// job store");
                let root_cert = std::fs::read(path).map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
                redis::Client::build_with_tls(url, redis::TlsCertificates { client_tls: None, root_cert: Some(root_cert) })
                    .map_err(bad_url)?
            }
            None => redis::Client::open(url).map_err(bad_url)?,
        };
        let claim_idle = claim_idle.max(Duration::from_millis(500));
        let store = Self { client, pool: Mutex::new(Vec::new()), ttl: ttl.max(Duration::from_secs(1)), claim_idle };
        if let Err(error) = store.ping() {
            tracing::warn!(%error, "Redis does not answer yet; submitted jobs get 503 store_unavailable until it does");
        }
        Ok(store)
    }

    /// A new connection, with timeouts, on which the consumer group (and the stream) exist.
    fn connect(&self) -> redis::RedisResult<Connection> {
        let mut c = self.client.get_connection_with_timeout(Duration::from_secs(2))?;
        c.set_read_timeout(Some(Duration::from_secs(10)))?;
        c.set_write_timeout(Some(Duration::from_secs(10)))?;
        match c.xgroup_create_mkstream::<_, _, _, ()>(QUEUE, GROUP, "0") {
            Err(e) if e.code() != Some("BUSYGROUP") => Err(e),
            _ => Ok(c),
        }
    }

    /// Runs `f` on a pooled connection (a new one when none is idle); a connection that
    /// failed is dropped rather than returned.
    fn with<T>(&self, f: impl FnOnce(&mut Connection) -> redis::RedisResult<T>) -> StoreResult<T> {
        let pooled = self.pool.lock().unwrap_or_else(|p| p.into_inner()).pop();
        let mut connection = match pooled {
            Some(c) => c,
            None => self.connect().map_err(classify)?,
        };
        let result = f(&mut connection);
        if result.is_ok() {
            self.pool.lock().unwrap_or_else(|p| p.into_inner()).push(connection);
        }
        result.map_err(classify)
    }

    fn put_record(&self, job: &StoredJob, expire: bool) -> StoreResult<()> {
        let json = serde_json::to_vec(job)?;
        let key = job_key(&job.id);
        if expire {
            self.with(|c| c.set_ex::<_, _, ()>(key, json, self.ttl.as_secs()))
        } else {
            self.with(|c| c.set::<_, _, ()>(key, json))
        }
    }

    fn update(&self, id: &str, change: impl FnOnce(&mut StoredJob)) -> StoreResult<StoredJob> {
        let mut job = self.get(id)?.ok_or_else(|| anyhow::anyhow!("no job `{id}` in the store"))?;
        change(&mut job);
        Ok(job)
    }

    /// Stores a finished record (with its TTL) and takes its entry off the queue.
    fn finish(&self, job: StoredJob, image: Option<&[u8]>) -> StoreResult<()> {
        let ttl = self.ttl.as_secs();
        let json = serde_json::to_vec(&job)?;
        self.with(|c| {
            let mut pipe = redis::pipe();
            pipe.atomic();
            if let Some(image) = image {
                pipe.set_ex(image_key(&job.id), image, ttl).ignore();
            }
            pipe.set_ex(job_key(&job.id), json, ttl).ignore();
            if let Some(entry) = &job.entry {
                pipe.xack(QUEUE, GROUP, &[entry]).ignore();
                pipe.xdel(QUEUE, &[entry]).ignore();
            }
            pipe.query::<()>(c)
        })
    }

    /// The job an entry carries, with the entry noted; None (and the entry dropped) when the
    /// record is gone or already finished (a replica finished it just before it died).
    fn take(&self, consumer: &str, entry: &str, id: Option<String>) -> StoreResult<Option<StoredJob>> {
        let job = match id {
            Some(id) => self.get(&id)?,
            None => None,
        };
        match job {
            Some(mut job) if !job.finished() => {
                job.entry = Some(entry.to_owned());
                job.worker = Some(consumer.to_owned());
                self.put_record(&job, false)?;
                Ok(Some(job))
            }
            _ => {
                self.with(|c| redis::pipe().xack(QUEUE, GROUP, &[entry]).xdel(QUEUE, &[entry]).query::<()>(c))?;
                Ok(None)
            }
        }
    }
}

impl JobStore for RedisStore {
    fn accept_record(&self, record: &StoredJob) -> StoreResult<()> {
        let (id, json) = (&record.id, serde_json::to_vec(record)?);
        // The record first: a worker that takes the entry always finds it.
        let mut script = redis::cmd("EVAL");
        script.arg(ACCEPT).arg(3).arg(job_key(id)).arg(QUEUE).arg(INDEX).arg(json).arg(id).arg(record.submitted_unix_ms);
        let created: i64 = self.with(|c| script.query(c))?;
        if created == 0 {
            return Err(StoreError::Exists(id.to_owned()));
        }
        Ok(())
    }

    fn keyed(&self, key: &str) -> StoreResult<Option<KeyedJob>> {
        let held: Option<Vec<u8>> = self.with(|c| c.get(idempotency_key(key)))?;
        let Some(held) = held.map(|bytes| serde_json::from_slice::<KeyedJob>(&bytes)).transpose()? else { return Ok(None) };
        let exists: bool = self.with(|c| c.exists(job_key(&held.id)))?;
        Ok(exists.then_some(held))
    }

    fn accept_keyed(&self, record: &StoredJob, key: &str, claim: &KeyedJob) -> StoreResult<Option<KeyedJob>> {
        let (id, json) = (&record.id, serde_json::to_vec(record)?);
        let ttl_ms = claim.expires_unix_ms.saturating_sub(unix_ms()).max(1);
        let mut script = redis::cmd("EVAL");
        script.arg(ACCEPT_KEYED).arg(4).arg(job_key(id)).arg(QUEUE).arg(INDEX).arg(idempotency_key(key));
        script.arg(json).arg(id).arg(record.submitted_unix_ms).arg(serde_json::to_vec(claim)?).arg(ttl_ms);
        let answer: redis::Value = self.with(|c| script.query(c))?;
        match answer {
            redis::Value::Int(1) => Ok(None),
            redis::Value::Int(_) => Err(StoreError::Exists(id.to_owned())),
            redis::Value::BulkString(held) => Ok(Some(serde_json::from_slice(&held)?)),
            other => Err(anyhow::anyhow!("unexpected answer to an idempotent accept: {other:?}").into()),
        }
    }

    /// Reads the index newest first from a fixed top score (so jobs accepted meanwhile do not
    /// shift the offsets), the records of each batch in one `MGET`.
    fn list(&self, filter: &JobFilter, after: Option<&Cursor>, limit: usize) -> StoreResult<(Vec<ListedJob>, Option<Cursor>)> {
        let top = after.map_or(unix_ms() + 1, |c| c.submitted_unix_ms);
        let batch = (limit * 2).clamp(64, 1000);
        // `offset` is the position in the index (less the ids dropped on the way), `scanned`
        // what this call has read, the bound.
        let (mut page, mut offset, mut scanned) = (Vec::new(), 0, 0);
        loop {
            let entries: Vec<(String, f64)> = self.with(|c| {
                redis::cmd("ZREVRANGEBYSCORE")
                    .arg(INDEX)
                    .arg(top)
                    .arg("-inf")
                    .arg("WITHSCORES")
                    .arg("LIMIT")
                    .arg(offset)
                    .arg(batch)
                    .query(c)
            })?;
            if entries.is_empty() {
                return Ok((page, None));
            }
            offset += entries.len();
            scanned += entries.len();
            let last = entries.last().map(|(id, score)| Cursor { submitted_unix_ms: *score as u64, id: id.clone() });
            let fresh: Vec<&String> =
                entries.iter().filter(|(id, score)| after.is_none_or(|c| c.precedes(*score as u64, id))).map(|(id, _)| id).collect();
            if !fresh.is_empty() {
                let keys: Vec<String> = fresh.iter().map(|id| job_key(id)).collect();
                let records: Vec<Option<Vec<u8>>> = self.with(|c| redis::cmd("MGET").arg(&keys).query(c))?;
                let mut gone = Vec::new();
                for (id, record) in fresh.iter().zip(records) {
                    let Some(record) = record else {
                        gone.push((*id).clone());
                        continue;
                    };
                    let listed = serde_json::from_slice::<StoredJob>(&record)?.listed();
                    if filter.admits(listed.status, &listed.method) {
                        page.push(listed);
                        if page.len() == limit {
                            let next = page.last().map(ListedJob::cursor);
                            return Ok((page, next));
                        }
                    }
                }
                if !gone.is_empty() {
                    // Records expired by their TTL: their ids leave the index.
                    self.with(|c| c.zrem::<_, _, ()>(INDEX, &gone))?;
                    offset -= gone.len();
                }
            }
            if entries.len() < batch {
                return Ok((page, None));
            }
            // Scanned as far as one call may: the next page starts after the last id read.
            if scanned >= MAX_LIST_SCAN {
                return Ok((page, last));
            }
        }
    }

    /// A new attempt (a replica that died mid-job leaves its job to another) draws a
    /// progressive job's rounds afresh: the last attempt's are forgotten.
    fn start(&self, id: &str) -> StoreResult<()> {
        let job = self.update(id, |job| {
            job.status = JobStatus::Running;
            job.attempts += 1;
            job.rounds.clear();
        })?;
        self.put_record(&job, false)?;
        if job.attempts > 1 {
            self.drop_rounds(id)?;
        }
        Ok(())
    }

    fn succeed(&self, id: &str, result: &Value, image: &[u8]) -> StoreResult<bool> {
        let cancelled = self.cancelled(id)?;
        let job = self.update(id, |job| {
            if cancelled {
                // The record may say `running` again (a progress report read it before the
                // cancel): the cancel key decides.
                job.status = JobStatus::Cancelled;
                job.finished_unix_ms = Some(unix_ms());
                job.error =
                    Some(serde_json::json!({"code": "cancelled", "message": "the job was cancelled before it finished", "status": 409}));
            } else {
                job.status = JobStatus::Succeeded;
                job.finished_unix_ms = Some(unix_ms());
                job.result = Some(result.clone());
                job.image_bytes = image.len() as u64;
                job.done = job.total;
            }
        })?;
        self.finish(job, (!cancelled).then_some(image))?;
        Ok(!cancelled)
    }

    fn fail(&self, id: &str, error: &Value) -> StoreResult<()> {
        if StoredJob::status_after(error) == JobStatus::Cancelled {
            let ttl = self.ttl.as_secs();
            self.with(|c| c.set_ex::<_, _, ()>(cancel_key(id), 1, ttl))?;
        }
        let job = self.update(id, |job| {
            job.status = StoredJob::status_after(error);
            job.finished_unix_ms = Some(unix_ms());
            job.error = Some(error.clone());
        })?;
        self.finish(job, None)
    }

    fn get(&self, id: &str) -> StoreResult<Option<StoredJob>> {
        let bytes: Option<Vec<u8>> = self.with(|c| c.get(job_key(id)))?;
        Ok(match bytes {
            Some(bytes) => Some(serde_json::from_slice(&bytes)?),
            None => None,
        })
    }

    fn image(&self, id: &str) -> StoreResult<Option<Vec<u8>>> {
        self.with(|c| c.get(image_key(id)))
    }

    fn unfinished(&self) -> StoreResult<Vec<StoredJob>> {
        Ok(Vec::new())
    }

    fn expire(&self, _max_age: Duration, _max_image_bytes: u64) -> StoreResult<(usize, usize)> {
        // Finished records and images carry their TTL; Redis drops them itself. The index's
        // oldest ids are checked here, so that it does not grow with jobs nobody lists.
        let oldest: Vec<String> = self.with(|c| c.zrange(INDEX, 0, 99))?;
        if !oldest.is_empty() {
            let keys: Vec<String> = oldest.iter().map(|id| job_key(id)).collect();
            let records: Vec<Option<Vec<u8>>> = self.with(|c| redis::cmd("MGET").arg(&keys).query(c))?;
            let gone: Vec<&String> = oldest.iter().zip(&records).filter(|(_, r)| r.is_none()).map(|(id, _)| id).collect();
            if !gone.is_empty() {
                self.with(|c| c.zrem::<_, _, ()>(INDEX, &gone))?;
            }
        }
        Ok((0, 0))
    }

    fn ping(&self) -> StoreResult<()> {
        self.with(|c| redis::cmd("PING").query::<()>(c))
    }

    fn shared(&self) -> bool {
        true
    }

    fn queued(&self) -> StoreResult<u64> {
        // Entries in the stream that no worker has taken: all of them less the pending ones.
        self.with(|c| {
            let length: u64 = c.xlen(QUEUE)?;
            let pending: redis::streams::StreamPendingReply = c.xpending(QUEUE, GROUP)?;
            Ok(length.saturating_sub(pending.count() as u64))
        })
    }

    /// The entries no worker has taken, and the oldest of them: the first entry after the
    /// group's last delivered one (an entry's id is the millisecond it was added).
    fn backlog(&self) -> StoreResult<Option<Backlog>> {
        self.with(|c| {
            let length: u64 = c.xlen(QUEUE)?;
            let pending: redis::streams::StreamPendingReply = c.xpending(QUEUE, GROUP)?;
            let jobs = length.saturating_sub(pending.count() as u64);
            if jobs == 0 {
                return Ok(Some(Backlog { jobs, oldest_unix_ms: None }));
            }
            let groups: redis::streams::StreamInfoGroupsReply = c.xinfo_groups(QUEUE)?;
            let last = groups.groups.iter().find(|g| g.name == GROUP).map_or("0-0".to_owned(), |g| g.last_delivered_id.clone());
            let next: redis::streams::StreamRangeReply = c.xrange_count(QUEUE, format!("({last}"), "+", 1)?;
            let oldest_unix_ms = next.ids.first().and_then(|entry| entry.id.split('-').next()?.parse().ok());
            Ok(Some(Backlog { jobs, oldest_unix_ms }))
        })
    }

    fn next(&self, consumer: &str, wait: Duration) -> StoreResult<Option<StoredJob>> {
        // A dead replica's job first: entries no heartbeat renewed for CLAIM_IDLE.
        let claimed: redis::streams::StreamAutoClaimReply = self.with(|c| {
            c.xautoclaim_options(
                QUEUE,
                GROUP,
                consumer,
                self.claim_idle.as_millis() as u64,
                "0-0",
                redis::streams::StreamAutoClaimOptions::default().count(1),
            )
        })?;
        if let Some(entry) = claimed.claimed.first() {
            tracing::warn!(entry = %entry.id, "claimed a job whose replica stopped answering");
            return self.take(consumer, &entry.id, entry.get("id"));
        }
        let mut options = redis::streams::StreamReadOptions::default().group(GROUP, consumer).count(1);
        // BLOCK 0 would wait for ever: no wait means no BLOCK at all.
        if !wait.is_zero() {
            options = options.block(wait.as_millis() as usize);
        }
        let reply: Option<redis::streams::StreamReadReply> = self.with(|c| c.xread_options(&[QUEUE], &[">"], &options))?;
        let Some(entry) = reply.and_then(|r| r.keys.into_iter().next()).and_then(|k| k.ids.into_iter().next()) else {
            return Ok(None);
        };
        self.take(consumer, &entry.id, entry.get("id"))
    }

    fn heartbeat_every(&self) -> Duration {
        self.claim_idle / 5
    }

    fn cancelled(&self, id: &str) -> StoreResult<bool> {
        self.with(|c| c.exists(cancel_key(id)))
    }

    fn heartbeat(&self, consumer: &str, job: &StoredJob) -> StoreResult<()> {
        let Some(entry) = &job.entry else { return Ok(()) };
        // Claiming one's own entry with no minimum idle time resets its idle time.
        self.with(|c| {
            redis::cmd("XCLAIM").arg(QUEUE).arg(GROUP).arg(consumer).arg(0).arg(entry).arg("JUSTID").query::<redis::Value>(c).map(|_| ())
        })
    }

    fn progress(&self, id: &str, done: u64, total: u64) -> StoreResult<()> {
        let job = self.update(id, |job| {
            job.done = done;
            job.total = total;
        })?;
        self.put_record(&job, false)
    }

    /// The report with its expiry, its name in the set of live replicas, and the names
    /// whose reports expired dropped from the set: one atomic step.
    fn announce(&self, report: &ReplicaReport, ttl: Duration) -> StoreResult<()> {
        let json = serde_json::to_vec(report)?;
        let now = unix_ms();
        let ttl_ms = ttl.as_millis().max(1) as u64;
        self.with(|c| {
            redis::pipe()
                .atomic()
                .pset_ex(replica_key(&report.replica), json, ttl_ms)
                .ignore()
                .zadd(REPLICAS, &report.replica, now + ttl_ms)
                .ignore()
                .zrembyscore(REPLICAS, "-inf", now)
                .ignore()
                .query::<()>(c)
        })
    }

    fn withdraw(&self, replica: &str) -> StoreResult<()> {
        self.with(|c| redis::pipe().atomic().del(replica_key(replica)).ignore().zrem(REPLICAS, replica).ignore().query::<()>(c))
    }

    fn replicas(&self) -> StoreResult<Vec<ReplicaReport>> {
        let names: Vec<String> = self.with(|c| c.zrangebyscore(REPLICAS, unix_ms(), "+inf"))?;
        if names.is_empty() {
            return Ok(Vec::new());
        }
        let keys: Vec<String> = names.iter().map(|name| replica_key(name)).collect();
        let reports: Vec<Option<Vec<u8>>> = self.with(|c| redis::cmd("MGET").arg(&keys).query(c))?;
        // A report that expired between the two reads is a replica that just left.
        let mut reports: Vec<ReplicaReport> = reports.into_iter().flatten().filter_map(|json| serde_json::from_slice(&json).ok()).collect();
        reports.sort_by(|a, b| a.replica.cmp(&b.replica));
        Ok(reports)
    }

    fn record_finished(&self, summary: &JobSummary, keep: usize) -> StoreResult<()> {
        let json = serde_json::to_vec(summary)?;
        let last = keep.max(1) as isize - 1;
        self.with(|c| redis::pipe().atomic().lpush(RECENT, json).ignore().ltrim(RECENT, 0, last).ignore().query::<()>(c))
    }

    fn recent_finished(&self, n: usize) -> StoreResult<Vec<JobSummary>> {
        if n == 0 {
            return Ok(Vec::new());
        }
        let listed: Vec<Vec<u8>> = self.with(|c| c.lrange(RECENT, 0, n as isize - 1))?;
        Ok(listed.iter().filter_map(|json| serde_json::from_slice(json).ok()).collect())
    }

    /// In one hash per job, expiring as finished records do: a replica that dies mid-job
    /// leaves none for longer than that.
    fn put_round(&self, id: &str, round: usize, image: &[u8]) -> StoreResult<bool> {
        let (key, ttl) = (rounds_key(id), self.ttl.as_secs().max(1) as i64);
        self.with(|c| redis::pipe().atomic().hset(&key, round, image).ignore().expire(&key, ttl).ignore().query::<()>(c))?;
        Ok(true)
    }

    fn round(&self, id: &str, round: usize) -> StoreResult<Option<Vec<u8>>> {
        self.with(|c| c.hget(rounds_key(id), round))
    }

    fn drop_rounds(&self, id: &str) -> StoreResult<()> {
        self.with(|c| c.del(rounds_key(id)))
    }

    fn round_drawn(&self, id: &str, round: &crate::job::progressive::Round) -> StoreResult<()> {
        let job = self.update(id, |job| job.rounds.push(round.clone()))?;
        self.put_record(&job, false)
    }

    fn put_upload(&self, kind: Kind, id: &str, bytes: &[u8]) -> StoreResult<()> {
        self.with(|c| c.set_ex::<_, _, ()>(upload_key(kind, id), bytes, UPLOAD_TTL.as_secs()))
    }

    fn get_upload(&self, kind: Kind, id: &str) -> StoreResult<Option<Vec<u8>>> {
        // Reading renews the TTL: an upload in use never expires.
        self.with(|c| redis::cmd("GETEX").arg(upload_key(kind, id)).arg("EX").arg(UPLOAD_TTL.as_secs()).query(c))
    }

    fn upload_size(&self, kind: Kind, id: &str) -> StoreResult<Option<u64>> {
        let length: u64 = self.with(|c| c.strlen(upload_key(kind, id)))?;
        Ok((length > 0).then_some(length))
    }

    fn delete_upload(&self, kind: Kind, id: &str) -> StoreResult<bool> {
        self.with(|c| c.del::<_, u64>(upload_key(kind, id)).map(|n| n > 0))
    }
}
