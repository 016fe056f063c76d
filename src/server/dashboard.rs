//! The dashboard at `/`: one static page, its script and style, and Chart.js (MIT, vendored
//! under `dashboard/vendor/`), compiled into the binary so the daemon serves it with no files
//! beside it and no network. The page polls `/v1/stats`; nothing here computes anything.

use axum::extract::Path;
use axum::http::header;
use axum::response::{Html, IntoResponse, Response};

use super::error::ApiError;
use crate::error::{ErrorCode, JobError};

const PAGE: &str = include_str!("../../dashboard/index.html");

/// (name, content type, body) of each asset under `/dashboard/`.
const ASSETS: &[(&str, &str, &str)] = &[
    ("app.js", "text/javascript; charset=utf-8", include_str!("../../dashboard/app.js")),
    ("style.css", "text/css; charset=utf-8", include_str!("../../dashboard/style.css")),
    ("chart.umd.min.js", "text/javascript; charset=utf-8", include_str!("../../dashboard/vendor/chart.umd.min.js")),
];

pub async fn page() -> Html<&'static str> {
    Html(PAGE)
}

pub async fn asset(Path(name): Path<String>) -> Response {
    match ASSETS.iter().find(|(asset, _, _)| *asset == name) {
        // Assets change only with the binary; an hour of caching spares the poll loop nothing
        // but spares reloads the 200 kB of Chart.js.
        Some((_, content_type, body)) => {
            ([(header::CONTENT_TYPE, *content_type), (header::CACHE_CONTROL, "public, max-age=3600")], *body).into_response()
        }
        None => ApiError(JobError::new(ErrorCode::NotFound, format!("no dashboard asset `{name}`"))).into_response(),
    }
}
