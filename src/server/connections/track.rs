//! The `track` middleware: notes on each request's connection when its body has been read
//! (`Body` → `Busy`) and when its answer is sent (`Busy` → `Idle`), so that the sweeper times
//! out only clients that keep the daemon waiting, never one waiting for its render.

use std::pin::Pin;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::task::{Context, Poll};

use axum::body::Body;
use axum::extract::connect_info::Connected;
use axum::extract::{ConnectInfo, Request};
use axum::middleware::Next;
use axum::response::Response;
use axum::serve::IncomingStream;
use http_body::Body as _;

use super::{Conn, Phase, TrackedListener, Tracker};

/// The connection a request arrived on, for the `track` middleware (axum's connect info).
#[derive(Clone)]
pub struct ConnRef(Arc<Conn>, Arc<Tracker>);

impl Connected<IncomingStream<'_, TrackedListener>> for ConnRef {
    fn connect_info(stream: IncomingStream<'_, TrackedListener>) -> Self {
        let io = stream.io();
        Self(io.conn.clone(), io.tracker.clone())
    }
}

/// Notes a request's progress on its connection: `Body` until its body is read, then `Busy`
/// until its answer is sent, then `Idle`. Requests without a tracked connection (the router
/// driven directly, in tests) pass untouched.
pub async fn track(request: Request, next: Next) -> Response {
    let Some(ConnectInfo(ConnRef(conn, tracker))) = request.extensions().get::<ConnectInfo<ConnRef>>().cloned() else {
        return next.run(request).await;
    };
    let now = tracker.now_ms();
    let (parts, body) = request.into_parts();
    let body = if body.is_end_stream() {
        conn.enter(Phase::Busy, now);
        body
    } else {
        conn.enter(Phase::Body, now);
        conn.read_ms.store(now, Ordering::Release);
        Body::new(TrackedBody { body, conn: Some(conn.clone()), tracker: tracker.clone() })
    };
    let response = next.run(Request::from_parts(parts, body)).await;
    // A handler may answer without reading the body (a refusal): the answer is what remains.
    conn.enter(Phase::Busy, tracker.now_ms());
    response.map(|body| Body::new(AnswerBody { body, conn, tracker }))
}

/// A request body that marks its connection `Busy` once it is read to the end.
struct TrackedBody {
    body: Body,
    conn: Option<Arc<Conn>>,
    tracker: Arc<Tracker>,
}

impl http_body::Body for TrackedBody {
    type Data = axum::body::Bytes;
    type Error = axum::Error;

    fn poll_frame(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        let polled = Pin::new(&mut self.body).poll_frame(cx);
        if matches!(polled, Poll::Ready(None)) || self.body.is_end_stream() {
            if let Some(conn) = self.conn.take() {
                conn.enter(Phase::Busy, self.tracker.now_ms());
            }
        }
        polled
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.body.size_hint()
    }
}

/// A response body that marks its connection `Idle` (kept alive) once sent or dropped.
struct AnswerBody {
    body: Body,
    conn: Arc<Conn>,
    tracker: Arc<Tracker>,
}

impl http_body::Body for AnswerBody {
    type Data = axum::body::Bytes;
    type Error = axum::Error;

    fn poll_frame(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.body.size_hint()
    }
}

impl Drop for AnswerBody {
    fn drop(&mut self) {
        self.conn.answered.store(true, Ordering::Release);
        self.conn.enter(Phase::Idle, self.tracker.now_ms());
    }
}
