//! Crash: the mapper is killed (SIGKILL) while two robots publish, then restarted on the same
//! store. Every node it had acked is in the restored map, and every node the robots made
//! reaches the map (their outboxes replay what was not acked), each with its 3D cloud.
//! Checked through HTTP only.

mod common;

use common::*;
use std::time::Duration;

const ROBOTS: usize = 2;

#[test]
fn every_acked_node_survives_a_mapper_kill_and_every_node_arrives() {
    let dir = temp_dir("crash");
    let mapper = MapperProcess::start(&dir);
    // 60 s of driving at 4× speed: 15 nodes per robot over ~15 s.
    let edges: Vec<_> = (0..ROBOTS)
        .map(|r| spawn_edge(&dir, r, &mapper.zenoh, 60.0, 4.0))
        .collect();
    let http = mapper.http.clone();
    // Kill once both robots have nodes in the map.
    let before = wait_for(Duration::from_secs(60), || {
        let seqs: Vec<Vec<u64>> = (0..ROBOTS)
            .map(|r| node_seqs(&http, "park", &format!("robot{r}")))
            .collect();
        seqs.iter().all(|s| s.len() >= 3).then_some(seqs)
    })
    .expect("both robots' nodes reach the map");
    let ports = mapper.kill();
    std::thread::sleep(Duration::from_secs(2));
    let mapper = MapperProcess::restart(ports);

    // Restored from the store: everything seen before the kill (a node is in the map's view
    // only after its commit).
    assert_restored(&mapper.http, &before);
    for (r, edge) in edges.into_iter().enumerate() {
        let report = edge_report(edge, Duration::from_secs(120));
        let made = report["nodes"].as_u64().expect("nodes");
        assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
        assert!(
            report["node_resends"].as_u64().unwrap() > 0,
            "robot{r} had to re-send: {report}"
        );
        let seqs = node_seqs(&mapper.http, "park", &format!("robot{r}"));
        assert_eq!(
            seqs,
            (0..made).collect::<Vec<_>>(),
            "robot{r}: every node made, once, in order"
        );
    }
    let summary = get_json(&mapper.http, "/api/v1/fleets/park/summary").expect("summary");
    assert_eq!(summary["robots"], ROBOTS);
    // Every node's cloud, those stored before the kill too, under the node's own id.
    let graph = get_json(&mapper.http, "/api/v1/fleets/park/graph").expect("graph");
    for node in graph["nodes"].as_array().expect("nodes") {
        let path = format!("/api/v1/fleets/park/nodes/{}/cloud", node["id"]);
        let cloud = get_json(&mapper.http, &path).unwrap_or_else(|| panic!("{path}"));
        assert_eq!(
            (&cloud["robot"], &cloud["node_seq"]),
            (&node["robot"], &node["node_seq"])
        );
        assert!(cloud["kept"].as_u64().unwrap() > 0, "{path}");
    }
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
