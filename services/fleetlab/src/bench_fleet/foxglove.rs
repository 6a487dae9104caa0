//! The bench's Foxglove clients (`--foxglove-clients`): each connects to the mapper's
//! Foxglove feed with the protocol's subprotocol (`foxglove.sdk.v1`), subscribes to every
//! channel as it is advertised (a client that watches everything: the most a client costs)
//! and counts what it receives until the run ends. Each runs on a thread of its own with
//! a runtime of its own, as a viewer in a process of its own would: its reading does not
//! queue on the mapper's async threads.

use anyhow::{Context, Result};
use futures_util::{SinkExt, StreamExt};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;

/// What one client received.
#[derive(Serialize, Default)]
pub(super) struct FoxgloveClient {
    /// Channels it subscribed to.
    channels: usize,
    /// Messages received.
    messages: u64,
    /// Their bytes (the messages, without the frames' headers).
    bytes: u64,
    /// Messages per schema.
    by_schema: BTreeMap<String, u64>,
}

/// A client following the feed at `url` (ws://…) on a thread of its own, until `stop`.
pub(super) fn start(
    url: String,
    no_grid: bool,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Result<FoxgloveClient>> {
    std::thread::spawn(move || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?
            .block_on(follow(url, no_grid, stop))
    })
}

/// Follows the feed at `url` (ws://…) until `stop`; without the grids when `no_grid`.
async fn follow(url: String, no_grid: bool, stop: Arc<AtomicBool>) -> Result<FoxgloveClient> {
    let mut request = url.as_str().into_client_request()?;
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_static("foxglove.sdk.v1"),
    );
    // A grid is one message of up to 8 MiB: no cap on a message's size (the library's is 16 MiB).
    let config = tokio_tungstenite::tungstenite::protocol::WebSocketConfig::default()
        .max_message_size(None)
        .max_frame_size(None);
    let (mut ws, _) = tokio_tungstenite::connect_async_with_config(request, Some(config), false)
        .await
        .with_context(|| format!("{url}: the Foxglove feed"))?;
    let mut got = FoxgloveClient::default();
    let mut schemas: HashMap<u32, String> = HashMap::new();
    while !stop.load(Ordering::SeqCst) {
        let frame = match tokio::time::timeout(Duration::from_millis(200), ws.next()).await {
            Err(_) => continue,
            Ok(None) => break,
            Ok(Some(frame)) => frame?,
        };
        match frame {
            Message::Text(text) => {
                let op: serde_json::Value = serde_json::from_str(&text)?;
                if op["op"] != "advertise" {
                    continue;
                }
                for channel in op["channels"].as_array().into_iter().flatten() {
                    let id = schemas.len() as u32 + 1;
                    let schema = channel["schemaName"].as_str().unwrap_or("").to_owned();
                    if no_grid && schema == "foxglove.Grid" {
                        continue;
                    }
                    schemas.insert(id, schema);
                    let subscribe = serde_json::json!({
                        "op": "subscribe",
                        "subscriptions": [{"id": id, "channelId": channel["id"]}],
                    });
                    ws.send(Message::Text(subscribe.to_string().into())).await?;
                    got.channels += 1;
                }
            }
            // Opcode 1 (message data): a u32 subscription id, a u64 log time, the message.
            Message::Binary(b) if b.len() >= 13 && b[0] == 1 => {
                let id = u32::from_le_bytes([b[1], b[2], b[3], b[4]]);
                got.messages += 1;
                got.bytes += (b.len() - 13) as u64;
                let schema = schemas.get(&id).cloned().unwrap_or_default();
                *got.by_schema.entry(schema).or_default() += 1;
            }
            _ => {}
        }
    }
    ws.close(None).await.ok();
    Ok(got)
}
