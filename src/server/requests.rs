//! Every request's id, its access-log line and, for clients that ask, its errors as problem
//! details (contract §3 "Requests"). The id is the client's `x-request-id` when well formed,
//! else the trace id of a valid W3C `traceparent`, else a new one; it is echoed on every
//! answer, carried by the request's span (so every log line of the request, and of the job it
//! submits, names it) and kept in a submitted job's record. Malformed ids are replaced, never
//! logged or stored as they came.

use std::sync::{Arc, OnceLock};
use std::time::Instant;

use axum::extract::{MatchedPath, Request, State};
use axum::http::{header, HeaderMap, HeaderValue};
use axum::middleware::Next;
use axum::response::Response;
use http_body::Body as _;
use serde_json::{json, Value};
use tracing::Instrument as _;

/// The header that carries a request's id, both ways.
pub const REQUEST_ID: &str = "x-request-id";

/// The media type of RFC 9457 problem details.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// Longest request id taken from a client.
const MAX_REQUEST_ID: usize = 64;

/// Largest error body rewritten as problem details (error bodies are a few hundred bytes).
const MAX_ERROR_BODY: usize = 64 << 10;

/// The route template a request matched (`/v1/jobs/{id}`), filled in by `note_route` once
/// routing is done, read by the access log: templates, not paths, so a log line's length
/// and the set of routes stay bounded whatever the client sends.
#[derive(Clone, Default)]
struct RouteSlot(Arc<OnceLock<String>>);

/// An id a client may name its request with: 1 to 64 of `[A-Za-z0-9._:-]`.
fn well_formed_id(value: &str) -> bool {
    (1..=MAX_REQUEST_ID).contains(&value.len()) && value.bytes().all(|b| b.is_ascii_alphanumeric() || b"._:-".contains(&b))
}

/// The trace id of a valid W3C `traceparent` (`00-<32 hex>-<16 hex>-<2 hex>`, ids not all
/// zeros, version not `ff`); a later version may append fields after a dash.
fn trace_id(traceparent: &str) -> Option<&str> {
    let mut parts = traceparent.splitn(5, '-');
    let (version, trace, parent, flags) = (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
    let hex = |s: &str, n: usize| s.len() == n && s.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b));
    let zeros = |s: &str| s.bytes().all(|b| b == b'0');
    let valid = hex(version, 2) && version != "ff" && hex(trace, 32) && hex(parent, 16) && hex(flags, 2) && !zeros(trace) && !zeros(parent);
    let closed = version != "00" || parts.next().is_none();
    (valid && closed).then_some(trace)
}

/// The id of a request: its `x-request-id` if well formed, else its `traceparent`'s trace id,
/// else a new random one.
pub fn request_id_of(headers: &HeaderMap) -> String {
    let header = |name: &str| headers.get(name).and_then(|v| v.to_str().ok());
    if let Some(id) = header(REQUEST_ID).filter(|id| well_formed_id(id)) {
        return id.to_owned();
    }
    if let Some(trace) = header("traceparent").and_then(trace_id) {
        return trace.to_owned();
    }
    uuid::Uuid::new_v4().simple().to_string()
}

/// Whether the client asked for problem details (`Accept: application/problem+json`).
fn wants_problem(headers: &HeaderMap) -> bool {
    let accept = headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()).unwrap_or("");
    accept.split(',').any(|t| t.trim().starts_with(PROBLEM_JSON))
}

/// Middleware, outermost: names the request, runs it in its span, echoes the id, rewrites an
/// error as problem details when asked, counts it by route and status, and writes the
/// access-log line.
pub async fn track(State(state): State<Arc<super::AppState>>, mut request: Request, next: Next) -> Response {
    let started = Instant::now();
    let id = request_id_of(request.headers());
    let problem = wants_problem(request.headers());
    // A method is a token of any length: the log keeps its first 16 characters.
    let method: String = request.method().as_str().chars().take(16).collect();
    let route = RouteSlot::default();
    // Handlers that keep the id (`POST /v1/jobs`) read it where the client would send it.
    if let Ok(value) = HeaderValue::from_str(&id) {
        request.headers_mut().insert(REQUEST_ID, value);
    }
    request.extensions_mut().insert(route.clone());
    let span = tracing::info_span!("request", request_id = %id);
    let mut response = next.run(request).instrument(span.clone()).await;
    if problem && (response.status().is_client_error() || response.status().is_server_error()) {
        response = as_problem(response, &id).await;
    }
    if let Ok(value) = HeaderValue::from_str(&id) {
        response.headers_mut().insert(REQUEST_ID, value);
    }
    let bytes = response.body().size_hint().exact();
    let route = route.0.get().map_or("(no route)", String::as_str);
    state.metrics.request_answered(route, response.status().as_u16(), started.elapsed().as_secs_f64());
    span.in_scope(|| {
        tracing::info!(
            target: "penumbra::access",
            method,
            route,
            status = response.status().as_u16(),
            bytes = bytes.map_or_else(|| "-".to_owned(), |b| b.to_string()),
            duration_ms = (started.elapsed().as_secs_f64() * 1000.0 * 1000.0).round() / 1000.0,
            "request"
        )
    });
    response
}

/// Route middleware: notes the template the request matched for the access log.
pub async fn note_route(request: Request, next: Next) -> Response {
    if let (Some(slot), Some(path)) = (request.extensions().get::<RouteSlot>(), request.extensions().get::<MatchedPath>()) {
        slot.0.set(path.as_str().to_owned()).ok();
    }
    next.run(request).await
}

/// An error answer (`{"error": {code, message, field?}}`) as RFC 9457 problem details:
/// `type` (a URN per code), `title`, `status`, `detail`, and `code`, `field`, `request_id`.
/// Answers that are not such a body (a HEAD's empty one) stay as they are.
async fn as_problem(response: Response, request_id: &str) -> Response {
    let is_json = response.headers().get(header::CONTENT_TYPE).is_some_and(|v| v.as_bytes().starts_with(b"application/json"));
    if !is_json {
        return response;
    }
    let (mut parts, body) = response.into_parts();
    let Ok(bytes) = axum::body::to_bytes(body, MAX_ERROR_BODY).await else {
        return Response::from_parts(parts, axum::body::Body::empty());
    };
    let Some(error) = serde_json::from_slice::<Value>(&bytes).ok().and_then(|v| v.get("error").cloned()) else {
        return Response::from_parts(parts, axum::body::Body::from(bytes));
    };
    let status = parts.status;
    let code = error["code"].as_str().unwrap_or("internal");
    let mut problem = json!({
        "type": format!("urn:penumbra:error:{code}"),
        "title": status.canonical_reason().unwrap_or("Error"),
        "status": status.as_u16(),
        "detail": error["message"],
        "code": code,
        "request_id": request_id,
    });
    if let Some(field) = error.get("field") {
        problem["field"] = field.clone();
    }
    let body = serde_json::to_vec(&problem).expect("a Value serializes");
    parts.headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
    parts.headers.remove(header::CONTENT_LENGTH);
    Response::from_parts(parts, axum::body::Body::from(body))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_named_by_its_id_its_trace_or_a_new_id() {
        let headers = |pairs: &[(&'static str, &str)]| {
            let mut map = HeaderMap::new();
            for (name, value) in pairs {
                map.insert(*name, HeaderValue::from_str(value).unwrap());
            }
            map
        };
        let trace = "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01";
        assert_eq!(request_id_of(&headers(&[(REQUEST_ID, "build-42.a:b_c")])), "build-42.a:b_c");
        assert_eq!(request_id_of(&headers(&[("traceparent", trace)])), "4bf92f3577b34da6a3ce929d0e0e4736");
        // A malformed id gives way to the trace; a malformed trace to a new id.
        assert_eq!(request_id_of(&headers(&[(REQUEST_ID, "has space"), ("traceparent", trace)])), "4bf92f3577b34da6a3ce929d0e0e4736");
        for bad in [
            "00-00000000000000000000000000000000-00f067aa0ba902b7-01",
            "00-4bf92f3577b34da6a3ce929d0e0e4736-0000000000000000-01",
            "ff-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01",
            "00-4BF92F3577B34DA6A3CE929D0E0E4736-00f067aa0ba902b7-01",
            "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01-extra",
            "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7",
        ] {
            let id = request_id_of(&headers(&[("traceparent", bad), (REQUEST_ID, &"x".repeat(65))]));
            assert!(id.len() == 32 && id != "4bf92f3577b34da6a3ce929d0e0e4736", "{bad} gave {id}");
        }
        assert_eq!(trace_id("01-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01-future"), Some("4bf92f3577b34da6a3ce929d0e0e4736"));
    }
}
