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
    /// Where a progressive job's rounds keep what a method carries from one round to the next
    /// (the reference's sums); `None` for a render that stands alone.
    fn rounds(&self) -> Option<&Rounds> {
        None
    }
}

/// What a method carries between the rounds of a progressive job, held by the job's
/// supervisor for the job's life: the method's own type, which it takes at the start of a
/// round and puts back at the end (opaque here, so that nothing below the methods knows it).
#[derive(Default)]
pub struct Rounds(std::sync::Mutex<Option<Box<dyn std::any::Any + Send>>>);

impl Rounds {
    /// What the last round left, if it was a `T`.
    pub fn take<T: 'static>(&self) -> Option<Box<T>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).take()?.downcast().ok()
    }

    pub fn put<T: Send + 'static>(&self, carried: T) {
        *self.0.lock().unwrap_or_else(|p| p.into_inner()) = Some(Box::new(carried));
    }
}

/// A supervisor with a progressive job's `Rounds`: `inner` hears the progress and says when
/// to stop.
pub struct WithRounds<'a, S: ?Sized> {
    pub inner: &'a S,
    pub rounds: &'a Rounds,
}

impl<S: Supervisor + ?Sized> Supervisor for WithRounds<'_, S> {
    fn progress(&self, done: u64, total: u64) {
        self.inner.progress(done, total)
    }
    fn cancelled(&self) -> bool {
        self.inner.cancelled()
    }
    fn rounds(&self) -> Option<&Rounds> {
        Some(self.rounds)
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
