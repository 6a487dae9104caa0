//! One robot's live feed ([`crate::views::live`]) as a WebSocket or as server-sent events.

use super::{Api, ApiError, Reply};
use crate::views::live::LiveSample;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{FromRequestParts, Path, Request, State};
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use runtime::session::now_ns;
use serde_json::json;
use std::sync::Arc;
use tokio::sync::watch;

/// What one subscriber gets next: the newest sample, as JSON, with the scan only when it is
/// one the subscriber has not had. `None` when the feed or the mapper ends.
struct Follower {
    fleet: String,
    robot: String,
    feed: watch::Receiver<Option<Arc<LiveSample>>>,
    stopping: watch::Receiver<bool>,
    last_scan: u64,
}

impl Follower {
    async fn next(&mut self) -> Option<String> {
        loop {
            tokio::select! {
                changed = self.feed.changed() => changed.ok()?,
                _ = self.stopping.wait_for(|s| *s) => return None,
            }
            let Some(sample) = self.feed.borrow_and_update().clone() else {
                continue;
            };
            let mut message = json!({
                "type": "live",
                "fleet": self.fleet,
                "robot": self.robot,
                "sent_ns": now_ns(),
            });
            let fields = serde_json::to_value(sample.as_ref()).expect("serializes");
            message
                .as_object_mut()
                .expect("an object")
                .extend(fields.as_object().expect("an object").clone());
            if let Some(scan) = sample.scan.as_ref().filter(|s| s.seq != self.last_scan) {
                self.last_scan = scan.seq;
                message["scan"] = serde_json::to_value(scan.as_ref()).expect("serializes");
            }
            return Some(message.to_string());
        }
    }
}

/// A robot's live feed at its odometry rate: its map pose (the last solve's correction
/// applied to live odometry), odometry, speed and the correction's age, and its newest live
/// leveled scan (`scan`, once per scan: bearings and ranges in the scan's frame, that frame in
/// the robot's and in the map). A WebSocket when the request asks for one (text messages),
/// server-sent events otherwise; one JSON object each, `type` `live`. A subscriber that reads
/// slowly gets the newest sample, never a queue. Counts among `[http] event_streams`.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/robots/{robot}/live", tag = "fleets",
    params(("fleet" = String, Path, description = "Fleet id"), ("robot" = String, Path, description = "Robot id")),
    responses(
        (status = 200, description = "Server-sent events, data: one JSON object each (`type`: `live`)", content_type = "text/event-stream", body = String),
        (status = 101, description = "WebSocket (Upgrade: websocket): one JSON text message per sample"),
        (status = 404, description = "No such fleet, or no odometry from the robot yet", body = String),
        (status = 503, description = "As many streams open as the mapper serves (`[http] event_streams`)", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn live(
    State(api): State<Api>,
    Path((fleet, robot)): Path<(String, String)>,
    request: Request,
) -> Reply<Response> {
    api.view(&fleet)?;
    let feed = api
        .shared
        .live_feeds
        .subscribe(&fleet, &robot)
        .ok_or_else(|| {
            ApiError::NotFound(format!("no odometry from robot {robot} of {fleet} yet"))
        })?;
    let slot = api.limits.stream_slot()?;
    let mut follower = Follower {
        fleet,
        robot,
        feed,
        stopping: api.shared.stopping.subscribe(),
        last_scan: 0,
    };
    // The newest sample goes out at once.
    follower.feed.mark_changed();
    let wants_socket = request
        .headers()
        .get(header::UPGRADE)
        .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"websocket"));
    if wants_socket {
        let (mut parts, _) = request.into_parts();
        let upgrade = WebSocketUpgrade::from_request_parts(&mut parts, &())
            .await
            .map_err(|e| ApiError::BadRequest(e.to_string()))?;
        return Ok(upgrade.on_upgrade(move |socket| async move {
            let _slot = slot;
            follow_on_socket(follower, socket).await;
        }));
    }
    let stream = futures_util::stream::unfold((follower, slot), |(mut f, slot)| async move {
        let text = f.next().await?;
        Some((
            Ok::<_, std::convert::Infallible>(Event::default().data(text)),
            (f, slot),
        ))
    });
    Ok(Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response())
}

async fn follow_on_socket(mut follower: Follower, mut socket: WebSocket) {
    loop {
        tokio::select! {
            next = follower.next() => {
                let Some(text) = next else { break };
                if socket.send(Message::Text(text.into())).await.is_err() {
                    break;
                }
            }
            // The client's messages are not used; its close ends the feed.
            received = socket.recv() => match received {
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => {}
            },
        }
    }
    let _ = socket.send(Message::Close(None)).await;
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam::Pose2;

    fn sample(stamp_ns: u64) -> Option<Arc<LiveSample>> {
        Some(Arc::new(LiveSample {
            stamp_ns,
            received_ns: stamp_ns,
            pose: None,
            odometry: Pose2::IDENTITY,
            speed_m_s: 0.0,
            correction_age_ms: None,
            scan: None,
        }))
    }

    #[tokio::test]
    async fn a_follower_that_fell_behind_gets_the_newest_sample_only() {
        let (tx, feed) = watch::channel(None);
        let (_stop, stopping) = watch::channel(false);
        let mut follower = Follower {
            fleet: "park".into(),
            robot: "r".into(),
            feed,
            stopping,
            last_scan: 0,
        };
        for stamp in 1..=1000 {
            tx.send_replace(sample(stamp));
        }
        let next: serde_json::Value =
            serde_json::from_str(&follower.next().await.unwrap()).unwrap();
        assert_eq!(next["stamp_ns"], 1000);
        tx.send_replace(sample(1001));
        let next: serde_json::Value =
            serde_json::from_str(&follower.next().await.unwrap()).unwrap();
        assert_eq!(next["stamp_ns"], 1001);
    }
}
