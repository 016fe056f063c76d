//! The one place where job errors become HTTP statuses and JSON bodies
//! (`{"error": {"code", "message", "field"?}}`). 5xx bodies stay generic; details go to logs.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::json;

use crate::error::{ErrorCode, JobError};

pub struct ApiError(pub JobError);

impl From<JobError> for ApiError {
    fn from(error: JobError) -> Self {
        Self(error)
    }
}

pub fn status_of(code: ErrorCode) -> StatusCode {
    match code {
        ErrorCode::InvalidJson | ErrorCode::InvalidParameter => StatusCode::BAD_REQUEST,
        ErrorCode::PayloadTooLarge => StatusCode::PAYLOAD_TOO_LARGE,
        ErrorCode::NotUploaded | ErrorCode::NotFound => StatusCode::NOT_FOUND,
        ErrorCode::PathNotAllowed => StatusCode::FORBIDDEN,
        ErrorCode::InvalidField
        | ErrorCode::UnknownField
        | ErrorCode::UnknownMethod
        | ErrorCode::UnknownBuiltin
        | ErrorCode::InvalidAsset
        | ErrorCode::LimitExceeded
        | ErrorCode::BudgetUnmet
        | ErrorCode::IdempotencyKeyReused => StatusCode::UNPROCESSABLE_ENTITY,
        ErrorCode::QueueFull => StatusCode::TOO_MANY_REQUESTS,
        ErrorCode::DeadlineExceeded | ErrorCode::ShuttingDown | ErrorCode::StoreUnavailable => StatusCode::SERVICE_UNAVAILABLE,
        ErrorCode::InsufficientStorage => StatusCode::INSUFFICIENT_STORAGE,
        ErrorCode::Unauthorized => StatusCode::UNAUTHORIZED,
        ErrorCode::Conflict | ErrorCode::Cancelled => StatusCode::CONFLICT,
        ErrorCode::Internal => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

/// A failed store call as the client's error: 503 while the store is unavailable, 507 when it
/// has no room; anything else is internal (logged, generic towards the client).
pub fn store_error(error: crate::store::StoreError) -> JobError {
    use crate::store::StoreError;
    match error {
        StoreError::Unavailable(detail) => {
            tracing::debug!(%detail, "job store unavailable");
            JobError::new(ErrorCode::StoreUnavailable, "the job store is unavailable; retry after the Retry-After seconds")
        }
        StoreError::Full(detail) => {
            JobError::new(ErrorCode::InsufficientStorage, format!("the job store has no room for this job: {detail}"))
        }
        other => JobError::internal(format!("the job store failed: {other}")),
    }
}

/// The `error` object clients see for `error`: code, message (generic for internal errors,
/// which are logged here in full), field. Shared by error responses and failed-job events.
pub fn error_body(error: &JobError) -> serde_json::Value {
    let message = if error.message_is_public() {
        error.message.clone()
    } else {
        tracing::error!(message = %error.message, "job failed inside the renderer");
        "internal error; the job failed and the server keeps serving".to_owned()
    };
    let mut body = json!({"code": error.code.as_str(), "message": message});
    if let Some(field) = &error.field {
        body["field"] = json!(field);
    }
    body
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let error = self.0;
        let status = status_of(error.code);
        let mut response = (status, Json(json!({ "error": error_body(&error) }))).into_response();
        let retry_after = match error.code {
            // A job takes about a second on lavapipe: try again then.
            ErrorCode::QueueFull => Some("1"),
            // The store is probed every second; a blink is over in a few.
            ErrorCode::StoreUnavailable => Some("2"),
            // Another replica takes the request at once; this one is gone in a few seconds. A
            // job that waited past the deadline met a backlog that drains in seconds too.
            ErrorCode::ShuttingDown | ErrorCode::DeadlineExceeded => Some("5"),
            // The oldest results expire or are dropped within a minute or so.
            ErrorCode::InsufficientStorage => Some("30"),
            _ => None,
        };
        if let Some(seconds) = retry_after {
            response.headers_mut().insert(axum::http::header::RETRY_AFTER, axum::http::HeaderValue::from_static(seconds));
        }
        response
    }
}
