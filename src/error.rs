//! Job errors: the one error type that crosses module boundaries on the way to a client.
//!
//! Every error carries a stable machine-readable `code`, a human message and, for bad
//! input, the offending `field` as a dotted path (`camera.fov_y_deg`). HTTP status codes are
//! assigned in exactly one place (`server::error`), never here.

use std::fmt;

/// What went wrong, as a stable code clients can switch on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorCode {
    /// The body is not JSON, or not the JSON shape a job has.
    InvalidJson,
    /// A field has the wrong type or a value outside its documented range.
    InvalidField,
    /// A field the contract does not know (including method parameters).
    UnknownField,
    /// `method.name` names no registered method.
    UnknownMethod,
    /// A built-in scene or light image that does not exist.
    UnknownBuiltin,
    /// A scene or light image id the server does not hold (upload it again).
    NotUploaded,
    /// A `{"path": ...}` the caller may not read, or that does not exist.
    PathNotAllowed,
    /// A scene or image file that could not be decoded.
    InvalidAsset,
    /// The request exceeds a configured limit (size, pixels, triangles ...).
    LimitExceeded,
    /// An `auto` job's budget that no method is predicted to meet on this device; the message
    /// names the closest method and its prediction.
    BudgetUnmet,
    /// The request body exceeds the configured size limit.
    PayloadTooLarge,
    /// A request header or query parameter (`Idempotency-Key`, a listing's `cursor`) is
    /// malformed or too long; the `field` names it.
    InvalidParameter,
    /// An `Idempotency-Key` already names a job submitted with another body.
    IdempotencyKeyReused,
    /// No such job, result or route.
    NotFound,
    /// The job queue is full: retry after the `Retry-After` seconds.
    QueueFull,
    /// The job waited in the queue past the configured deadline without starting.
    DeadlineExceeded,
    /// The daemon is shutting down and admits no new job: retry on another replica, or later.
    ShuttingDown,
    /// The job store does not answer (Redis down, the data directory failing): retry after
    /// the `Retry-After` seconds.
    StoreUnavailable,
    /// The job store has no room for this job's result (its disk is at the free-space margin).
    InsufficientStorage,
    /// No valid bearer token on a server that requires one.
    Unauthorized,
    /// The request conflicts with the resource's state (cancelling a finished job).
    Conflict,
    /// The job was cancelled (its client went away, or `DELETE /v1/jobs/{id}`).
    Cancelled,
    /// Something failed inside the renderer; the message is generic towards clients.
    Internal,
}

impl ErrorCode {
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorCode::InvalidJson => "invalid_json",
            ErrorCode::InvalidField => "invalid_field",
            ErrorCode::UnknownField => "unknown_field",
            ErrorCode::UnknownMethod => "unknown_method",
            ErrorCode::UnknownBuiltin => "unknown_builtin",
            ErrorCode::NotUploaded => "not_uploaded",
            ErrorCode::PathNotAllowed => "path_not_allowed",
            ErrorCode::InvalidAsset => "invalid_asset",
            ErrorCode::LimitExceeded => "limit_exceeded",
            ErrorCode::BudgetUnmet => "budget_unmet",
            ErrorCode::PayloadTooLarge => "payload_too_large",
            ErrorCode::InvalidParameter => "invalid_parameter",
            ErrorCode::IdempotencyKeyReused => "idempotency_key_reused",
            ErrorCode::NotFound => "not_found",
            ErrorCode::QueueFull => "queue_full",
            ErrorCode::DeadlineExceeded => "deadline_exceeded",
            ErrorCode::ShuttingDown => "shutting_down",
            ErrorCode::StoreUnavailable => "store_unavailable",
            ErrorCode::InsufficientStorage => "insufficient_storage",
            ErrorCode::Unauthorized => "unauthorized",
            ErrorCode::Conflict => "conflict",
            ErrorCode::Cancelled => "cancelled",
            ErrorCode::Internal => "internal",
        }
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An error in a job, reported to the client that sent it and to no one else.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{code}: {message}{}", field.as_ref().map(|f| format!(" (field `{f}`)")).unwrap_or_default())]
pub struct JobError {
    pub code: ErrorCode,
    pub message: String,
    pub field: Option<String>,
}

impl JobError {
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        Self { code, message: message.into(), field: None }
    }

    /// An error about one field, named by its dotted path.
    pub fn field(code: ErrorCode, field: impl Into<String>, message: impl Into<String>) -> Self {
        Self { code, message: message.into(), field: Some(field.into()) }
    }

    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::field(ErrorCode::InvalidField, field, message)
    }

    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(ErrorCode::Internal, message)
    }

    /// Whether the message may be shown to the client as it is: every error but a failure
    /// inside the renderer, whose details stay in the logs.
    pub fn message_is_public(&self) -> bool {
        self.code != ErrorCode::Internal
    }
}

pub type JobResult<T> = Result<T, JobError>;
