//! Outage: one robot's link to the mapper goes down for a while (a TCP relay drops its
//! connections and refuses new ones) while it keeps driving and making nodes. Nothing is
//! lost: after the link is back, every node it made is in the map, in order.

mod common;

use common::*;
use std::time::Duration;

#[test]
fn no_node_is_lost_when_a_robot_is_cut_off_for_a_while() {
    let dir = temp_dir("outage");
    let mapper = MapperProcess::start(&dir);
    let relay = Relay::start(&mapper.zenoh);
    let cut_off = spawn_edge(&dir, 0, &relay.endpoint, 60.0, 4.0);
    let direct = spawn_edge(&dir, 1, &mapper.zenoh, 60.0, 4.0);
    let http = mapper.http.clone();
    let seqs = |r: usize| node_seqs(&http, "park", &format!("robot{r}"));
    wait_for(Duration::from_secs(60), || {
        (seqs(0).len() >= 2).then_some(())
    })
    .expect("robot0's nodes reach the map");

    relay.cut();
    let at_cut = seqs(0).len();
    std::thread::sleep(Duration::from_secs(6));
    let during = seqs(0).len();
    // The other robot kept mapping meanwhile.
    assert!(!seqs(1).is_empty());
    relay.restore();

    let report = edge_report(cut_off, Duration::from_secs(120));
    let made = report["nodes"].as_u64().expect("nodes");
    // 6 s at 4× is 24 s of driving: robot0 made nodes the map could not see.
    assert!(
        during <= at_cut + 1 && made as usize > during + 2,
        "the cut was real: {at_cut} nodes at the cut, {during} after 6 s, {made} made"
    );
    assert_eq!(report["outbox_pending"], 0, "{report}");
    assert_eq!(
        seqs(0),
        (0..made).collect::<Vec<_>>(),
        "every node, once, in order"
    );
    let other = edge_report(direct, Duration::from_secs(120));
    assert_eq!(seqs(1).len() as u64, other["nodes"].as_u64().unwrap());
    // Robots get their corrected poses back after the mapper's solves.
    assert!(other["map_pose_updates"].as_u64().unwrap() > 0, "{other}");
    assert!(other["map_pose"]["x"].is_number(), "{other}");
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
