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
        ErrorCode::InvalidJson => StatusCode::BAD_REQUEST,
        ErrorCode::PayloadTooLarge => StatusCode::PAYLOAD_TOO_LARGE,
        ErrorCode::NotUploaded | ErrorCode::NotFound => StatusCode::NOT_FOUND,
        ErrorCode::PathNotAllowed => StatusCode::FORBIDDEN,
        ErrorCode::InvalidField
        | ErrorCode::UnknownField
        | ErrorCode::UnknownMethod
        | ErrorCode::UnknownBuiltin
        | ErrorCode::InvalidAsset
        | ErrorCode::LimitExceeded => StatusCode::UNPROCESSABLE_ENTITY,
        ErrorCode::QueueFull => StatusCode::TOO_MANY_REQUESTS,
        ErrorCode::DeadlineExceeded | ErrorCode::ShuttingDown => StatusCode::SERVICE_UNAVAILABLE,
        ErrorCode::Unauthorized => StatusCode::UNAUTHORIZED,
        ErrorCode::Conflict | ErrorCode::Cancelled => StatusCode::CONFLICT,
        ErrorCode::Internal => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

/// The `error` object clients see for `error`: code, message (generic for internal errors,
/// which are logged here in full), field. Shared by error responses and failed-job events.
pub fn error_body(error: &JobError) -> serde_json::Value {
    let message = if error.is_client_error() {
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
        if error.code == ErrorCode::QueueFull {
            // A job takes about a second on lavapipe: try again then.
            response.headers_mut().insert(axum::http::header::RETRY_AFTER, axum::http::HeaderValue::from_static("1"));
        }
        response
    }
}
