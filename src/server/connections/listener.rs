//! The listening socket and its connections: `TrackedListener` accepts under the cap (making
//! room by closing the longest-waiting connection) and hands axum `TrackedStream`s, which note
//! when bytes arrive and fail once the tracker closes them.

use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};

use super::{Conn, Phase, Tracker};

/// A TCP listener whose connections the tracker guards.
pub struct TrackedListener {
    listener: TcpListener,
    tracker: Arc<Tracker>,
}

impl TrackedListener {
    pub fn new(listener: TcpListener, tracker: Arc<Tracker>) -> Self {
        Self { listener, tracker }
    }
}

impl axum::serve::Listener for TrackedListener {
    type Io = TrackedStream;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        loop {
            // At the cap with every connection busy answering: new clients wait in the
            // kernel's backlog until one finishes.
            while !self.tracker.make_room() {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            match self.listener.accept().await {
                Ok((stream, address)) => {
                    let (id, conn) = self.tracker.register();
                    return (TrackedStream { stream, id, conn, tracker: self.tracker.clone() }, address);
                }
                Err(error) if matches!(error.raw_os_error(), Some(libc::EMFILE | libc::ENFILE)) => {
                    // Out of descriptors despite the cap (other files open): shed one, retry.
                    tracing::warn!(%error, "out of file descriptors; closing the longest-waiting connection");
                    self.tracker.shed_one();
                    tokio::time::sleep(Duration::from_millis(20)).await;
                }
                Err(error) => {
                    tracing::debug!(%error, "accept failed");
                    tokio::time::sleep(Duration::from_millis(20)).await;
                }
            }
        }
    }

    fn local_addr(&self) -> io::Result<Self::Addr> {
        self.listener.local_addr()
    }
}

/// A client connection that notes the bytes it reads and fails once closed by the tracker
/// (hyper then drops it, which closes the socket).
pub struct TrackedStream {
    stream: TcpStream,
    id: u64,
    pub(super) conn: Arc<Conn>,
    pub(super) tracker: Arc<Tracker>,
}

fn closed_error() -> io::Error {
    io::Error::new(io::ErrorKind::TimedOut, "connection closed: its client was too slow, or idle, or room was needed")
}

impl AsyncRead for TrackedStream {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        if self.conn.closed.load(Ordering::Acquire) {
            return Poll::Ready(Err(closed_error()));
        }
        let before = buf.filled().len();
        let polled = Pin::new(&mut self.stream).poll_read(cx, buf);
        match &polled {
            Poll::Ready(Ok(())) if buf.filled().len() > before => {
                let now = self.tracker.now_ms();
                self.conn.read_ms.store(now, Ordering::Release);
                if self.conn.phase() == Phase::Idle {
                    self.conn.enter(Phase::Head, now);
                }
            }
            Poll::Pending => {
                let mut waker = self.conn.waker.lock().unwrap_or_else(|p| p.into_inner());
                // Most polls come from the same task: clone its waker only when it changed.
                if !waker.as_ref().is_some_and(|w| w.will_wake(cx.waker())) {
                    *waker = Some(cx.waker().clone());
                }
                drop(waker);
                // Closed between the check above and the waker's registration: not missed.
                if self.conn.closed.load(Ordering::Acquire) {
                    return Poll::Ready(Err(closed_error()));
                }
            }
            _ => {}
        }
        polled
    }
}

impl AsyncWrite for TrackedStream {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        if self.conn.closed.load(Ordering::Acquire) {
            return Poll::Ready(Err(closed_error()));
        }
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_write_vectored(mut self: Pin<&mut Self>, cx: &mut Context<'_>, bufs: &[io::IoSlice<'_>]) -> Poll<io::Result<usize>> {
        if self.conn.closed.load(Ordering::Acquire) {
            return Poll::Ready(Err(closed_error()));
        }
        Pin::new(&mut self.stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

impl Drop for TrackedStream {
    fn drop(&mut self) {
        self.tracker.connections().remove(&self.id);
    }
}
