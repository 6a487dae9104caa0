//! Received messages as domain types: what the mapping takes, parsed once at the edge of the
//! mapper so that nothing past it sees a protobuf message.

use super::cloud::{ClassifiedCloud, cloud_from_wire, cloud_to_wire};
use super::gps::{gps_fix_from_wire, gps_fix_to_wire};
use super::localization::matching_scan;
use super::node::{decode_odometry, validate_node};
use super::odometry::{odometry_from_wire, odometry_to_wire};
use super::pose::{pose2_from_wire, pose2_to_wire};
use super::scan::{counts_from_wire, leveled_scan_from_wire, leveled_scan_to_wire};
use crate::{MAX_NODE_BYTES, MAX_SPEED_M_PER_S, Message, WireError, v1};
use leveling::{ClassCounts, LeveledScan, TimedPose};
use slam::Pose2;
use slam::gnss::GpsFix;
use slam::matching::Scan2;

/// One node of a robot as it is built, before its check: a leveled scan with its odometry,
/// the GPS fixes carried to it and, optionally, its segmented cloud (see `node.proto`). Only
/// [`Node::new`] (at the robot) and [`decode_node`] (at the mapper) make a [`Node`] of it.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeParts {
    /// The sender's fleet.
    pub fleet: String,
    /// The sender's robot.
    pub robot: String,
    /// The node's number in its chain.
    pub node_seq: u64,
    /// The robot's chain (`Node.chain_id`; 0 from senders before chains).
    pub chain_id: u64,
    /// The lowest node_seq of the chain the robot still held when it sent this one (0 as
    /// built: each send sets it, [`crate::node_as_sent`]).
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
    /// The robot's planar motion since its previous node, if there is one.
    pub odometry_delta: Option<Pose2>,
    /// The scan's frame in the robot's planar frame.
    pub scan_origin: Pose2,
    /// Every fix since the previous node, oldest first (`earlier_gps`, then `gps`).
    pub gps: Vec<GpsFix>,
    /// The segmented 3D cloud, when the robot keeps it (the mapper stores it apart).
    pub cloud: Option<ClassifiedCloud>,
}

/// One node of a robot, checked: the one form of a node between the node builder and the
/// mapping. Read its parts through `Deref`; a changed node is made again with
/// [`Node::new`] from [`Node::into_parts`].
#[derive(Clone, Debug, PartialEq)]
pub struct Node(NodeParts);

impl std::ops::Deref for Node {
    type Target = NodeParts;

    fn deref(&self) -> &NodeParts {
        &self.0
    }
}

impl Node {
    /// Checks `parts` by the rules the mapper decodes a node with ([`validate_node`]: the
    /// contract's rules are written once, on the message), so a node the robot makes is a
    /// node the mapper takes.
    pub fn new(parts: NodeParts) -> Result<Node, WireError> {
        validate_node(&node_to_wire(&parts))?;
        Ok(Node(parts))
    }

    /// The parts, to change and check again.
    pub fn into_parts(self) -> NodeParts {
        self.0
    }

    /// The node's scan as matching uses it, cut at `max_range_m`.
    pub fn matching_scan(&self, max_range_m: f32) -> Scan2 {
        matching_scan(&self.scan, max_range_m)
    }
}

impl NodeParts {
    /// The node's encoding as the outbox keeps it: header send number, send time and
    /// `held_from_seq` 0 (each send appends its own, [`crate::node_as_sent`]).
    pub fn encode(&self) -> Vec<u8> {
        node_to_wire(self).encode_to_vec()
    }
}

/// The node as its message.
fn node_to_wire(node: &NodeParts) -> v1::Node {
    let header = v1::Header::new(&node.fleet, &node.robot, 0, node.stamp_ns, 0);
    let scan = leveled_scan_to_wire(&node.scan, node.counts.as_ref(), header.clone());
    let mut fixes: Vec<v1::GpsFix> = node
        .gps
        .iter()
        .map(|fix| gps_fix_to_wire(fix, header.clone()))
        .collect();
    let gps = fixes.pop();
    v1::Node {
        header: Some(header.clone()),
        node_seq: node.node_seq,
        scan: Some(scan),
        odometry: Some(odometry_to_wire(&node.odometry, header)),
        gps,
        odometry_delta_from_previous: node.odometry_delta.as_ref().map(pose2_to_wire),
        scan_origin_in_robot: Some(pose2_to_wire(&node.scan_origin)),
        earlier_gps: fixes,
        cloud: node.cloud.as_ref().map(cloud_to_wire),
        chain_id: node.chain_id,
        held_from_seq: node.held_from_seq,
    }
}

/// Checks that a node at `next` (stamp in ns, odometry x and y in m) can follow one at
/// `previous` in one chain: a later stamp, and a step no faster than [`MAX_SPEED_M_PER_S`]
/// (plus a robot's length, so a node after a long stop is not fast). The mapper runs it on
/// each node it takes: a failing step starts a new odometry chain (an odometry reset).
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

/// A node message as the mapping takes it; every check of [`validate_node`] applies.
pub fn node_from_wire(node: &v1::Node) -> Result<Node, WireError> {
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
    Ok(Node(NodeParts {
        fleet: header.fleet_id.clone(),
        robot: header.robot_id.clone(),
        node_seq: node.node_seq,
        chain_id: node.chain_id,
        held_from_seq: node.held_from_seq,
        stamp_ns: header.stamp_ns,
        scan: leveled_scan_from_wire(scan)?,
        counts: scan.counts.as_ref().map(counts_from_wire).transpose()?,
        odometry: odometry_from_wire(odometry)?,
        odometry_delta: node
            .odometry_delta_from_previous
            .as_ref()
            .map(pose2_from_wire)
            .transpose()?,
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
        cloud: node.cloud.as_ref().map(cloud_from_wire).transpose()?,
    }))
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

/// Decodes a node and checks it into a [`Node`], once: bytes over [`MAX_NODE_BYTES`],
/// garbage, a missing header, a foreign wire version and every failure of [`validate_node`]
/// are errors.
pub fn decode_node(bytes: &[u8]) -> Result<Node, WireError> {
    check_size("Node", bytes)?;
    node_from_wire(&super::decode("Node", bytes)?)
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

/// A robot's live leveled scan (`live_scan.proto`): for live views, not a node.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveScan {
    /// The sender's fleet.
    pub fleet: String,
    /// The sender's robot.
    pub robot: String,
    /// The scan's start (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// The leveled scan.
    pub scan: LeveledScan,
    /// The scan's points per class, when known.
    pub counts: Option<ClassCounts>,
    /// Dead reckoning at the scan's start.
    pub odometry: TimedPose,
    /// The scan's frame in the robot's planar frame.
    pub scan_origin: Pose2,
}

impl LiveScan {
    /// A node's scan as a live scan.
    pub fn of_node(node: &Node) -> LiveScan {
        LiveScan {
            fleet: node.fleet.clone(),
            robot: node.robot.clone(),
            stamp_ns: node.stamp_ns,
            scan: node.scan.clone(),
            counts: node.counts,
            odometry: node.odometry,
            scan_origin: node.scan_origin,
        }
    }

    /// Its message as sent: publication `seq` of the robot, sent at `sent_ns`.
    pub fn encode(&self, seq: u64, sent_ns: u64) -> Vec<u8> {
        let header = v1::Header::new(&self.fleet, &self.robot, seq, self.stamp_ns, sent_ns);
        let scan = leveled_scan_to_wire(&self.scan, self.counts.as_ref(), header.clone());
        v1::LiveScan {
            header: Some(header.clone()),
            scan: Some(scan),
            odometry: Some(odometry_to_wire(&self.odometry, header)),
            scan_origin_in_robot: Some(pose2_to_wire(&self.scan_origin)),
        }
        .encode_to_vec()
    }
}

/// Live odometry as sent: `pose` of `robot` of `fleet`, publication `seq`, sent at `sent_ns`.
pub fn encode_odometry(
    fleet: &str,
    robot: &str,
    pose: &TimedPose,
    seq: u64,
    sent_ns: u64,
) -> Vec<u8> {
    let header = v1::Header::new(fleet, robot, seq, pose.stamp_ns, sent_ns);
    odometry_to_wire(pose, header).encode_to_vec()
}

/// Decodes and checks a live scan into a [`LiveScan`].
pub fn decode_live_scan(bytes: &[u8]) -> Result<LiveScan, WireError> {
    check_size("LiveScan", bytes)?;
    let msg: v1::LiveScan = super::decode("LiveScan", bytes)?;
    live_scan_from_wire(&msg)
}

/// A live scan message checked into a [`LiveScan`].
fn live_scan_from_wire(msg: &v1::LiveScan) -> Result<LiveScan, WireError> {
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
    Ok(LiveScan {
        fleet: header.fleet_id.clone(),
        robot: header.robot_id.clone(),
        stamp_ns: header.stamp_ns,
        scan: leveled_scan_from_wire(scan)?,
        counts: scan.counts.as_ref().map(counts_from_wire).transpose()?,
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

    #[test]
    fn a_live_scan_is_checked_like_a_nodes_scan() {
        let node = node_from_wire(&node()).unwrap();
        let live = LiveScan::of_node(&node);
        let bytes = live.encode(3, STAMP_NS + 7);
        assert_eq!(decode_live_scan(&bytes).unwrap(), live);
        let mut forged = v1::LiveScan::decode(&bytes[..]).unwrap();
        forged
            .odometry
            .as_mut()
            .unwrap()
            .header
            .as_mut()
            .unwrap()
            .robot_id = "other".into();
        assert!(matches!(
            decode_live_scan(&forged.encode_to_vec()),
            Err(WireError::Invalid {
                field: "LiveScan.odometry.header",
                ..
            })
        ));
        forged.scan = None;
        assert!(matches!(
            decode_live_scan(&forged.encode_to_vec()),
            Err(WireError::Missing {
                field: "LiveScan.scan"
            })
        ));
    }

    #[test]
    fn a_node_becomes_its_domain_form_once() {
        let wire = node();
        let domain = node_from_wire(&wire).unwrap();
        assert_eq!(
            (domain.fleet.as_str(), domain.robot.as_str()),
            ("campus", "rover-1")
        );
        assert_eq!(domain.node_seq, wire.node_seq);
        assert_eq!(domain.stamp_ns, STAMP_NS);
        let scan = wire.scan.as_ref().unwrap();
        assert_eq!(
            domain.scan.polar(),
            (scan.bearing_rad.clone(), scan.range_m.clone())
        );
        assert_eq!(domain.counts, Some(counts()));
        assert_eq!(domain.gps.len(), wire.earlier_gps.len() + 1);
        assert_eq!(
            domain.gps.last().unwrap().position.latitude_deg,
            wire.gps.as_ref().unwrap().latitude_deg
        );
        assert_eq!(domain.cloud.as_ref().unwrap().points_m.len(), 4);
        // Whatever validate_node rejects, decoding rejects.
        let mut bad = node();
        bad.scan.as_mut().unwrap().range_m[3] = f32::NAN;
        assert_eq!(
            decode_node(&bad.encode_to_vec()).unwrap_err().to_string(),
            validate_node(&bad).unwrap_err().to_string()
        );
    }

    #[test]
    fn a_node_encoded_once_decodes_to_itself() {
        let node = node_from_wire(&node()).unwrap();
        let mut parts = node.clone().into_parts();
        parts.held_from_seq = 0;
        let built = Node::new(parts).unwrap();
        // The fixture's satellites and send fields are not the domain's: compare domain forms.
        assert_eq!(decode_node(&built.encode()).unwrap(), built);
        // Without counts, GPS, a cloud and a previous node too.
        let mut bare = built.clone().into_parts();
        (bare.counts, bare.cloud, bare.odometry_delta) = (None, None, None);
        bare.gps.clear();
        let bare = Node::new(bare).unwrap();
        assert_eq!(decode_node(&bare.encode()).unwrap(), bare);
        // The constructor holds the mapper's rules: a NaN range is no node.
        let mut bad = built.into_parts();
        bad.scan.beams[2].range_m = Some(f32::NAN);
        assert!(matches!(
            Node::new(bad),
            Err(WireError::InvalidValue {
                field: "LeveledScan.range_m",
                index: Some(2),
                ..
            })
        ));
    }
}
