//! Chains: first contact, duplicates, gaps, a wiped outbox, bounds and odometry breaks.

use super::*;
use leveling::{Beam, LeveledScan, TimedPose};
use nalgebra::{Isometry3, Translation3};

const S: u64 = 1_000_000_000;

/// Node `seq` of `robot`'s chain `chain`, the robot `x` m along, at `seq` s.
pub(crate) fn node(robot: &str, chain: u64, seq: u64, held_from: u64, x: f64) -> NodeInput {
    let beams = (0..90)
        .map(|k| Beam {
            bearing_rad: k as f32 * 0.07,
            range_m: Some(5.0 + (k % 7) as f32),
        })
        .collect();
    NodeInput {
        fleet: "site".into(),
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
        scan_origin: Pose2::IDENTITY,
        gps: Vec::new(),
    }
}

fn map() -> FleetMap {
    FleetMap::new("site", Mapper2dParams::default(), None, 40.0)
}

#[test]
fn a_new_chain_starts_where_its_robot_holds_nodes() {
    let mut map = map();
    // First contact: node 0 was lost, node 1 came. It must not start the chain.
    assert_eq!(
        map.sequence(&node("r", 7, 1, 0, 1.0)),
        Sequence::Gap { expected: 0 }
    );
    assert!(map.ingest(&node("r", 7, 1, 0, 1.0)).is_err());
    assert_eq!(map.chain_acked("r", 7), None);
    map.ingest(&node("r", 7, 0, 0, 0.0)).unwrap();
    map.ingest(&node("r", 7, 1, 0, 1.0)).unwrap();
    assert_eq!(map.chain_acked("r", 7), Some(1));
    assert_eq!(map.sequence(&node("r", 7, 1, 0, 1.0)), Sequence::Duplicate);
    assert_eq!(
        map.sequence(&node("r", 7, 3, 0, 3.0)),
        Sequence::Gap { expected: 2 }
    );
    // A mapper that lost its store meets a chain whose first nodes were acked long ago.
    let mut fresh = self::map();
    fresh.ingest(&node("r", 7, 40, 40, 40.0)).unwrap();
    assert_eq!(fresh.robots()[0].chains[0].first_node_seq, 40);
}

#[test]
fn a_wiped_outbox_is_a_second_chain_of_the_same_robot() {
    let mut map = map();
    for seq in 0..3 {
        map.ingest(&node("r", 7, seq, 0, seq as f64)).unwrap();
    }
    // The same numbers again, from a new outbox: new nodes, not duplicates.
    for seq in 0..3 {
        let n = node("r", 9, seq, 0, seq as f64);
        assert_eq!(map.sequence(&n), Sequence::Next);
        map.ingest(&n).unwrap();
    }
    assert_eq!(map.robots().len(), 1);
    let chains: Vec<(u64, u64)> = map.robots()[0]
        .chains
        .iter()
        .map(|c| (c.chain_id, c.last_node_seq))
        .collect();
    assert_eq!(chains, [(7, 2), (9, 2)]);
    assert_eq!(map.nodes().len(), 6);
    // Each chain is its own odometry chain in the network.
    assert_ne!(
        map.mapper.node_robot(0).0,
        map.mapper.node_robot(3).0,
        "chains must not be joined by odometry"
    );
}

#[test]
fn an_implausible_step_breaks_odometry_not_the_chain() {
    let mut map = map();
    map.ingest(&node("r", 7, 0, 0, 0.0)).unwrap();
    // 500 m in one second: an odometry reset.
    let jumped = map.ingest(&node("r", 7, 1, 0, 500.0)).unwrap();
    assert_eq!(
        jumped.odometry_break.map(|e| e.reason()),
        Some("implausible_step")
    );
    assert_eq!(map.chain_acked("r", 7), Some(1));
    assert_ne!(map.mapper.node_robot(0).0, map.mapper.node_robot(1).0);
    let next = map.ingest(&node("r", 7, 2, 0, 501.0)).unwrap();
    assert_eq!(next.odometry_break, None);
    assert_eq!(map.mapper.node_robot(1).0, map.mapper.node_robot(2).0);
}

#[test]
fn robots_and_chains_are_bounded() {
    let mut map = map();
    for chain in 1..=MAX_CHAINS_PER_ROBOT as u64 {
        map.ingest(&node("r", chain, 0, 0, 0.0)).unwrap();
    }
    let err = map.ingest(&node("r", 0xffff, 0, 0, 0.0)).unwrap_err();
    assert!(
        matches!(&err, IngestError::Refused { source, .. } if source.reason() == "too_many_chains"),
        "{err}"
    );
    for r in 1..MAX_ROBOTS_PER_FLEET {
        map.ingest(&node(&format!("r{r}"), 1, 0, 0, 0.0)).unwrap();
    }
    let err = map.ingest(&node("one-more", 1, 0, 0, 0.0)).unwrap_err();
    assert!(
        matches!(&err, IngestError::Refused { source, .. } if source.reason() == "too_many_robots"),
        "{err}"
    );
}
