//! Lingering close of request bodies, as nginx's `lingering_close`: what an answer leaves of its
//! request's body unread (a 413 past the body limit, a 415, a 429, a 404 with a body) is read and
//! dropped before the answer goes out, so that a client that writes its whole body before it
//! reads (Python's `urllib.request`, for one) reads the answer. Without it the server answers
//! and closes while that client is still writing: the close of a socket with unread data resets
//! the connection, and the client sees a broken pipe or a reset instead of the answer.
//!
//! Bounded in bytes and time: at most [`LINGER_FACTOR`] times the body limit and
//! [`LINGER_TIME`]. Past either bound the answer goes out as it is and the connection closes;
//! when `Content-Length` already declares more than the byte bound nothing is read. The body of
//! a request that sent `Expect: 100-continue` is drained only if the handler began to read it
//! (the server has then sent `100 Continue`, and the client sends the body); otherwise its
//! client waits for the answer without sending the body, and reading would ask for it. A body
//! that stopped arriving (answered `body_timeout`) is not drained.

use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll};
use std::time::Duration;

use super::error::ErrorCode;
use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::http::{HeaderMap, header};
use axum::middleware::Next;
use axum::response::Response;
use http_body::{Frame, SizeHint};
use http_body_util::BodyExt;

/// A request body is drained up to this many times the body limit (bytes read after the answer
/// was decided).
pub const LINGER_FACTOR: usize = 4;

/// The longest a request body is drained.
pub const LINGER_TIME: Duration = Duration::from_secs(5);

/// Middleware (state: the body limit): runs the request, then drains what the handler left of
/// its body, within the bounds, before it returns the answer.
pub async fn linger(State(body_limit): State<usize>, req: Request, next: Next) -> Response {
    let cap = body_limit.saturating_mul(LINGER_FACTOR);
    if content_length(req.headers()).is_some_and(|n| n > cap) {
        return next.run(req).await;
    }
    let expects = expects_continue(req.headers());
    let (parts, body) = req.into_parts();
    let unread = Arc::new(Mutex::new(None));
    let body = Body::new(Watched {
        inner: Some(body),
        asked: !expects,
        unread: unread.clone(),
    });
    let response = next.run(Request::from_parts(parts, body)).await;
    if response.extensions().get::<ErrorCode>() == Some(&ErrorCode::BodyTimeout) {
        // The client stopped sending: nothing would arrive to drain.
        return response;
    }
    let rest = unread.lock().unwrap_or_else(PoisonError::into_inner).take();
    if let Some(rest) = rest {
        drain(rest, cap).await;
    }
    response
}

/// Reads and drops up to `cap` bytes of `body`, for at most [`LINGER_TIME`].
async fn drain(mut body: Body, cap: usize) {
    let read = async {
        let mut seen = 0usize;
        while let Some(Ok(frame)) = body.frame().await {
            seen += frame.data_ref().map_or(0, Bytes::len);
            if seen > cap {
                break;
            }
        }
    };
    let _ = tokio::time::timeout(LINGER_TIME, read).await;
}

fn expects_continue(headers: &HeaderMap) -> bool {
    headers
        .get(header::EXPECT)
        .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"100-continue"))
}

fn content_length(headers: &HeaderMap) -> Option<usize> {
    headers
        .get(header::CONTENT_LENGTH)?
        .to_str()
        .ok()?
        .trim()
        .parse()
        .ok()
}

/// A request body that, dropped before its end, leaves the rest in `unread` if the client was
/// asked for it.
struct Watched {
    /// `None` once the body ended or failed.
    inner: Option<Body>,
    /// Whether the client sends the body: it did not wait for `100 Continue`, or the body was
    /// polled (which sends `100 Continue`).
    asked: bool,
    unread: Arc<Mutex<Option<Body>>>,
}

impl HttpBody for Watched {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        let this = self.get_mut();
        this.asked = true;
        let Some(inner) = this.inner.as_mut() else {
            return Poll::Ready(None);
        };
        let polled = Pin::new(inner).poll_frame(cx);
        if matches!(polled, Poll::Ready(None | Some(Err(_)))) {
            this.inner = None;
        }
        polled
    }

    fn is_end_stream(&self) -> bool {
        self.inner.as_ref().is_none_or(Body::is_end_stream)
    }

    fn size_hint(&self) -> SizeHint {
        self.inner
            .as_ref()
            .map_or_else(|| SizeHint::with_exact(0), Body::size_hint)
    }
}

impl Drop for Watched {
    fn drop(&mut self) {
        if let Some(inner) = self.inner.take()
            && self.asked
            && !inner.is_end_stream()
        {
            *self.unread.lock().unwrap_or_else(PoisonError::into_inner) = Some(inner);
        }
    }
}
