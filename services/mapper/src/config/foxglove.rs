//! `[foxglove]`: the fleets live in Foxglove (the `foxglove-feed` crate, started beside the
//! mapper by `levelmap mapper`).

use serde::{Deserialize, Serialize};

/// A Foxglove WebSocket server beside the mapper (docs/foxglove.md): each fleet's grid, its
/// robots' poses and frames and its pose graph, in the fleet's map frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FoxgloveConfig {
    /// Serve it; off by default.
    pub enabled: bool,
    /// Its address. Loopback by default: the Foxglove protocol has no access control, so a
    /// mapper with a read token refuses any other address.
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
