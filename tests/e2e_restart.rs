//! Restart from a snapshot: the mapper is stopped gracefully while two robots publish (it
//! writes each fleet's snapshot as it stops), started again, takes more nodes, and is
//! SIGKILLed. `levelmap mapper --verify-store` then finds the snapshot and the nodes after
//! it, and that they restore exactly what a full replay of the store maps; the mapper
//! restarted on the store has every node it had acked, and the robots' other nodes arrive.

mod common;

use common::*;
use std::time::Duration;

const ROBOTS: usize = 2;
/// Periodic snapshots off: the one written at the graceful stop is the only one.
const CONFIG: &str = "[store]\nsnapshot_every_nodes = 100000\n";

/// Every robot's node_seqs in the map, once each robot has at least `at_least`.
fn nodes_in_map(http: &str, at_least: usize) -> Vec<Vec<u64>> {
    wait_for(Duration::from_secs(60), || {
        let seqs: Vec<Vec<u64>> = (0..ROBOTS)
            .map(|r| node_seqs(http, "park", &format!("robot{r}")))
            .collect();
        seqs.iter().all(|s| s.len() >= at_least).then_some(seqs)
    })
    .expect("the robots' nodes reach the map")
}

#[test]
fn a_mapper_killed_after_its_snapshot_restarts_to_what_a_full_replay_maps() {
    let dir = temp_dir("restart");
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let mapper = MapperProcess::start_with(&dir, zenoh, CONFIG);
    // 60 s of driving at 4× speed: 15 nodes per robot over ~15 s.
    let edges: Vec<_> = (0..ROBOTS)
        .map(|r| spawn_edge(&dir, r, &mapper.zenoh, 60.0, 4.0))
        .collect();
    nodes_in_map(&mapper.http, 3);
    let ports = mapper.stop();
    let (code, stopped) = verify_store(&ports.config);
    assert_eq!(code, Some(0), "{stopped}");
    let snapshot_nodes = stopped["fleets"][0]["snapshot"]["covers"].as_u64().unwrap();
    assert_eq!(
        snapshot_nodes,
        stopped["fleets"][0]["nodes"].as_u64().unwrap(),
        "the snapshot at the stop covers every node: {stopped}"
    );

    // Started from the snapshot; more nodes; killed.
    let mapper = MapperProcess::restart(ports);
    let before = nodes_in_map(&mapper.http, 3 + snapshot_nodes as usize / ROBOTS + 3);
    let ports = mapper.kill();
    let (code, killed) = verify_store(&ports.config);
    let fleet = &killed["fleets"][0];
    assert_eq!(code, Some(0), "{killed}");
    assert_eq!(fleet["snapshot"]["covers"].as_u64(), Some(snapshot_nodes));
    assert!(
        fleet["nodes"].as_u64().unwrap() >= snapshot_nodes + 6,
        "nodes after the snapshot: {killed}"
    );
    assert_eq!(fleet["snapshot"]["differences"], serde_json::json!([]));

    // Restored from the snapshot and the nodes after it: everything acked before the kill.
    let mapper = MapperProcess::restart(ports);
    assert_restored(&mapper.http, &before);
    for (r, edge) in edges.into_iter().enumerate() {
        let report = edge_report(edge, Duration::from_secs(120));
        let made = report["nodes"].as_u64().expect("nodes");
        let seqs = node_seqs(&mapper.http, "park", &format!("robot{r}"));
        assert_eq!(
            seqs,
            (0..made).collect::<Vec<_>>(),
            "robot{r}: every node, once, in order"
        );
    }
    // The last restart's map, taken from the snapshot, and a full replay agree on the store.
    let ports = mapper.kill();
    let (code, last) = verify_store(&ports.config);
    assert_eq!(code, Some(0), "{last}");
    std::fs::remove_dir_all(&dir).ok();
}
