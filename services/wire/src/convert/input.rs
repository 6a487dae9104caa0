//! Received messages as domain types: what the mapping takes, parsed once at the edge of the
//! mapper so that nothing past it sees a protobuf message.

use super::gps::gps_fix_from_wire;
use super::node::{decode_odometry, validate_node};
use super::odometry::odometry_from_wire;
use super::pose::pose2_from_wire;
use super::scan::{counts_from_wire, leveled_scan_from_wire};
use crate::{MAX_NODE_BYTES, MAX_SPEED_M_PER_S, WireError, v1};
use leveling::{ClassCounts, LeveledScan, TimedPose};
use slam::Pose2;
use slam::gnss::GpsFix;

/// One node of a robot, checked: a leveled scan with its odometry and the GPS fixes carried
/// to it (see `node.proto`). The segmented cloud, stored apart, is not part of it.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeInput {
    /// The sender's fleet.
    pub fleet: String,
    /// The sender's robot.
    pub robot: String,
    /// The node's number in its chain.
    pub node_seq: u64,
    /// The robot's chain (`Node.chain_id`; 0 from senders before chains).
    pub chain_id: u64,
    /// The lowest node_seq of the chain the robot still held when it sent this one.
    pub held_from_seq: u64,
    /// The scan's start (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// The leveled scan.
    pub scan: LeveledScan,
    /// The scan's points per class, when the robot sent them.
    pub counts: Option<ClassCounts>,
    /// Dead reckoning at the scan's start (odometry frame, 3D: its attitude levels the GPS
    /// lever arm).
    pub odometry: TimedPose,
    /// The scan's frame in the robot's planar frame.
    pub scan_origin: Pose2,
    /// Every fix since the previous node, oldest first (`earlier_gps`, then `gps`).
    pub gps: Vec<GpsFix>,
}

impl NodeInput {
    /// The leveled scan as bearings (rad) and ranges (m, 0 = no return), as it came.
    pub fn polar(&self) -> (Vec<f32>, Vec<f32>) {
        self.scan
            .beams
            .iter()
            .map(|b| (b.bearing_rad, b.range_m.unwrap_or(0.0)))
            .unzip()
    }
}

/// Checks that a node at `next` (stamp in ns, odometry x and y in m) can follow one at
/// `previous` in one chain: a later stamp, and a step no faster than [`MAX_SPEED_M_PER_S`]
/// (plus a robot's length, so a node after a long stop is not fast). The edge runs it before
/// it commits a node (a failing step starts a new chain: an odometry reset), the mapper
/// before it takes one.
pub fn check_step(previous: (u64, [f64; 2]), next: (u64, [f64; 2])) -> Result<(), WireError> {
    let ((t0, [x0, y0]), (t1, [x1, y1])) = (previous, next);
    if t1 <= t0 {
        return Err(WireError::InvalidValue {
            field: "Node.header.stamp_ns",
            index: None,
            value: t1 as f64,
            problem: "not after the previous node's",
        });
    }
    let step_m = (x1 - x0).hypot(y1 - y0);
    let allowed_m = MAX_SPEED_M_PER_S * (t1 - t0) as f64 * 1e-9 + 1.0;
    if step_m > allowed_m {
        return Err(WireError::Implausible {
            field: "Node.odometry",
            index: None,
            value: step_m,
            limit: allowed_m,
            reason: "implausible_step",
        });
    }
    Ok(())
}

/// A node as the mapping takes it; every check of [`validate_node`] applies.
pub fn node_input(node: &v1::Node) -> Result<NodeInput, WireError> {
    validate_node(node)?;
    let header = node.header.as_ref().ok_or(WireError::Missing {
        field: "Node.header",
    })?;
    let scan = node
        .scan
        .as_ref()
        .ok_or(WireError::Missing { field: "Node.scan" })?;
    let odometry = node.odometry.as_ref().ok_or(WireError::Missing {
        field: "Node.odometry",
    })?;
    Ok(NodeInput {
        fleet: header.fleet_id.clone(),
        robot: header.robot_id.clone(),
        node_seq: node.node_seq,
        chain_id: node.chain_id,
        held_from_seq: node.held_from_seq,
        stamp_ns: header.stamp_ns,
        scan: leveled_scan_from_wire(scan)?,
        counts: scan.counts.as_ref().map(counts_from_wire).transpose()?,
        odometry: odometry_from_wire(odometry)?,
        scan_origin: node
            .scan_origin_in_robot
            .as_ref()
            .map_or(Ok(Pose2::IDENTITY), pose2_from_wire)?,
        gps: node
            .earlier_gps
            .iter()
            .chain(&node.gps)
            .map(gps_fix_from_wire)
            .collect::<Result<_, _>>()?,
    })
}

/// A message over [`MAX_NODE_BYTES`] is refused before it is decoded.
fn check_size(field: &'static str, bytes: &[u8]) -> Result<(), WireError> {
    if bytes.len() > MAX_NODE_BYTES {
        return Err(WireError::Implausible {
            field,
            index: None,
            value: bytes.len() as f64,
            limit: MAX_NODE_BYTES as f64,
            reason: "too_large",
        });
    }
    Ok(())
}

/// Decodes a node and parses it into its [`NodeInput`] (checked once); the message is
/// returned too, for what is stored of it.
pub fn decode_node_input(bytes: &[u8]) -> Result<(NodeInput, v1::Node), WireError> {
    check_size("Node", bytes)?;
    let node: v1::Node = super::decode("Node", bytes)?;
    Ok((node_input(&node)?, node))
}

/// A robot's live odometry, checked.
#[derive(Clone, Debug, PartialEq)]
pub struct OdometryInput {
    /// The sender's fleet.
    pub fleet: String,
    /// The sender's robot.
    pub robot: String,
    /// The pose (odometry frame) and its time.
    pub pose: TimedPose,
}

/// Decodes and checks live odometry into an [`OdometryInput`].
pub fn odometry_input(bytes: &[u8]) -> Result<OdometryInput, WireError> {
    let msg = decode_odometry(bytes)?;
    let pose = odometry_from_wire(&msg)?;
    let header = msg.header.ok_or(WireError::Missing {
        field: "Odometry.header",
    })?;
    Ok(OdometryInput {
        fleet: header.fleet_id,
        robot: header.robot_id,
        pose,
    })
}

/// A robot's live leveled scan, checked (`live_scan.proto`).
#[derive(Clone, Debug, PartialEq)]
pub struct LiveScanInput {
    /// The sender's fleet.
    pub fleet: String,
    /// The sender's robot.
    pub robot: String,
    /// The scan's start (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// The leveled scan.
    pub scan: LeveledScan,
    /// Dead reckoning at the scan's start.
    pub odometry: TimedPose,
    /// The scan's frame in the robot's planar frame.
    pub scan_origin: Pose2,
}

/// Decodes and checks a live scan into a [`LiveScanInput`].
pub fn live_scan_input(bytes: &[u8]) -> Result<LiveScanInput, WireError> {
    check_size("LiveScan", bytes)?;
    let msg: v1::LiveScan = super::decode("LiveScan", bytes)?;
    live_scan_from_wire(&msg)
}

/// A live scan message checked into a [`LiveScanInput`].
pub fn live_scan_from_wire(msg: &v1::LiveScan) -> Result<LiveScanInput, WireError> {
    let header = super::check_header(msg.header.as_ref(), "LiveScan.header")?;
    let scan = msg.scan.as_ref().ok_or(WireError::Missing {
        field: "LiveScan.scan",
    })?;
    let odometry = msg.odometry.as_ref().ok_or(WireError::Missing {
        field: "LiveScan.odometry",
    })?;
    for (inner, field) in [
        (scan.header.as_ref(), "LiveScan.scan.header"),
        (odometry.header.as_ref(), "LiveScan.odometry.header"),
    ] {
        if let Some(inner) = inner {
            super::same_sender(header, inner, field)?;
        }
    }
    Ok(LiveScanInput {
        fleet: header.fleet_id.clone(),
        robot: header.robot_id.clone(),
        stamp_ns: header.stamp_ns,
        scan: leveled_scan_from_wire(scan)?,
        odometry: odometry_from_wire(odometry)?,
        scan_origin: msg
            .scan_origin_in_robot
            .as_ref()
            .map_or(Ok(Pose2::IDENTITY), pose2_from_wire)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::fixtures::*;
    use prost::Message;

    #[test]
    fn a_live_scan_is_checked_like_a_nodes_scan() {
        let wire = node();
        let live = v1::LiveScan::of_node(&wire);
        let input = live_scan_input(&live.encode_to_vec()).unwrap();
        let from_node = node_input(&wire).unwrap();
        assert_eq!(input.scan, from_node.scan);
        assert_eq!(input.odometry, from_node.odometry);
        assert_eq!(input.scan_origin, from_node.scan_origin);
        let mut forged = live.clone();
        forged
            .odometry
            .as_mut()
            .unwrap()
            .header
            .as_mut()
            .unwrap()
            .robot_id = "other".into();
        assert!(matches!(
            live_scan_input(&forged.encode_to_vec()),
            Err(WireError::Invalid {
                field: "LiveScan.odometry.header",
                ..
            })
        ));
        let mut no_scan = live;
        no_scan.scan = None;
        assert!(matches!(
            live_scan_input(&no_scan.encode_to_vec()),
            Err(WireError::Missing {
                field: "LiveScan.scan"
            })
        ));
    }

    #[test]
    fn a_node_becomes_its_domain_input_once() {
        let wire = node();
        let input = node_input(&wire).unwrap();
        assert_eq!(
            (input.fleet.as_str(), input.robot.as_str()),
            ("campus", "rover-1")
        );
        assert_eq!(input.node_seq, wire.node_seq);
        assert_eq!(input.stamp_ns, STAMP_NS);
        let scan = wire.scan.as_ref().unwrap();
        let (bearings, ranges) = input.polar();
        assert_eq!((&bearings, &ranges), (&scan.bearing_rad, &scan.range_m));
        assert_eq!(input.counts, Some(counts()));
        assert_eq!(input.gps.len(), wire.earlier_gps.len() + 1);
        assert_eq!(
            input.gps.last().unwrap().position.latitude_deg,
            wire.gps.as_ref().unwrap().latitude_deg
        );
        // Whatever validate_node rejects, node_input rejects.
        let mut bad = node();
        bad.scan.as_mut().unwrap().range_m[3] = f32::NAN;
        assert_eq!(
            node_input(&bad).unwrap_err().to_string(),
            validate_node(&bad).unwrap_err().to_string()
        );
    }
}
