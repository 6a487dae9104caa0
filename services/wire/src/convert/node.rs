//! GPS fixes, nodes and acks, and decoding checked messages.

use super::cloud::{check_cloud_against_counts, validate_cloud};
use super::gps::validate_gps_fix;
use super::odometry::odometry_from_wire;
use super::pose::pose2d_from_wire;
use super::scan::leveled_scan_from_wire;
use super::{check_header, decode, same_sender};
use crate::{Message, WireError, v1};

/// Checks a node: header; a scan and odometry, valid, from the same fleet and robot; the GPS
/// fixes and the odometry delta, if present, valid; `earlier_gps` only beside `gps`, oldest
/// first, each stamped before `gps`; the cloud, if present, valid ([`validate_cloud`]) and
/// consistent with the scan's counts.
pub fn validate_node(node: &v1::Node) -> Result<(), WireError> {
    let header = check_header(node.header.as_ref(), "Node.header")?;
    let scan = node
        .scan
        .as_ref()
        .ok_or(WireError::Missing { field: "Node.scan" })?;
    leveled_scan_from_wire(scan)?;
    let odometry = node.odometry.as_ref().ok_or(WireError::Missing {
        field: "Node.odometry",
    })?;
    odometry_from_wire(odometry)?;
    // Both checked above, so present.
    if let (Some(s), Some(o)) = (&scan.header, &odometry.header) {
        same_sender(header, s, "Node.scan.header")?;
        same_sender(header, o, "Node.odometry.header")?;
    }
    if let Some(gps) = &node.gps {
        validate_gps_fix(gps)?;
        if let Some(g) = &gps.header {
            same_sender(header, g, "Node.gps.header")?;
        }
    }
    validate_earlier_gps(header, node)?;
    if node.held_from_seq > node.node_seq {
        return Err(WireError::Invalid {
            field: "Node.held_from_seq",
            detail: format!(
                "{} is above node_seq {}: a robot holds the node it sends",
                node.held_from_seq, node.node_seq
            ),
        });
    }
    if let Some(cloud) = &node.cloud {
        let kept = validate_cloud(cloud)?;
        if let Some(counts) = &scan.counts {
            check_cloud_against_counts(&kept, cloud, counts)?;
        }
    }
    for pose in [
        &node.odometry_delta_from_previous,
        &node.scan_origin_in_robot,
    ]
    .into_iter()
    .flatten()
    {
        pose2d_from_wire(pose)?;
    }
    Ok(())
}

/// Checks `Node.earlier_gps`: only beside `Node.gps`, each fix valid and from the node's
/// sender, stamps strictly increasing and before `Node.gps`'s.
fn validate_earlier_gps(header: &v1::Header, node: &v1::Node) -> Result<(), WireError> {
    const FIELD: &str = "Node.earlier_gps";
    let Some(latest) = &node.gps else {
        return match node.earlier_gps.len() {
            0 => Ok(()),
            n => Err(WireError::Invalid {
                field: FIELD,
                detail: format!("{n} fixes without Node.gps"),
            }),
        };
    };
    let stamp = |fix: &v1::GpsFix| fix.header.as_ref().map_or(0, |h| h.stamp_ns);
    let mut previous: Option<u64> = None;
    for (k, fix) in node.earlier_gps.iter().enumerate() {
        validate_gps_fix(fix)?;
        if let Some(g) = &fix.header {
            same_sender(header, g, "Node.earlier_gps.header")?;
        }
        let t = stamp(fix);
        if previous.is_some_and(|p| t <= p) || t >= stamp(latest) {
            return Err(WireError::InvalidValue {
                field: FIELD,
                index: Some(k),
                value: t as f64,
                problem: "a stamp not after the fix before it and before Node.gps's",
            });
        }
        previous = Some(t);
    }
    Ok(())
}

/// Checks an ack: header present, of this version, with valid ids.
pub fn validate_ack(ack: &v1::Ack) -> Result<(), WireError> {
    check_header(ack.header.as_ref(), "Ack.header").map(drop)
}

/// Decodes and checks a node message ([`validate_node`]), for the tests of the checks.
#[cfg(test)]
pub(crate) fn decode_node_message(bytes: &[u8]) -> Result<v1::Node, WireError> {
    let node: v1::Node = decode("Node", bytes)?;
    validate_node(&node)?;
    Ok(node)
}

/// A stored node as it is sent: `stored` (a node's encoding, as the outbox keeps it) with
/// what each send sets appended: the lowest node the robot still holds, the header's send
/// number and send time. Protobuf merges a repeated singular field into the one before it
/// (the header's given fields replace the stored ones, the rest stay), so a send neither
/// decodes nor re-encodes the node. The stored node carries 0 in those three fields, as the
/// node builder makes it: a 0 here leaves the stored value.
pub fn node_as_sent(stored: &[u8], held_from_seq: u64, header_seq: u64, sent_ns: u64) -> Vec<u8> {
    let stamp = v1::Node {
        header: Some(v1::Header {
            seq: header_seq,
            sent_ns,
            ..Default::default()
        }),
        held_from_seq,
        ..Default::default()
    };
    let mut bytes = Vec::with_capacity(stored.len() + stamp.encoded_len());
    bytes.extend_from_slice(stored);
    stamp.encode(&mut bytes).expect("a Vec grows");
    bytes
}

/// A received node's encoding split, without decoding or re-encoding the node, into the
/// node without its cloud and the cloud's own encoding (`Node.cloud`, field 9): the mapper
/// stores the two apart. Several cloud fields merge, as protobuf merges them. `bytes` must be
/// a node that decoded; an encoding this scan does not follow (groups) is split by decoding.
pub fn split_node_cloud(bytes: Vec<u8>) -> (Vec<u8>, Option<Vec<u8>>) {
    const CLOUD_FIELD: u32 = 9;
    let mut node = Vec::with_capacity(bytes.len());
    let mut cloud: Option<Vec<u8>> = None;
    let mut rest = &bytes[..];
    while !rest.is_empty() {
        let Some((tag, content, after)) = next_field(rest) else {
            return split_by_decoding(bytes);
        };
        let field = &rest[..rest.len() - after.len()];
        if tag == CLOUD_FIELD {
            cloud.get_or_insert_default().extend_from_slice(content);
        } else {
            node.extend_from_slice(field);
        }
        rest = after;
    }
    match cloud {
        None => (bytes, None),
        some => (node, some),
    }
}

/// The first field of `bytes`: its number, its content (a length-delimited field's payload)
/// and the bytes after it; `None` for a group or a malformed field.
fn next_field(mut bytes: &[u8]) -> Option<(u32, &[u8], &[u8])> {
    use prost::encoding::{WireType, decode_key, decode_varint};
    let (tag, wire_type) = decode_key(&mut bytes).ok()?;
    let len = match wire_type {
        WireType::Varint => {
            let before = bytes.len();
            let mut probe = bytes;
            decode_varint(&mut probe).ok()?;
            before - probe.len()
        }
        WireType::SixtyFourBit => 8,
        WireType::ThirtyTwoBit => 4,
        WireType::LengthDelimited => usize::try_from(decode_varint(&mut bytes).ok()?).ok()?,
        WireType::StartGroup | WireType::EndGroup => return None,
    };
    (len <= bytes.len()).then(|| (tag, &bytes[..len], &bytes[len..]))
}

fn split_by_decoding(bytes: Vec<u8>) -> (Vec<u8>, Option<Vec<u8>>) {
    let Ok(mut node) = v1::Node::decode(&bytes[..]) else {
        return (bytes, None);
    };
    match node.cloud.take() {
        Some(cloud) => (node.encode_to_vec(), Some(cloud.encode_to_vec())),
        None => (bytes, None),
    }
}

/// Decodes and checks live odometry ([`odometry_from_wire`]).
pub fn decode_odometry(bytes: &[u8]) -> Result<v1::Odometry, WireError> {
    let odometry: v1::Odometry = decode("Odometry", bytes)?;
    odometry_from_wire(&odometry)?;
    Ok(odometry)
}

/// Decodes and checks an ack ([`validate_ack`]).
pub fn decode_ack(bytes: &[u8]) -> Result<v1::Ack, WireError> {
    let ack: v1::Ack = decode("Ack", bytes)?;
    validate_ack(&ack)?;
    Ok(ack)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::fixtures::*;
    use crate::*;

    #[test]
    fn garbage_bytes_are_rejected() {
        for bytes in [&b"garbage"[..], &[0xff; 16], &[0x0a, 0x05, 0x01]] {
            let err = decode_node_message(bytes).unwrap_err();
            assert!(
                matches!(
                    err,
                    WireError::Decode {
                        message: "Node",
                        ..
                    }
                ),
                "{err}"
            );
            assert!(decode_odometry(bytes).is_err());
            assert!(decode_ack(bytes).is_err());
        }
        // Empty bytes are a valid encoding of an empty node, which has no header.
        assert_eq!(
            decode_node_message(&[]).unwrap_err(),
            WireError::Missing {
                field: "Node.header"
            }
        );
    }

    #[test]
    fn other_wire_versions_are_rejected() {
        let err = rejection(|n| n.header.as_mut().unwrap().version = 2);
        assert_eq!(
            err,
            WireError::Version {
                field: "Node.header",
                found: 2
            }
        );
        assert!(err.to_string().contains("wire version 2"), "{err}");
        let err = rejection(|n| wire_scan(n).header.as_mut().unwrap().version = 2);
        assert!(matches!(
            err,
            WireError::Version {
                field: "LeveledScan.header",
                found: 2
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().header.as_mut().unwrap().version = 0);
        assert!(matches!(
            err,
            WireError::Version {
                field: "GpsFix.header",
                found: 0
            }
        ));
        let mut ack = v1::Ack {
            header: Some(header(3)),
            acked_node_seq: Some(6),
            chain_id: 0xfeed,
            resend_from: None,
        };
        let decoded = decode_ack(&ack.encode_to_vec()).unwrap();
        assert_eq!(
            (decoded.acked_node_seq, decoded.chain_id),
            (Some(6), 0xfeed)
        );
        ack.header.as_mut().unwrap().version = 2;
        assert!(decode_ack(&ack.encode_to_vec()).is_err());
    }

    #[test]
    fn missing_parts_are_rejected() {
        assert_eq!(
            rejection(|n| n.header = None),
            WireError::Missing {
                field: "Node.header"
            }
        );
        assert_eq!(
            rejection(|n| n.scan = None),
            WireError::Missing { field: "Node.scan" }
        );
        assert_eq!(
            rejection(|n| wire_scan(n).header = None),
            WireError::Missing {
                field: "LeveledScan.header"
            }
        );
        assert_eq!(
            rejection(|n| n.odometry.as_mut().unwrap().pose = None),
            WireError::Missing {
                field: "Odometry.pose"
            }
        );
        // An unset orientation (all zeros) is not the identity.
        let err = rejection(|n| {
            let p = n.odometry.as_mut().unwrap().pose.as_mut().unwrap();
            (p.qw, p.qx, p.qy, p.qz) = (0.0, 0.0, 0.0, 0.0);
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Pose3D.qw",
                ..
            }
        ));
        // GPS is optional.
        let mut n = node();
        n.gps = None;
        n.earlier_gps.clear();
        n.odometry_delta_from_previous = None;
        decode_node_message(&n.encode_to_vec()).unwrap();
    }

    #[test]
    fn bad_headers_fixes_and_poses_are_rejected() {
        let err = rejection(|n| n.header.as_mut().unwrap().robot_id = "rover/*".into());
        assert!(matches!(err, WireError::InvalidId { kind: "robot", .. }));
        let err = rejection(|n| wire_scan(n).header.as_mut().unwrap().robot_id = "rover-2".into());
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "Node.scan.header",
                ..
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().latitude_deg = 91.0);
        assert_eq!(err.to_string(), "GpsFix.latitude_deg = 91 is out of range");
        let err = rejection(|n| n.gps.as_mut().unwrap().position_covariance_m2.truncate(4));
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "GpsFix.position_covariance_m2",
                ..
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().position_covariance_m2[4] = -0.1);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                index: Some(4),
                problem: "a negative variance",
                ..
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().status = 42);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "GpsFix.status",
                ..
            }
        ));
        let err = rejection(|n| n.odometry.as_mut().unwrap().pose.as_mut().unwrap().x_m = f64::NAN);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Pose3D.x_m",
                ..
            }
        ));
        let err = rejection(|n| n.odometry.as_mut().unwrap().pose_covariance = vec![0.0; 35]);
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "Odometry.pose_covariance",
                ..
            }
        ));
        let err = rejection(|n| {
            n.odometry_delta_from_previous.as_mut().unwrap().yaw_rad = f64::INFINITY;
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Pose2D.yaw_rad",
                ..
            }
        ));
    }

    #[test]
    fn bad_earlier_fixes_are_rejected() {
        let err = rejection(|n| n.earlier_gps[0].longitude_deg = f64::NAN);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "GpsFix.longitude_deg",
                problem: "not finite",
                ..
            }
        ));
        let err = rejection(|n| {
            n.earlier_gps[0].header.as_mut().unwrap().robot_id = "rover-2".into();
        });
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "Node.earlier_gps.header",
                ..
            }
        ));
        // Not before Node.gps, or out of order.
        let err = rejection(|n| {
            let latest = n.gps.as_ref().unwrap().header.as_ref().unwrap().stamp_ns;
            n.earlier_gps[0].header.as_mut().unwrap().stamp_ns = latest;
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Node.earlier_gps",
                index: Some(0),
                ..
            }
        ));
        let err = rejection(|n| {
            let mut older = n.earlier_gps[0].clone();
            older.header.as_mut().unwrap().stamp_ns -= 1_000_000_000;
            n.earlier_gps.push(older);
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Node.earlier_gps",
                index: Some(1),
                ..
            }
        ));
        let err = rejection(|n| n.gps = None);
        assert!(
            err.to_string().contains("1 fixes without Node.gps"),
            "{err}"
        );
    }

    #[test]
    fn finite_but_absurd_positions_are_rejected() {
        // 1e200 m is finite: it used to pass and break every later solve of the fleet.
        let far = rejection(|n| n.odometry.as_mut().unwrap().pose.as_mut().unwrap().x_m = 1e200);
        assert!(
            matches!(
                far,
                WireError::Implausible {
                    field: "Pose3D.x_m",
                    reason: "implausible_position",
                    ..
                }
            ),
            "{far:?}"
        );
        let origin = rejection(|n| {
            n.scan_origin_in_robot = Some(v1::Pose2D {
                x_m: -2e6,
                y_m: 0.0,
                yaw_rad: 0.0,
            })
        });
        assert!(
            matches!(
                origin,
                WireError::Implausible {
                    field: "Pose2D.x_m",
                    ..
                }
            ),
            "{origin:?}"
        );
        let range = rejection(|n| n.scan.as_mut().unwrap().range_m[0] = 1001.0);
        assert_eq!(range.reason(), "implausible_range");
        assert!(
            matches!(
                range,
                WireError::Implausible {
                    field: "LeveledScan.range_m",
                    index: Some(0),
                    ..
                }
            ),
            "{range:?}"
        );
        // At the bound, a position is still taken.
        let mut edge = node();
        edge.odometry.as_mut().unwrap().pose.as_mut().unwrap().x_m = MAX_POSITION_M;
        validate_node(&edge).unwrap();
        let big = vec![0u8; MAX_NODE_BYTES + 1];
        assert_eq!(decode_node(&big).unwrap_err().reason(), "too_large");
    }

    #[test]
    fn a_node_holds_what_it_sends() {
        let err = rejection(|n| {
            n.node_seq = 3;
            n.held_from_seq = 4;
        });
        assert!(err.to_string().contains("held_from_seq"), "{err}");
        let mut ok = node();
        ok.node_seq = 3;
        ok.held_from_seq = 3;
        validate_node(&ok).unwrap();
    }

    #[test]
    fn a_node_as_sent_is_the_stored_node_with_its_send_fields() {
        let mut stored = node();
        stored.held_from_seq = 0;
        stored.node_seq = 9;
        let header = stored.header.as_mut().unwrap();
        (header.seq, header.sent_ns) = (0, 0);
        let bytes = stored.encode_to_vec();
        let sent = node_as_sent(&bytes, 7, 41, 123_456_789);
        let decoded = decode_node_message(&sent).unwrap();
        let mut expected = stored.clone();
        expected.held_from_seq = 7;
        let header = expected.header.as_mut().unwrap();
        (header.seq, header.sent_ns) = (41, 123_456_789);
        assert_eq!(decoded, expected, "only the send fields change");
        // Nothing held below the first node yet: the stored 0 stays.
        let first = decode_node_message(&node_as_sent(&bytes, 0, 1, 5)).unwrap();
        assert_eq!(first.held_from_seq, 0);
        assert_eq!(
            first.header.unwrap().fleet_id,
            stored.header.unwrap().fleet_id
        );
    }

    #[test]
    fn a_cloud_is_split_from_its_node_without_re_encoding() {
        let sent = node();
        let bytes = sent.encode_to_vec();
        let (stored, cloud) = split_node_cloud(bytes.clone());
        let mut expected = sent.clone();
        let expected_cloud = expected.cloud.take().unwrap();
        assert_eq!(v1::Node::decode(&stored[..]).unwrap(), expected);
        assert_eq!(
            stored,
            expected.encode_to_vec(),
            "the other fields' bytes as sent"
        );
        let cloud = v1::SegmentedCloud::decode(&cloud.unwrap()[..]).unwrap();
        assert_eq!(cloud, expected_cloud);
        // Without a cloud: the bytes themselves.
        let bare = expected.encode_to_vec();
        assert_eq!(split_node_cloud(bare.clone()), (bare, None));
        // A group (wire type 3) is split by decoding: prost skips it.
        let mut grouped = vec![(15 << 3) | 3, (15 << 3) | 4];
        grouped.extend_from_slice(&bytes);
        let (stored, cloud) = split_node_cloud(grouped);
        assert_eq!(v1::Node::decode(&stored[..]).unwrap(), expected);
        assert!(cloud.is_some());
    }

    #[test]
    fn a_step_faster_than_a_robot_is_implausible() {
        let t = 1_000_000_000;
        check_step((t, [0.0, 0.0]), (2 * t, [40.0, 0.0])).unwrap();
        // A long stop, then a node: 1 m is a robot's length, whatever the time.
        check_step((t, [0.0, 0.0]), (t + 1, [0.0, 1.0])).unwrap();
        let fast = check_step((t, [0.0, 0.0]), (2 * t, [0.0, 52.0])).unwrap_err();
        assert_eq!(fast.reason(), "implausible_step");
        assert!(check_step((t, [0.0, 0.0]), (t, [0.0, 0.0])).is_err());
    }
}
