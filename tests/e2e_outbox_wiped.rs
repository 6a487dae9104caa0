//! A robot whose outbox is lost (a new disk, a wiped SD card) starts numbering again from 0:
//! its new nodes are a second chain of the same robot in the same map, not duplicates.

mod common;

use common::*;
use std::time::Duration;

#[test]
fn a_wiped_outbox_starts_a_second_chain_and_nothing_is_lost() {
    let dir = temp_dir("outbox-wiped");
    let mapper = MapperProcess::start(&dir);
    let mut made = Vec::new();
    for run in 0..2 {
        // 100 s of park at 8x: about 25 nodes.
        let edge = spawn_edge(&dir, 0, &mapper.zenoh, 100.0, 8.0);
        let report = edge_report(edge, Duration::from_secs(120));
        assert_eq!(report["outbox_pending"], 0, "run {run}: {report}");
        made.push(report["nodes"].as_u64().expect("nodes"));
        std::fs::remove_file(dir.join("robot0-outbox.redb")).expect("outbox wiped");
    }
    assert!(made.iter().all(|&n| n >= 20), "20 nodes a run: {made:?}");
    let seqs = node_seqs(&mapper.http, "park", "robot0");
    let expected: Vec<u64> = (0..made[0]).chain(0..made[1]).collect();
    assert_eq!(seqs, expected, "both runs' nodes, each once");
    let robots = get_json(&mapper.http, "/api/v1/fleets/park/robots").expect("robots");
    let robot = &robots["robots"][0];
    assert_eq!(robots["robots"].as_array().unwrap().len(), 1, "{robots}");
    let chains: Vec<(u64, u64)> = robot["chains"]
        .as_array()
        .expect("chains")
        .iter()
        .map(|c| {
            (
                c["first_node_seq"].as_u64().unwrap(),
                c["last_node_seq"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(chains, [(0, made[0] - 1), (0, made[1] - 1)], "{robot}");
    let ids: Vec<&serde_json::Value> = robot["chains"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| &c["chain_id"])
        .collect();
    assert_ne!(ids[0], ids[1]);
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
