//! The levelmap wire contract (ARCHITECTURE.md): protobuf messages generated from
//! `proto/levelmap/v1/*.proto` (compiled by protox, no system `protoc`), the Zenoh key
//! expressions, and checked conversions between the messages and the `leveling` types.
//!
//! A node has one form past this crate: [`Node`], made from its [`NodeParts`] by
//! [`Node::new`] (the robot's node builder) or by [`decode_node`] (the mapper's subscriber),
//! both checked by the same rules ([`validate_node`]), and encoded once, at the robot's outbox
//! ([`NodeParts::encode`]); each send appends its send fields to that encoding
//! ([`node_as_sent`]), and the mapper splits the cloud from it without re-encoding
//! ([`split_node_cloud`]). Live scans and odometry go the same way ([`LiveScan`],
//! [`encode_odometry`], [`decode_odometry`]). Decoding rejects malformed bytes, a missing
//! header, a foreign wire version and out-of-domain numbers with a [`WireError`] naming the
//! field. A node may carry its segmented 3D cloud ([`ClassifiedCloud`]). A map version, the mapper's frozen map
//! as one file, is written by [`encode_map_version_file`] and read back, checked, by
//! [`decode_map_version_file`].

mod convert;
mod error;
mod keys;

/// Types generated from `proto/levelmap/v1` (package `levelmap.v1`). Their docs are the
/// `.proto` comments; a field the contract leaves uncommented is named for what it holds.
#[allow(missing_docs)]
pub mod v1 {
    include!(concat!(env!("OUT_DIR"), "/levelmap.v1.rs"));
}

pub use convert::*;
pub use error::{MAX_NODE_BYTES, MAX_POSITION_M, MAX_RANGE_M, MAX_SPEED_M_PER_S, WireError};
pub use keys::{
    KEY_ROOT, RobotKey, Topic, ack_key, all_robots_key_expr, localization_key, map_key,
    map_key_expr, message_name_of_key, node_key, odom_key, parse_robot_key, robot_key, scan_key,
    validate_id,
};
/// Re-exported so users can encode and decode without depending on prost themselves.
pub use prost::Message;

/// Every file of `proto/levelmap/v1` and its imports as an encoded protobuf
/// `FileDescriptorSet` (without comments): the schema data of a recording's channels, which
/// tools such as Foxglove decode the messages with ([`message_name_of_key`] names the type).
pub const DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/levelmap.fds"));

/// The wire version every [`v1::Header`] carries; receivers reject any other.
pub const WIRE_VERSION: u32 = 1;

impl v1::Node {
    /// Every header the node holds: its own, its scan's, its odometry's and its fixes'.
    pub fn headers_mut(&mut self) -> impl Iterator<Item = &mut v1::Header> {
        [
            self.header.as_mut(),
            self.scan.as_mut().and_then(|s| s.header.as_mut()),
            self.odometry.as_mut().and_then(|o| o.header.as_mut()),
        ]
        .into_iter()
        .flatten()
        .chain(
            self.gps
                .iter_mut()
                .chain(self.earlier_gps.iter_mut())
                .filter_map(|g| g.header.as_mut()),
        )
    }
}

impl v1::Header {
    /// A header of the current [`WIRE_VERSION`]. `seq` counts publications per robot and topic;
    /// `stamp_ns` is the measurement time and `sent_ns` the publication time (ns since the
    /// Unix epoch).
    pub fn new(
        fleet_id: impl Into<String>,
        robot_id: impl Into<String>,
        seq: u64,
        stamp_ns: u64,
        sent_ns: u64,
    ) -> v1::Header {
        v1::Header {
            version: WIRE_VERSION,
            fleet_id: fleet_id.into(),
            robot_id: robot_id.into(),
            seq,
            stamp_ns,
            sent_ns,
        }
    }
}
