//! Outage: one robot's link to the mapper goes down for a while (a TCP relay drops its
//! connections and refuses new ones) while it keeps driving and making nodes. Nothing is
//! lost: after the link is back, every node it made is in the map, in order; and the gap the
//! outage left is re-sent at once, while the robot keeps making nodes (not when it stops).

mod common;

use common::*;
use std::time::Duration;

#[test]
fn no_node_is_lost_when_a_robot_is_cut_off_for_a_while() {
    let dir = temp_dir("outage");
    let mapper = MapperProcess::start(&dir);
    let relay = Relay::start(&mapper.zenoh);
    // 400 s of park at 16x: robot0 drives for 25 s, long past the cut, making a node every
    // 0.25 s or so: faster than its resend timer (500 ms) could ever fire without acks.
    let mut cut_off = spawn_edge(&dir, 0, &relay.endpoint, 400.0, 16.0);
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
    let restored = std::time::Instant::now();
    // The nodes made during the cut were put into a dead link: the first node after it shows
    // the mapper a gap, and the ack's resend_from brings them at once. Before, each new node
    // reset the edge's resend timer, so the gap waited until the robot stopped.
    let caught_up = wait_for(Duration::from_secs(10), || {
        let now = seqs(0);
        let contiguous = now.iter().enumerate().all(|(i, &s)| s == i as u64);
        (contiguous && now.len() > during + 10).then_some(now.len())
    })
    .expect("the map catches up with robot0 after the cut");
    let catch_up_s = restored.elapsed().as_secs_f64();
    assert!(
        cut_off.try_wait().expect("edge status").is_none(),
        "caught up ({caught_up} nodes, {catch_up_s:.1} s after the link came back) only once \
         robot0 stopped driving"
    );
    eprintln!(
        "after the cut: {caught_up} nodes in the map {catch_up_s:.1} s after the link came back"
    );

    let report = edge_report(cut_off, Duration::from_secs(120));
    let made = report["nodes"].as_u64().expect("nodes");
    // 6 s at 16× is 96 s of driving: robot0 made nodes the map could not see.
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
