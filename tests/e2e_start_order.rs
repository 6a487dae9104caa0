//! Robots that boot before the mapper (out of radio range, or the server restarting) record
//! from the start: their nodes wait in the outbox and are all mapped once the mapper is up.

mod common;

use common::*;
use std::time::Duration;

#[test]
fn a_robot_started_before_the_mapper_loses_nothing() {
    let dir = temp_dir("start-order");
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    // 20 s of park at 4x: the robot drives for 5 s, the mapper comes up after 3 s.
    let early = spawn_edge(&dir, 0, &zenoh, 20.0, 4.0);
    std::thread::sleep(Duration::from_secs(3));
    let mapper = MapperProcess::start_on(&dir, zenoh);
    let report = edge_report(early, Duration::from_secs(120));
    let made = report["nodes"].as_u64().expect("nodes made");
    assert!(made >= 5, "{report}");
    assert_eq!(report["outbox_pending"], 0, "{report}");
    let seqs = node_seqs(&mapper.http, "park", "robot0");
    assert_eq!(seqs, (0..made).collect::<Vec<_>>(), "{report}");
    std::fs::remove_dir_all(&dir).ok();
}
