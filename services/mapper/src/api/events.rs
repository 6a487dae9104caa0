//! The event stream.

use super::{Api, Reply};
use axum::extract::State;
use axum::response::IntoResponse;
use axum::response::sse::{Event, KeepAlive, Sse};
use tokio::sync::broadcast::error::RecvError;

/// Server-sent events, each one JSON object with a `type`: `node` (a node mapped: fleet,
/// robot, node, node_seq, pose), `optimized` (a fleet's poses changed), `pose` (a robot's
/// live map pose, at most 2 Hz per robot). A subscriber that falls behind skips what it
/// missed. The stream ends when the mapper stops. At most `[http] event_streams` are open at
/// once; a closed one gives its place back.
#[utoipa::path(get, path = "/api/v1/events", tag = "events", responses(
    (status = 200, description = "Server-sent events, data: one JSON object each", content_type = "text/event-stream", body = String),
    (status = 503, description = "As many streams open as the mapper serves (`[http] event_streams`)", body = String,
        headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
))]
pub(super) async fn events(State(api): State<Api>) -> Reply<impl IntoResponse> {
    let slot = api.limits.stream_slot()?;
    let rx = api.shared.events.subscribe();
    let stopping = api.shared.stopping.subscribe();
    // The slot lives in the stream's state: freed when the stream is dropped (the client
    // went away, or the mapper stops).
    let stream = futures_util::stream::unfold(
        (rx, stopping, slot),
        |(mut rx, mut stopping, slot)| async move {
            loop {
                let received = tokio::select! {
                    r = rx.recv() => r,
                    _ = stopping.wait_for(|s| *s) => return None,
                };
                match received {
                    Ok(text) => {
                        let event = Ok::<_, std::convert::Infallible>(Event::default().data(text));
                        return Some((event, (rx, stopping, slot)));
                    }
                    Err(RecvError::Lagged(_)) => continue,
                    Err(RecvError::Closed) => return None,
                }
            }
        },
    );
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()))
}
