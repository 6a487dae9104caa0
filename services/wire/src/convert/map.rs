//! The mapper's answers on the bus: optimized node poses and the map's summary.

use super::decode;
use super::pose::{pose2_from_wire, pose2_to_wire};
use crate::{WIRE_VERSION, WireError, v1, validate_id};
use slam::Pose2;

/// The optimized pose of one node of a fleet's map.
#[derive(Clone, Debug, PartialEq)]
pub struct MapPose {
    /// The robot's id.
    pub robot: String,
    /// The node's number in its robot's sequence.
    pub node_seq: u64,
    /// The node's scan frame in the map frame.
    pub pose: Pose2,
}

/// Node poses of `fleet` on the wire.
pub fn map_poses_to_wire(fleet: &str, poses: &[MapPose], sent_ns: u64) -> v1::MapPoses {
    v1::MapPoses {
        version: WIRE_VERSION,
        fleet_id: fleet.to_owned(),
        sent_ns,
        poses: poses
            .iter()
            .map(|p| v1::NodePose {
                robot_id: p.robot.clone(),
                node_seq: p.node_seq,
                pose: Some(pose2_to_wire(&p.pose)),
            })
            .collect(),
        solved_from: Vec::new(),
    }
}

/// Decodes and checks node poses: this wire version, valid ids, finite poses.
pub fn decode_map_poses(bytes: &[u8]) -> Result<(String, Vec<MapPose>), WireError> {
    let msg: v1::MapPoses = decode("MapPoses", bytes)?;
    check_version("MapPoses.version", msg.version)?;
    validate_id("fleet", &msg.fleet_id)?;
    let poses = msg
        .poses
        .iter()
        .map(|p| {
            validate_id("robot", &p.robot_id)?;
            let pose = p.pose.as_ref().ok_or(WireError::Missing {
                field: "NodePose.pose",
            })?;
            Ok(MapPose {
                robot: p.robot_id.clone(),
                node_seq: p.node_seq,
                pose: pose2_from_wire(pose)?,
            })
        })
        .collect::<Result<_, WireError>>()?;
    Ok((msg.fleet_id, poses))
}

/// Decodes and checks a map summary: this wire version, a valid fleet id.
pub fn decode_map_summary(bytes: &[u8]) -> Result<v1::MapSummary, WireError> {
    let msg: v1::MapSummary = decode("MapSummary", bytes)?;
    check_version("MapSummary.version", msg.version)?;
    validate_id("fleet", &msg.fleet_id)?;
    Ok(msg)
}

fn check_version(field: &'static str, found: u32) -> Result<(), WireError> {
    if found == WIRE_VERSION {
        Ok(())
    } else {
        Err(WireError::Version { field, found })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Message;

    #[test]
    fn poses_round_trip_and_bad_ones_are_rejected() {
        let poses = vec![MapPose {
            robot: "r0".into(),
            node_seq: 3,
            pose: Pose2::new(1.5, -2.0, 0.25),
        }];
        let msg = map_poses_to_wire("park", &poses, 7);
        let (fleet, back) = decode_map_poses(&msg.encode_to_vec()).unwrap();
        assert_eq!((fleet.as_str(), back), ("park", poses));
        let mut bad = msg.clone();
        bad.poses[0].pose.as_mut().unwrap().x_m = f64::NAN;
        assert!(decode_map_poses(&bad.encode_to_vec()).is_err());
        let mut old = msg;
        old.version = 0;
        assert!(matches!(
            decode_map_poses(&old.encode_to_vec()),
            Err(WireError::Version { .. })
        ));
        assert!(decode_map_summary(b"\xff\xff").is_err());
    }
}
