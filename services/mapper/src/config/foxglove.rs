//! `[foxglove]`: the fleets live in Foxglove (the `foxglove-feed` crate, started beside the
//! mapper by `levelmap mapper`).

use serde::{Deserialize, Serialize};

/// A Foxglove WebSocket server beside the mapper (docs/foxglove.md): each fleet's grid, pose
/// graph, robots' poses and frames, and new nodes' scans, clouds and GPS fixes, in the
/// fleet's map frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FoxgloveConfig {
    /// Serve it; off by default.
    pub enabled: bool,
    /// Its address; loopback by default. With a read token, a connection there needs the
    /// read or write token (`?token=` or a bearer header: the feed's token front).
    pub listen: String,
    /// The robots' poses and frames go out this often (ms).
    pub poses_every_ms: u64,
    /// A fleet's grid and graph go out at most this often (ms), when its map changed and a
    /// client subscribes (a grid is made from every node's scan).
    pub map_every_ms: u64,
}

impl Default for FoxgloveConfig {
    fn default() -> Self {
        FoxgloveConfig {
            enabled: false,
            listen: "127.0.0.1:8765".into(),
            poses_every_ms: 100,
            map_every_ms: 2000,
        }
    }
}
