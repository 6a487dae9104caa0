//! Faults stay local: a fleet whose stored rows do not replay is quarantined at start, while
//! the other fleets are restored and keep mapping. Two fleets are mapped by the real mapper,
//! which is killed; one row of one fleet is overwritten in the redb file (as a bad disk
//! sector or a bad copy would); the restarted mapper serves the healthy fleet, answers 503
//! with the reason for the other, and leaves that fleet's new nodes unacked in the robots'
//! outboxes.

mod common;

use common::*;
use redb::ReadableTable;
use std::time::{Duration, Instant};

const NODES: redb::TableDefinition<(&str, u64), &[u8]> = redb::TableDefinition::new("nodes");

#[test]
fn a_fleet_whose_rows_do_not_replay_is_quarantined_and_the_others_run() {
    let dir = temp_dir("quarantine");
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let fleets = "fleets = [\"park\", \"campus\"]";
    let mapper = MapperProcess::start_with(&dir, zenoh.clone(), fleets);
    // 24 s of park at 4x each: a handful of nodes per fleet.
    let park = spawn_edge_env(&dir, 0, &zenoh, (24.0, 4.0), &[]);
    let campus = spawn_edge_env(
        &dir,
        1,
        &zenoh,
        (24.0, 4.0),
        &[("LEVELMAP_FLEET", "campus")],
    );
    let park_made = edge_report(park, Duration::from_secs(120))["nodes"]
        .as_u64()
        .unwrap();
    let campus_made = edge_report(campus, Duration::from_secs(120))["nodes"]
        .as_u64()
        .unwrap();
    assert!(
        park_made >= 3 && campus_made >= 3,
        "{park_made}, {campus_made}"
    );
    assert_eq!(
        node_seqs(&mapper.http, "campus", "robot1").len() as u64,
        campus_made
    );
    let ports = mapper.kill();

    // One campus node's row becomes bytes that are no node.
    {
        let db = redb::Database::open(dir.join("mapper.redb")).expect("the store opens");
        let txn = db.begin_write().unwrap();
        let mut nodes = txn.open_table(NODES).unwrap();
        assert!(nodes.get(("campus", 1)).unwrap().is_some());
        nodes
            .insert(("campus", 1), &b"\xff\xff not a node"[..])
            .unwrap();
        drop(nodes);
        txn.commit().unwrap();
    }

    let started = Instant::now();
    let mapper = MapperProcess::restart(ports);
    eprintln!(
        "restarted with a quarantine in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let http = mapper.http.clone();
    let (status, body) = http_get(&http, "/healthz").expect("healthz");
    let health: serde_json::Value = serde_json::from_str(&body).expect("JSON health");
    assert_eq!(
        (status, &health["status"]),
        (200, &"degraded".into()),
        "{body}"
    );
    let reason = health["quarantined"]["campus"]
        .as_str()
        .expect("campus quarantined");
    assert!(reason.contains("node 1 of fleet campus"), "{reason}");
    assert!(health["quarantined"].get("park").is_none(), "{body}");

    // The fleet list names it apart, with the reason.
    let (status, body) = http_get(&http, "/api/v1/fleets").expect("fleets");
    assert_eq!(status, 200, "{body}");
    let list: serde_json::Value = serde_json::from_str(&body).expect("JSON");
    assert_eq!(list["fleets"], serde_json::json!(["park"]), "{body}");
    assert_eq!(list["quarantined"][0]["fleet"], "campus", "{body}");
    assert_eq!(
        list["quarantined"][0]["reason"].as_str(),
        Some(reason),
        "{body}"
    );

    // The quarantined fleet's routes: 503, the reason as JSON.
    for path in [
        "summary",
        "robots",
        "graph",
        "map.png",
        "robots/robot1/pose",
    ] {
        let (status, body) =
            http_get(&http, &format!("/api/v1/fleets/campus/{path}")).expect("an answer");
        assert_eq!(status, 503, "{path}: {body}");
        let why: serde_json::Value = serde_json::from_str(&body).expect("JSON reason");
        assert_eq!(why["fault"], "quarantined", "{body}");
        assert_eq!(why["fleet"], "campus", "{body}");
        assert_eq!(why["reason"].as_str(), Some(reason), "{body}");
    }
    // The healthy fleet: restored whole, and it keeps mapping.
    assert_eq!(
        node_seqs(&http, "park", "robot0"),
        (0..park_made).collect::<Vec<_>>()
    );
    let more_park = spawn_edge_env(&dir, 2, &zenoh, (16.0, 4.0), &[]);
    // A campus robot's nodes are not taken: not acked, they stay in its outbox.
    let no_linger = [
        ("LEVELMAP_FLEET", "campus"),
        ("LEVELMAP_LINGER_FOR_ACKS", "false"),
    ];
    let more_campus = spawn_edge_env(&dir, 3, &zenoh, (16.0, 4.0), &no_linger);
    let report = edge_report(more_park, Duration::from_secs(120));
    let made = report["nodes"].as_u64().unwrap();
    assert_eq!(report["outbox_pending"], 0, "{report}");
    assert_eq!(
        node_seqs(&http, "park", "robot2"),
        (0..made).collect::<Vec<_>>()
    );
    let report = edge_report(more_campus, Duration::from_secs(120));
    assert!(report["nodes"].as_u64().unwrap() >= 2, "{report}");
    assert_eq!(report["outbox_pending"], report["nodes"], "{report}");
    assert!(report["acked_node_seq"].is_null(), "{report}");
    let metrics = http_get(&http, "/metrics").expect("metrics").1;
    let refused = metric(
        &metrics,
        "levelmap_rejected_total{topic=\"node\",reason=\"quarantined\"}",
    );
    assert!(refused >= 2, "{metrics}");
    eprintln!(
        "park: {park_made} + {made} nodes mapped; campus: {campus_made} stored, quarantined; \
         {refused} campus nodes refused after the restart"
    );
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
