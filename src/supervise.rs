//! Supervising a render in progress: a `Supervisor` hears the progress of long methods and
//! may stop the render between GPU submissions (a client that went away, a job cancelled by
//! `DELETE`). It sits below everything that renders and everything that serves, so both speak
//! of it without knowing each other.

use crate::error::{ErrorCode, JobError};

/// Hears a render's progress and decides whether it goes on. Any `Fn(done, total)` is a
/// supervisor that never stops the render.
pub trait Supervisor {
    /// Steps done and steps in all of a long method (the reference's sample batches).
    fn progress(&self, _done: u64, _total: u64) {}
    /// Asked between phases and between a long method's batches: once it answers true the
    /// render stops at the next such point and fails with `cancelled`.
    fn cancelled(&self) -> bool {
        false
    }
}

impl<F: Fn(u64, u64)> Supervisor for F {
    fn progress(&self, done: u64, total: u64) {
        self(done, total)
    }
}

/// A supervisor made of two closures: progress, and whether to stop (a flag another thread
/// raises, typically).
pub struct Supervise<P, C> {
    pub progress: P,
    pub cancelled: C,
}

impl<P: Fn(u64, u64), C: Fn() -> bool> Supervisor for Supervise<P, C> {
    fn progress(&self, done: u64, total: u64) {
        (self.progress)(done, total)
    }
    fn cancelled(&self) -> bool {
        (self.cancelled)()
    }
}

/// The error of a render its supervisor stopped.
pub fn cancelled_error() -> JobError {
    JobError::new(ErrorCode::Cancelled, "the job was cancelled before it finished")
}

/// No supervisor: progress goes unheard and the render is never stopped (`&()`).
impl Supervisor for () {}
