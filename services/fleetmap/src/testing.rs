//! A node for tests of the map and of its shells (feature `testing`).

use leveling::nalgebra::{Isometry3, Translation3};
use leveling::{Beam, LeveledScan, TimedPose};
use slam::Pose2;
use wire::{Node, NodeParts};

const S: u64 = 1_000_000_000;

/// Node `seq` of `robot`'s chain `chain` in fleet `site`, the robot `x` m along, at `seq` s.
pub fn node(robot: &str, chain: u64, seq: u64, held_from: u64, x: f64) -> Node {
    node_of("site", robot, chain, seq, held_from, x)
}

/// [`node`] of fleet `fleet`.
pub fn node_of(fleet: &str, robot: &str, chain: u64, seq: u64, held_from: u64, x: f64) -> Node {
    let beams = (0..90)
        .map(|k| Beam {
            bearing_rad: k as f32 * 0.07,
            range_m: Some(5.0 + (k % 7) as f32),
            sensor_xy_m: [0.0, 0.0],
            ground_to_m: None,
        })
        .collect();
    Node::new(NodeParts {
        fleet: fleet.into(),
        robot: robot.into(),
        node_seq: seq,
        chain_id: chain,
        held_from_seq: held_from,
        stamp_ns: (seq + 1) * S,
        scan: LeveledScan {
            stamp_ns: (seq + 1) * S,
            beams,
        },
        counts: None,
        odometry: TimedPose {
            stamp_ns: (seq + 1) * S,
            pose: Isometry3::from_parts(Translation3::new(x, 0.0, 0.0), Default::default()),
        },
        odometry_delta: None,
        scan_origin: Pose2::IDENTITY,
        gps: Vec::new(),
        cloud: None,
    })
    .expect("a valid node")
}
