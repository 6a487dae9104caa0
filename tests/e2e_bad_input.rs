//! Bad input on the wire: garbage bytes, a wrong wire version, NaN ranges, a cloud with fewer
//! classes than points, a duplicate and an out-of-order node, an unknown fleet, a key that
//! disagrees with the header. Each is
//! rejected and counted by reason on /metrics, the mapper keeps running, and the nodes it had
//! accepted are all still in the map. A real mapper and a real Zenoh client over TCP on
//! loopback; the outcome is read through HTTP only.

mod common;

use common::*;
use std::time::Duration;
use wire::Message;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_messages_are_counted_and_rejected_and_nothing_accepted_is_lost() {
    let dir = temp_dir("bad-input");
    let (mapper, session, http) = in_process_mapper(&dir, "").await;
    let key = wire::node_key("park", "robot0").unwrap();
    let put = |key: String, bytes: Vec<u8>| {
        let session = session.clone();
        async move { session.put(key, bytes).await.expect("put") }
    };
    let nodes = real_nodes(2);
    let metrics = || {
        let h = http.clone();
        async move {
            tokio::task::spawn_blocking(move || http_get(&h, "/metrics").expect("metrics").1)
                .await
                .unwrap()
        }
    };
    let seqs = || {
        let h = http.clone();
        async move {
            tokio::task::spawn_blocking(move || node_seqs(&h, "park", "robot0"))
                .await
                .unwrap()
        }
    };

    // Node 0, re-sent until the mapper's subscription has reached us (as the edge does).
    loop {
        put(key.clone(), nodes[0].encode_to_vec()).await;
        tokio::time::sleep(Duration::from_millis(300)).await;
        if seqs().await == [0] {
            break;
        }
    }
    let duplicates_before = metric(&metrics().await, "levelmap_nodes_duplicate_total");

    let mut version = nodes[1].clone();
    version.header.as_mut().unwrap().version = 2;
    let mut nan = nodes[1].clone();
    nan.scan.as_mut().unwrap().range_m[3] = f32::NAN;
    let mut bad_cloud = nodes[1].clone();
    bad_cloud.cloud.as_mut().expect("a cloud").classes.pop();
    let mut ahead = nodes[1].clone();
    ahead.node_seq = 5;
    // A well-formed node of robot9, sent on robot0's key.
    let mut other_robot = nodes[1].clone();
    for header in other_robot.headers_mut() {
        header.robot_id = "robot9".into();
    }
    let cases: Vec<(String, Vec<u8>, &str)> = vec![
        (key.clone(), b"\xff\x00garbage".to_vec(), "malformed"),
        (key.clone(), version.encode_to_vec(), "version"),
        (key.clone(), nan.encode_to_vec(), "invalid_value"),
        (key.clone(), bad_cloud.encode_to_vec(), "inconsistent"),
        (key.clone(), ahead.encode_to_vec(), "out_of_order"),
        (
            wire::node_key("elsewhere", "robot0").unwrap(),
            nodes[1].encode_to_vec(),
            "unknown_fleet",
        ),
        (key.clone(), other_robot.encode_to_vec(), "key_mismatch"),
    ];
    for (key, bytes, reason) in &cases {
        put(key.clone(), bytes.clone()).await;
        let series = format!("levelmap_rejected_total{{topic=\"node\",reason=\"{reason}\"}}");
        let mut counted = 0;
        for _ in 0..50 {
            counted = metric(&metrics().await, &series);
            if counted > 0 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        assert_eq!(counted, 1, "{reason}: not counted once on /metrics");
    }
    // A duplicate is re-acked and counted, not mapped twice.
    put(key.clone(), nodes[0].encode_to_vec()).await;
    // The next node in order is still taken after all that.
    put(key.clone(), nodes[1].encode_to_vec()).await;
    let mut seen = Vec::new();
    for _ in 0..50 {
        seen = seqs().await;
        if seen.len() == 2 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(seen, [0, 1], "accepted nodes kept, nothing else mapped");
    let text = metrics().await;
    assert_eq!(
        metric(&text, "levelmap_nodes_duplicate_total"),
        duplicates_before + 1
    );
    assert_eq!(metric(&text, "levelmap_nodes_accepted_total"), 2);
    let h = http.clone();
    let health = tokio::task::spawn_blocking(move || http_get(&h, "/healthz"))
        .await
        .unwrap();
    assert_eq!(health.map(|h| h.0), Some(200));
    session.close().await.unwrap();
    mapper.stop().await.expect("mapper stops");
    std::fs::remove_dir_all(&dir).ok();
}
