//! Kill loops: SIGKILL the mapper again and again while three robots publish, and SIGKILL one
//! robot's edge service again and again: every node made is in the map exactly once.
//! The pauses between kills are random (1.5–4 s) from a seed printed for a re-run
//! (`LEVELMAP_DRILL_SEED`).

mod common;

use common::*;
use std::time::{Duration, Instant};

const ROBOTS: usize = 3;
const KILLS: usize = 10;

/// Pauses of 1.5–4 s, from a seed (splitmix64: the drill needs no crate for this).
struct Pauses(u64);

impl Pauses {
    fn new() -> Pauses {
        let seed = std::env::var("LEVELMAP_DRILL_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(runtime::session::now_ns);
        eprintln!("kill-loop seed: LEVELMAP_DRILL_SEED={seed}");
        Pauses(seed)
    }

    fn next(&mut self) -> Duration {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        let unit = (z ^ (z >> 31)) as f64 / u64::MAX as f64;
        Duration::from_secs_f64(1.5 + 2.5 * unit)
    }
}

/// Every node of `robot`'s one chain, 0 up to its last acked, exactly once, in order.
fn assert_all_once(http: &str, robot: &str, report: &serde_json::Value) {
    assert_eq!(report["outbox_pending"], 0, "{robot}: {report}");
    let last = report["acked_node_seq"].as_u64().expect("acked");
    let seqs = node_seqs(http, "park", robot);
    eprintln!(
        "{robot}: {} nodes mapped once, {} re-sends",
        last + 1,
        report["node_resends"]
    );
    assert_eq!(
        seqs,
        (0..=last).collect::<Vec<_>>(),
        "{robot}: every node made, once, in order"
    );
}

#[test]
fn ten_mapper_kills_while_three_robots_publish_lose_and_repeat_nothing() {
    let dir = temp_dir("mapper-kill-loop");
    let mut mapper = MapperProcess::start(&dir);
    // 180 s of park at 4x: the robots drive for 45 s, through every kill.
    let edges: Vec<KillOnDrop> = (0..ROBOTS)
        .map(|r| spawn_edge(&dir, r, &mapper.zenoh, 180.0, 4.0))
        .collect();
    let mut pauses = Pauses::new();
    let started = Instant::now();
    for _ in 0..KILLS {
        std::thread::sleep(pauses.next());
        mapper = MapperProcess::restart(mapper.kill());
    }
    eprintln!("{KILLS} kills in {:.1} s", started.elapsed().as_secs_f64());
    for (r, edge) in edges.into_iter().enumerate() {
        let report = edge_report(edge, Duration::from_secs(180));
        assert!(report["node_resends"].as_u64().unwrap() > 0, "{report}");
        assert_all_once(&mapper.http, &format!("robot{r}"), &report);
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn ten_edge_kills_lose_and_repeat_nothing() {
    let dir = temp_dir("edge-kill-loop");
    let mapper = MapperProcess::start(&dir);
    let steady: Vec<KillOnDrop> = (1..ROBOTS)
        .map(|r| spawn_edge(&dir, r, &mapper.zenoh, 120.0, 4.0))
        .collect();
    let mut pauses = Pauses::new();
    // Robot 0 restarts on its outbox each time (its simulator from the start: an odometry
    // reset, which the mapper takes as a break in odometry, not as a fault).
    for _ in 0..KILLS {
        let mut edge = spawn_edge(&dir, 0, &mapper.zenoh, 120.0, 4.0);
        std::thread::sleep(pauses.next());
        edge.kill().expect("SIGKILL");
        edge.wait().expect("reaped");
    }
    let last = spawn_edge(&dir, 0, &mapper.zenoh, 20.0, 4.0);
    let report = edge_report(last, Duration::from_secs(120));
    assert!(
        report["acked_node_seq"].as_u64().unwrap() >= 10,
        "the killed runs made nodes: {report}"
    );
    assert_all_once(&mapper.http, "robot0", &report);
    let robots = get_json(&mapper.http, "/api/v1/fleets/park/robots").expect("robots");
    let robot0 = &robots["robots"].as_array().expect("robots")[..]
        .iter()
        .find(|r| r["id"] == "robot0")
        .cloned()
        .expect("robot0");
    assert_eq!(robot0["chains"].as_array().unwrap().len(), 1, "{robot0}");
    for (r, edge) in steady.into_iter().enumerate() {
        let report = edge_report(edge, Duration::from_secs(120));
        assert_all_once(&mapper.http, &format!("robot{}", r + 1), &report);
    }
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
