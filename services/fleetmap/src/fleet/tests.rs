//! Chains: first contact, duplicates, gaps, a wiped outbox, bounds and odometry breaks.

use super::*;
use crate::testing::node;

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
    // A map restored from an old backup: the robot holds nodes from 6 on, so 2–5 are lost
    // and the chain goes on from 6, not waiting for them for good.
    assert_eq!(
        map.sequence(&node("r", 7, 9, 6, 9.0)),
        Sequence::Gap { expected: 6 }
    );
    assert_eq!(map.sequence(&node("r", 7, 6, 6, 6.0)), Sequence::Next);
    map.ingest(&node("r", 7, 6, 6, 6.0)).unwrap();
    assert_eq!(map.chain_acked("r", 7), Some(6));
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

#[test]
fn localized_nodes_are_taken_in_sequence_without_growing_the_network() {
    let mut map = map();
    for seq in 0..3 {
        map.ingest(&node("r", 7, seq, 0, seq as f64)).unwrap();
    }
    // Localizing: 3..=5 are taken (acked), one span, no node added.
    let mut spans = Vec::new();
    for seq in 3..6 {
        spans.push(
            map.take_localized(&node("r", 7, seq, 3, seq as f64), false)
                .unwrap(),
        );
    }
    assert_eq!(map.nodes().len(), 3);
    assert_eq!(map.chain_acked("r", 7), Some(5));
    // Readers see the chain acked to its localized node, not to its last mapped one.
    let view = crate::FleetView::of(&map, None, 0.0, 0);
    assert_eq!(
        (
            view.robots[0].chains[0].last_node_seq,
            view.robots[0].chains[0].acked_node_seq
        ),
        (2, 5)
    );
    let last = spans.last().unwrap();
    assert_eq!((last.first_seq, last.last_seq), (3, 5));
    assert_eq!(map.sequence(&node("r", 7, 4, 3, 4.0)), Sequence::Duplicate);
    assert!(
        map.take_localized(&node("r", 7, 7, 6, 7.0), false).is_err(),
        "a gap: the robot holds node 6 still"
    );
    // Mapping again: node 6 is taken, as a new part of the network (its odometry link
    // would span the drive the network never saw), however far the robot went.
    map.ingest(&node("r", 7, 6, 6, 60.0)).unwrap();
    assert_ne!(map.mapper.node_robot(2).0, map.mapper.node_robot(3).0);
    // A second run of localized nodes is a second span.
    let again = map
        .take_localized(&node("r", 7, 7, 7, 61.0), false)
        .unwrap();
    assert_eq!((again.first_seq, again.last_seq), (7, 7));
    spans.push(again);
    // A robot that only ever localized: its chain is known to the sequence, not as a robot.
    let only = map.take_localized(&node("q", 1, 0, 0, 0.0), false).unwrap();
    spans.push(only);
    assert_eq!(map.robots().len(), 1);
    assert_eq!(map.chain_acked("q", 1), Some(0));

    // A replay of the mapped nodes with the stored spans (the last of each run) ends where
    // the live map did: same network, same sequence.
    let stored: Vec<LocalizedSpan> = vec![spans[2].clone(), spans[3].clone(), spans[4].clone()];
    let mut replayed = self::map();
    let mut replay = SpanReplay::new(stored);
    for (seq, x) in [(0, 0.0), (1, 1.0), (2, 2.0), (6, 60.0)] {
        let n = node("r", 7, seq, if seq == 6 { 6 } else { 0 }, x);
        replay.before(&mut replayed, &n);
        replayed.ingest(&n).unwrap();
    }
    replay.rest(&mut replayed);
    assert_eq!(replayed.graph().edges, map.graph().edges);
    assert_eq!(replayed.chain_acked("r", 7), Some(7));
    assert_eq!(replayed.chain_acked("q", 1), Some(0));
    // The open run goes on in the same span.
    let next = replayed
        .take_localized(&node("r", 7, 8, 8, 62.0), false)
        .unwrap();
    assert_eq!((next.first_seq, next.last_seq), (7, 8));
}
