//! Connections guarded as nginx guards them (`client_header_timeout`, `client_body_timeout`,
//! `keepalive_timeout`, `worker_connections`): a client that is slow to send its request's
//! head or body, or that holds an idle keep-alive connection, is disconnected after a timeout,
//! and open connections are capped below the process's file-descriptor limit. At the cap a
//! new connection is still accepted and the one that has waited longest on its own client is
//! closed to make room — so stalled clients cannot lock out health checks and renders. A
//! connection whose request is being answered (a render, an event stream) is never closed.
//!
//! `TrackedListener` hands axum streams that note when bytes arrive and can be closed from
//! outside; the `track` middleware notes when a request's body is read and its answer sent;
//! a sweeper closes what has waited too long.

mod listener;
mod track;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::task::Waker;
use std::time::{Duration, Instant};

pub use listener::{TrackedListener, TrackedStream};
pub use track::{track, ConnRef};

/// File descriptors kept for everything but client connections: the GPU driver, the store,
/// Redis connections, logs.
const RESERVED_FDS: u64 = 128;

/// How often timeouts are checked: the most a timeout overruns.
const SWEEP_EVERY: Duration = Duration::from_millis(250);

/// The connection limits, all configurable (`serve --help`).
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    /// Open client connections at most (lowered to the file-descriptor limit less a reserve).
    pub max_connections: u64,
    /// From a request's first byte to the end of its head.
    pub header_timeout: Duration,
    /// Between two reads of a request body.
    pub body_timeout: Duration,
    /// An idle keep-alive connection, between the end of an answer and the next request.
    pub keep_alive_timeout: Duration,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        Self {
            max_connections: 4096,
            header_timeout: Duration::from_secs(30),
            body_timeout: Duration::from_secs(30),
            keep_alive_timeout: Duration::from_secs(75),
        }
    }
}

impl ConnectionLimits {
    /// The limits the `serve` flags ask for (before the file-descriptor limit lowers them).
    pub fn from_config(config: &crate::config::ServeConfig) -> Self {
        let secs = |s: f64| Duration::from_secs_f64(s.max(0.001));
        Self {
            max_connections: config.max_connections,
            header_timeout: secs(config.header_timeout_secs),
            body_timeout: secs(config.body_timeout_secs),
            keep_alive_timeout: secs(config.keep_alive_secs),
        }
    }

    /// The limits with `max_connections` lowered, when it must be, below the soft limit on
    /// open files (`ulimit -n`) less a reserve; a warning says so.
    pub fn within_fd_limit(mut self) -> Self {
        if let Some(fds) = open_files_limit() {
            let room = fds.saturating_sub(RESERVED_FDS).max(16);
            if self.max_connections > room {
                tracing::warn!(
                    configured = self.max_connections,
                    lowered_to = room,
                    open_files_limit = fds,
                    "--max-connections exceeds the file-descriptor limit less {RESERVED_FDS} reserved; lowered (raise it with `ulimit -n`)"
                );
                self.max_connections = room;
            }
        }
        self
    }
}

/// The soft limit on open files of this process.
fn open_files_limit() -> Option<u64> {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit writes the limit into the struct it is given and reads nothing else.
    let answered = unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) } == 0;
    (answered && limit.rlim_cur != libc::RLIM_INFINITY).then_some(limit.rlim_cur)
}

/// Where a connection's current exchange stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(super) enum Phase {
    /// Waiting for the first byte of a request (a new or a kept-alive connection).
    Idle,
    /// Bytes of a request head arrived; the head is not complete.
    Head,
    /// The request is being handled and its body is not fully read.
    Body,
    /// The request is read; its answer is being made or sent. Never closed.
    Busy,
}

/// One connection, as the listener, the middleware and the sweeper see it.
pub(super) struct Conn {
    pub(super) phase: AtomicU8,
    /// Milliseconds since the tracker's epoch when the phase began.
    pub(super) since_ms: AtomicU64,
    /// Milliseconds since the tracker's epoch of the last bytes read.
    pub(super) read_ms: AtomicU64,
    /// Whether it has answered a request (idle from then on means kept alive).
    pub(super) answered: AtomicBool,
    pub(super) closed: AtomicBool,
    /// Woken when the connection is closed, so that a pending read sees it.
    pub(super) waker: Mutex<Option<Waker>>,
}

impl Conn {
    pub(super) fn phase(&self) -> Phase {
        match self.phase.load(Ordering::Acquire) {
            0 => Phase::Idle,
            1 => Phase::Head,
            2 => Phase::Body,
            _ => Phase::Busy,
        }
    }

    pub(super) fn enter(&self, phase: Phase, now_ms: u64) {
        self.since_ms.store(now_ms, Ordering::Release);
        self.phase.store(phase as u8, Ordering::Release);
    }

    /// When it last heard from its client, for choosing whom to close at the cap.
    pub(super) fn last_heard_ms(&self) -> u64 {
        match self.phase() {
            Phase::Body => self.read_ms.load(Ordering::Acquire),
            _ => self.since_ms.load(Ordering::Acquire),
        }
    }

    pub(super) fn close(&self) {
        self.closed.store(true, Ordering::Release);
        if let Some(waker) = self.waker.lock().unwrap_or_else(|p| p.into_inner()).take() {
            waker.wake();
        }
    }
}

/// Why connections were closed, counted for `/metrics`.
#[derive(Debug, Default, Clone, Copy, serde::Serialize)]
pub struct ConnectionStats {
    pub open: u64,
    pub max: u64,
    pub header_timeouts: u64,
    pub body_timeouts: u64,
    pub idle_timeouts: u64,
    /// Closed at the cap to make room for a new connection.
    pub shed: u64,
}

/// Every open connection, the limits, and what was closed.
pub struct Tracker {
    pub(super) limits: ConnectionLimits,
    pub(super) epoch: Instant,
    pub(super) next_id: AtomicU64,
    pub(super) open: Mutex<HashMap<u64, Arc<Conn>>>,
    pub(super) header_timeouts: AtomicU64,
    pub(super) body_timeouts: AtomicU64,
    pub(super) idle_timeouts: AtomicU64,
    pub(super) shed: AtomicU64,
}

impl Tracker {
    pub fn new(limits: ConnectionLimits) -> Arc<Self> {
        Arc::new(Self {
            limits,
            epoch: Instant::now(),
            next_id: AtomicU64::new(0),
            open: Mutex::new(HashMap::new()),
            header_timeouts: AtomicU64::new(0),
            body_timeouts: AtomicU64::new(0),
            idle_timeouts: AtomicU64::new(0),
            shed: AtomicU64::new(0),
        })
    }

    pub(super) fn now_ms(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    pub(super) fn connections(&self) -> std::sync::MutexGuard<'_, HashMap<u64, Arc<Conn>>> {
        self.open.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn stats(&self) -> ConnectionStats {
        ConnectionStats {
            open: self.connections().len() as u64,
            max: self.limits.max_connections,
            header_timeouts: self.header_timeouts.load(Ordering::Relaxed),
            body_timeouts: self.body_timeouts.load(Ordering::Relaxed),
            idle_timeouts: self.idle_timeouts.load(Ordering::Relaxed),
            shed: self.shed.load(Ordering::Relaxed),
        }
    }

    /// Below the cap, nothing; at it, closes the connection that has waited longest on its
    /// client. False when every connection is busy answering (the new one must wait).
    pub(super) fn make_room(&self) -> bool {
        let open = self.connections();
        (open.len() as u64) < self.limits.max_connections
            || Self::shed_longest_waiting(&open, &self.shed)
            // Closed ones are on their way out: their slots come back in a moment.
            || open.values().any(|c| c.closed.load(Ordering::Acquire))
    }

    /// Closes the connection that has waited longest on its client (never one answering a
    /// request), counting it as shed; false when there is none.
    pub(super) fn shed_one(&self) -> bool {
        Self::shed_longest_waiting(&self.connections(), &self.shed)
    }

    fn shed_longest_waiting(open: &HashMap<u64, Arc<Conn>>, shed: &AtomicU64) -> bool {
        let oldest =
            open.values().filter(|c| c.phase() != Phase::Busy && !c.closed.load(Ordering::Acquire)).min_by_key(|c| c.last_heard_ms());
        oldest
            .inspect(|conn| {
                conn.close();
                shed.fetch_add(1, Ordering::Relaxed);
            })
            .is_some()
    }

    pub(super) fn register(self: &Arc<Self>) -> (u64, Arc<Conn>) {
        let now = self.now_ms();
        let conn = Arc::new(Conn {
            phase: AtomicU8::new(Phase::Idle as u8),
            since_ms: AtomicU64::new(now),
            read_ms: AtomicU64::new(now),
            answered: AtomicBool::new(false),
            closed: AtomicBool::new(false),
            waker: Mutex::new(None),
        });
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        self.connections().insert(id, conn.clone());
        (id, conn)
    }

    /// Closes every connection that has waited on its client past its timeout.
    fn sweep(&self) {
        let now = self.now_ms();
        let limits = &self.limits;
        let ms = |d: Duration| d.as_millis() as u64;
        for conn in self.connections().values() {
            let since = now.saturating_sub(conn.since_ms.load(Ordering::Acquire));
            let (late, counter) = match conn.phase() {
                // A new connection's first request must arrive as its head would.
                Phase::Idle if !conn.answered.load(Ordering::Acquire) => (since > ms(limits.header_timeout), &self.header_timeouts),
                Phase::Idle => (since > ms(limits.keep_alive_timeout), &self.idle_timeouts),
                Phase::Head => (since > ms(limits.header_timeout), &self.header_timeouts),
                Phase::Body => {
                    let quiet = now.saturating_sub(conn.read_ms.load(Ordering::Acquire));
                    (quiet > ms(limits.body_timeout), &self.body_timeouts)
                }
                Phase::Busy => continue,
            };
            if late && !conn.closed.load(Ordering::Acquire) {
                conn.close();
                counter.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Sweeps every `SWEEP_EVERY` for as long as the tracker is in use.
    pub fn spawn_sweeper(self: &Arc<Self>) {
        let tracker = Arc::downgrade(self);
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(SWEEP_EVERY);
            loop {
                tick.tick().await;
                let Some(tracker) = tracker.upgrade() else { return };
                tracker.sweep();
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tracker(max_connections: u64) -> Arc<Tracker> {
        let second = Duration::from_secs(1);
        Tracker::new(ConnectionLimits { max_connections, header_timeout: second, body_timeout: second, keep_alive_timeout: 2 * second })
    }

    #[test]
    fn at_the_cap_the_longest_waiting_connection_goes_and_busy_ones_stay() {
        let tracker = tracker(3);
        let (_, busy) = tracker.register();
        busy.enter(Phase::Busy, 0);
        let (_, old) = tracker.register();
        old.enter(Phase::Body, 0);
        old.read_ms.store(10, Ordering::Release);
        let (_, recent) = tracker.register();
        recent.enter(Phase::Body, 0);
        recent.read_ms.store(500, Ordering::Release);
        assert!(tracker.make_room());
        assert!(old.closed.load(Ordering::Acquire) && !recent.closed.load(Ordering::Acquire) && !busy.closed.load(Ordering::Acquire));
        assert_eq!(tracker.stats().shed, 1);
        // Every remaining connection busy: no room until one finishes.
        tracker.connections().retain(|_, c| !c.closed.load(Ordering::Acquire));
        recent.enter(Phase::Busy, 0);
        let (_, third) = tracker.register();
        third.enter(Phase::Busy, 0);
        assert!(!tracker.make_room());
    }

    #[test]
    fn each_phase_times_out_by_its_own_clock() {
        let tracker = tracker(100);
        let phases = [Phase::Head, Phase::Body, Phase::Idle, Phase::Busy];
        let conns: Vec<Arc<Conn>> = phases
            .iter()
            .map(|&phase| {
                let (_, conn) = tracker.register();
                conn.enter(phase, 0);
                conn.read_ms.store(0, Ordering::Release);
                conn
            })
            .collect();
        // A kept-alive idle connection gets the longer keep-alive timeout (2 s).
        conns[2].answered.store(true, Ordering::Release);
        std::thread::sleep(Duration::from_millis(1100));
        tracker.sweep();
        let closed: Vec<bool> = conns.iter().map(|c| c.closed.load(Ordering::Acquire)).collect();
        assert_eq!(closed, [true, true, false, false], "head and body past 1 s; idle within its 2 s; busy never");
        let stats = tracker.stats();
        assert_eq!((stats.header_timeouts, stats.body_timeouts, stats.idle_timeouts), (1, 1, 0));
    }
}
