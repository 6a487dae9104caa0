//! Disk full: the mapper's store lives on a small tmpfs, which a filler file fills while a
//! robot drives. Commits fail: the mapper acks nothing more, answers 503 (with the reason and
//! `Retry-After`) where the store is needed and on `/healthz`, and keeps serving the map it
//! committed. Once the filler is gone it resumes by itself, and every node the robot made is
//! mapped exactly once, in order; a restart on that store replays it without a fault (the map
//! and the store did not diverge). Needs root for `mount` (CI runs as root); fails otherwise.

mod common;
#[path = "../services/sitelog/tests/common/tmpfs.rs"]
mod tmpfs;

use common::*;
use std::time::{Duration, Instant};
use tmpfs::{Tmpfs, fill};

fn counter(http: &str, series: &str) -> u64 {
    metric(&http_get(http, "/metrics").expect("metrics").1, series)
}

fn health(http: &str) -> (u16, serde_json::Value) {
    let (status, body) = http_get(http, "/healthz").expect("healthz");
    (status, serde_json::from_str(&body).expect("JSON health"))
}

#[test]
fn a_full_disk_stops_the_acks_and_the_mapper_resumes_when_there_is_room() {
    let dir = temp_dir("disk-full");
    let disk = Tmpfs::mount(&dir.join("store"), "16m");
    let store = disk.0.join("mapper.redb");
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let mapper = MapperProcess::start_with(&dir, zenoh.clone(), &format!("store_path = {store:?}"));
    let http = mapper.http.clone();
    // 120 s of park at 4x: a node a second or so, each with its 3D cloud (~67 KB stored).
    let robot = spawn_edge(&dir, 0, &zenoh, 120.0, 4.0);
    let seqs = || node_seqs(&http, "park", "robot0");
    wait_for(Duration::from_secs(60), || {
        (seqs().len() >= 3).then_some(())
    })
    .expect("the robot's first nodes are mapped");

    let filled_at = Instant::now();
    let filler = disk.0.join("filler");
    let filled = fill(&filler);
    let (status, full) = wait_for(Duration::from_secs(60), || {
        let (status, h) = health(&http);
        (status == 503).then_some((status, h))
    })
    .expect("/healthz reports the failed commit");
    let to_detect = filled_at.elapsed();
    assert_eq!(
        (status, &full["status"]),
        (503, &"degraded".into()),
        "{full}"
    );
    let reason = full["store"].as_str().expect("the store's fault");
    assert!(reason.contains("No space left"), "{reason}");

    // While full: nothing more is mapped or acked, though the robot keeps sending.
    let (mapped, acks) = (seqs(), counter(&http, "levelmap_acks_sent_total"));
    let refused = |h: &str| {
        counter(
            h,
            "levelmap_rejected_total{topic=\"node\",reason=\"store\"}",
        )
    };
    let refused_before = refused(&http);
    std::thread::sleep(Duration::from_secs(4));
    assert_eq!(seqs(), mapped, "no node is mapped while the disk is full");
    assert_eq!(counter(&http, "levelmap_acks_sent_total"), acks, "no ack");
    assert!(refused(&http) > refused_before, "the robot kept sending");
    // A route that reads the store: 503 with the reason and Retry-After; the map still serves.
    let response = agent()
        .get(format!("http://{http}/api/v1/fleets/park/nodes/0/cloud"))
        .call()
        .expect("an answer");
    assert_eq!(response.status().as_u16(), 503);
    assert_eq!(
        response
            .headers()
            .get("retry-after")
            .map(|v| v.to_str().unwrap()),
        Some("5")
    );
    let body: serde_json::Value =
        serde_json::from_str(&response.into_body().read_to_string().unwrap()).unwrap();
    assert_eq!(body["fault"], "store", "{body}");
    assert!(get_json(&http, "/api/v1/fleets/park/summary").is_some());
    let full_for = filled_at.elapsed();

    let freed_at = Instant::now();
    std::fs::remove_file(&filler).expect("filler removed");
    wait_for(Duration::from_secs(60), || {
        (health(&http).0 == 200).then_some(())
    })
    .expect("the mapper resumes by itself");
    let to_resume = freed_at.elapsed();
    let first_new = wait_for(Duration::from_secs(60), || {
        (seqs().len() > mapped.len()).then_some(freed_at.elapsed())
    })
    .expect("nodes are mapped again");

    let report = edge_report(robot, Duration::from_secs(180));
    let made = report["nodes"].as_u64().unwrap();
    assert_eq!(report["outbox_pending"], 0, "{report}");
    assert_eq!(
        seqs(),
        (0..made).collect::<Vec<_>>(),
        "every node once, in order"
    );
    let (status, h) = health(&http);
    assert_eq!((status, &h["status"]), (200, &"ok".into()), "{h}");
    eprintln!(
        "disk full: {} KB filler; 503 after {:.1} s; {} nodes mapped before, none for {:.1} s \
         while {} re-sent nodes were refused; /healthz 200 {:.1} s after the filler went, the \
         next node mapped after {:.1} s; {made} nodes made, {made} mapped once ({} sends, {} \
         re-sends)",
        filled / 1024,
        to_detect.as_secs_f64(),
        mapped.len(),
        full_for.as_secs_f64(),
        refused(&http) - refused_before,
        to_resume.as_secs_f64(),
        first_new.as_secs_f64(),
        report["node_sends"],
        report["node_resends"],
    );

    // The store holds what the map held: a restart replays it, with nothing quarantined.
    let mapper = MapperProcess::restart(mapper.kill());
    let (status, h) = health(&mapper.http);
    assert_eq!((status, &h["status"]), (200, &"ok".into()), "{h}");
    assert_eq!(
        node_seqs(&mapper.http, "park", "robot0"),
        (0..made).collect::<Vec<_>>()
    );
    drop(mapper);
    drop(disk);
    std::fs::remove_dir_all(&dir).ok();
}
