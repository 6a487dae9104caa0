//! Acks delete only what they name: while a robot publishes, someone on the bus puts acks on
//! its ack key that name another chain, or its own chain but nodes it never made. The robot
//! ignores them (and counts them), and every node it made is still mapped exactly once.
//! (Who may put acks at all is the access-control list's business: e2e_security.)

mod common;

use common::*;
use std::time::Duration;
use wire::{Message, v1};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn acks_that_name_other_chains_or_unmade_nodes_delete_nothing() {
    let dir = temp_dir("forged-ack");
    let mapper = MapperProcess::start(&dir);
    let http = mapper.http.clone();
    let session = runtime::session::SessionConfig::client(&mapper.zenoh)
        .open(runtime::session::Role::Client)
        .await
        .expect("a client of the mapper's router");
    // 60 s of park at 4x: 15 s of driving.
    let edge = spawn_edge(&dir, 0, &mapper.zenoh, 60.0, 4.0);
    let chain_id = {
        let h = http.clone();
        tokio::task::spawn_blocking(move || {
            wait_for(Duration::from_secs(60), || {
                let robots = get_json(&h, "/api/v1/fleets/park/robots")?;
                robots["robots"][0]["chains"][0]["chain_id"].as_u64()
            })
        })
        .await
        .unwrap()
        .expect("robot0's chain on the map")
    };
    let key = wire::ack_key("park", "robot0").unwrap();
    let forged = |chain_id: u64, acked: u64| v1::Ack {
        header: Some(v1::Header::new("park", "robot0", 0, 1, 1)),
        acked_node_seq: Some(acked),
        chain_id,
        resend_from: None,
    };
    // Every 100 ms while it drives: "everything up to node 1,000,000 is stored", for its
    // chain and for another.
    for k in 0..50u64 {
        for ack in [forged(chain_id, 1_000_000 + k), forged(chain_id ^ 1, 5 + k)] {
            session.put(&key, ack.encode_to_vec()).await.expect("put");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let report = tokio::task::spawn_blocking(move || edge_report(edge, Duration::from_secs(120)))
        .await
        .unwrap();
    assert!(
        report["acks_ignored"].as_u64().unwrap() >= 50,
        "the forged acks reached the robot and were ignored: {report}"
    );
    assert_eq!(report["outbox_pending"], 0, "{report}");
    let made = report["nodes"].as_u64().unwrap();
    let seqs = tokio::task::spawn_blocking(move || node_seqs(&http, "park", "robot0"))
        .await
        .unwrap();
    assert_eq!(
        seqs,
        (0..made).collect::<Vec<_>>(),
        "every node, once: {report}"
    );
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
