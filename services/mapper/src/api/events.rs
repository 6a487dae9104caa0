//! The event stream.

use super::Api;
use axum::extract::State;
use axum::response::IntoResponse;
use axum::response::sse::{Event, KeepAlive, Sse};
use tokio::sync::broadcast::error::RecvError;

/// Server-sent events, each one JSON object with a `type`: `node` (a node mapped: fleet,
/// robot, node, node_seq, pose), `optimized` (a fleet's poses changed), `pose` (a robot's
/// live map pose, at most 2 Hz per robot). A subscriber that falls behind skips what it
/// missed. The stream ends when the mapper stops.
#[utoipa::path(get, path = "/api/v1/events", tag = "events", responses(
    (status = 200, description = "Server-sent events, data: one JSON object each", content_type = "text/event-stream", body = String),
))]
pub(super) async fn events(State(api): State<Api>) -> impl IntoResponse {
    let rx = api.shared.events.subscribe();
    let stopping = api.shared.stopping.subscribe();
    let stream =
        futures_util::stream::unfold((rx, stopping), |(mut rx, mut stopping)| async move {
            loop {
                let received = tokio::select! {
                    r = rx.recv() => r,
                    _ = stopping.wait_for(|s| *s) => return None,
                };
                match received {
                    Ok(text) => {
                        let event = Ok::<_, std::convert::Infallible>(Event::default().data(text));
                        return Some((event, (rx, stopping)));
                    }
                    Err(RecvError::Lagged(_)) => continue,
                    Err(RecvError::Closed) => return None,
                }
            }
        });
    Sse::new(stream).keep_alive(KeepAlive::default())
}
