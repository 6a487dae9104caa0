//! The levelmap wire contract (ARCHITECTURE.md): protobuf messages generated from
//! `proto/levelmap/v1/*.proto` (compiled by protox, no system `protoc`), the Zenoh key
//! expressions, and checked conversions between the messages and the `leveling` types.
//!
//! Sending: build a [`v1::Header`] with [`v1::Header::new`], convert with
//! [`leveled_scan_to_wire`], [`odometry_to_wire`], [`pose3d_to_wire`], encode with
//! [`Message::encode_to_vec`], publish on [`node_key`] / [`odom_key`].
//! Receiving: [`decode_node`], [`decode_odometry`] and [`decode_ack`] reject malformed bytes,
//! a missing header, a foreign wire version and out-of-domain numbers with a [`WireError`]
//! naming the field; [`leveled_scan_from_wire`] and [`pose3d_from_wire`] then give the
//! algorithm types. A node may carry its segmented 3D cloud ([`cloud_to_wire`],
//! [`cloud_from_wire`], checked by [`validate_cloud`]). A map version, the mapper's frozen map
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

impl v1::LiveScan {
    /// A node's scan as a live scan: its header, leveled scan, odometry and scan frame.
    pub fn of_node(node: &v1::Node) -> v1::LiveScan {
        v1::LiveScan {
            header: node.header.clone(),
            scan: node.scan.clone(),
            odometry: node.odometry.clone(),
            scan_origin_in_robot: node.scan_origin_in_robot,
        }
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
