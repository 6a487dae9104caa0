//! Outage: one robot's link to the mapper goes down for a while (a TCP relay drops its
//! connections and refuses new ones) while it keeps driving and making nodes. Nothing is
//! lost: after the link is back, every node it made is in the map, in order; and the gap the
//! outage left is re-sent at once, while the robot keeps making nodes (not when it stops).
//! And a link that stays open but reaches no mapper is replaced by the edge itself.

mod common;

use common::*;
use std::time::Duration;
use zenoh::Wait;

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

/// A transport Zenoh keeps open while nothing behind it routes the robot's nodes (what a
/// reconnection racing the router's teardown of the old transport can leave,
/// eclipse-zenoh/zenoh#1886; seen once in the partition drill). Here the robot's first
/// connection lands on a router with no mapper behind it: it answers keepalives and never
/// acks. The edge hears nothing for `reopen_link_after_ms` with nodes waiting, opens a new
/// session, and the relay takes that one to the mapper. With the reopening off, the robot's
/// nodes would wait in its outbox for good.
#[test]
fn a_link_that_stays_open_but_reaches_no_mapper_is_replaced() {
    let dir = temp_dir("unrouted");
    let mapper = MapperProcess::start(&dir);
    let dead_end = format!("tcp/127.0.0.1:{}", free_port());
    let mut config = zenoh::Config::default();
    for (key, value) in [
        ("mode", "\"router\"".to_owned()),
        ("listen/endpoints", format!("[\"{dead_end}\"]")),
        ("scouting/multicast/enabled", "false".to_owned()),
    ] {
        config.insert_json5(key, &value).expect("router config");
    }
    let router = zenoh::open(config)
        .wait()
        .expect("a router without a mapper");
    let relay = Relay::start_to(&[&dead_end, &mapper.zenoh]);
    let edge = spawn_edge_env(
        &dir,
        0,
        &relay.endpoint,
        (40.0, 4.0),
        &[("LEVELMAP_REOPEN_LINK_AFTER_MS", "3000")],
    );
    let report = edge_report(edge, Duration::from_secs(120));
    assert!(
        report["link_reopens"].as_u64().expect("link_reopens") >= 1,
        "{report}"
    );
    assert_eq!(report["outbox_pending"], 0, "{report}");
    let made = report["nodes"].as_u64().expect("nodes");
    assert_eq!(
        node_seqs(&mapper.http, "park", "robot0"),
        (0..made).collect::<Vec<_>>(),
        "every node, once, in order"
    );
    router.close().wait().expect("router closes");
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
