//! Bounded growth (docs/services.md, "Bounded growth"): one robot drives ten laps of the same
//! loop; where the map has nodes already it passes over them. The network's nodes and the
//! store after ten laps are within 1.2× of what they were after the first, and the passes'
//! GPS fixes make the map as good as keeping every node would (ATE within 1.2× of that run's).
//! A store with passes replays to the same network, their fixes included; clouds beyond a
//! fleet's bound are dropped oldest first.

mod common;

use common::*;
use serde_json::Value;

/// `levelmap demo` of one robot driving `laps` laps as fast as it goes, in `dir`: its report.
fn laps(laps: u32, dir: &std::path::Path) -> Value {
    laps_with(laps, dir, &[])
}

fn laps_with(laps: u32, dir: &std::path::Path, extra: &[&str]) -> Value {
    json_report(
        levelmap()
            .args(["demo", "--robots", "1", "--laps", &laps.to_string()])
            .args(extra)
            .args([
                "--no-baseline",
                "--speed",
                "0",
                "--json",
                "--http",
                "127.0.0.1:0",
            ])
            .args(["--zenoh", &format!("tcp/127.0.0.1:{}", free_port())])
            .arg("--dir")
            .arg(dir),
    )
}

#[test]
fn ten_laps_of_one_loop_keep_the_map_the_size_of_one() {
    let dir = temp_dir("laps");
    let r = laps(10, &dir.join("run"));
    let every = laps_with(10, &dir.join("every"), &["--keep-every-node"]);
    std::fs::remove_dir_all(&dir).ok();
    let first = &r["first_lap"];
    let (nodes, nodes_1) = (
        r["nodes"].as_f64().unwrap(),
        first["nodes"].as_f64().unwrap(),
    );
    let (store, store_1) = (
        r["store_bytes"].as_f64().unwrap(),
        first["store_bytes"].as_f64().unwrap(),
    );
    let (ate, ate_1) = (
        r["ate_rmse_m"].as_f64().unwrap(),
        first["ate_rmse_m"].as_f64().unwrap(),
    );
    // Measured (release): 30 → 30 nodes, 3.2 MB → 3.2 MB, ATE 0.109 → 0.039–0.044 m with the
    // passes' fixes (0.109 m without them); keeping every node: 291 nodes, 0.051 m.
    let ate_every = every["ate_rmse_m"].as_f64().unwrap();
    assert!(
        ate <= 1.2 * ate_every,
        "ATE {ate:.3} m after ten laps passing, {ate_every:.3} m keeping every node"
    );
    assert!(r["pass_fixes"].as_u64().unwrap() > 0, "{r}");
    assert!(
        nodes <= 1.2 * nodes_1,
        "nodes {nodes_1} after a lap, {nodes} after ten"
    );
    assert!(
        store <= 1.2 * store_1,
        "store {store_1} B after a lap, {store} B after ten"
    );
    assert!(
        ate <= ate_1,
        "ATE {ate_1:.3} m after a lap, {ate:.3} m after ten"
    );
    assert!(r["nodes_passed"].as_u64().unwrap() > 200, "{r}");
    assert_eq!(r["outbox_pending"], 0, "every node acked");
}

/// Cloud retention (`[clouds]`): with room for about two clouds, the oldest nodes' clouds are
/// dropped in the background while nodes are taken; the newest stays.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_oldest_clouds_are_dropped_beyond_the_fleets_bound() {
    let dir = temp_dir("clouds");
    let nodes = real_nodes(6);
    let cloud_bytes = wire::Message::encoded_len(nodes[0].cloud.as_ref().expect("a cloud")) as u64;
    let config = mapper::MapperConfig {
        clouds: mapper::config::CloudsConfig {
            max_bytes: 2 * cloud_bytes + cloud_bytes / 2,
            prune_every_s: std::num::NonZeroU64::new(1).unwrap(),
            ..Default::default()
        },
        ..Default::default()
    };
    let (mapper, session, http) = in_process_mapper_with(&dir, config).await;
    put_until_mapped(&session, &http, None, &nodes).await;
    let h = http.clone();
    let (kept, metrics) = tokio::task::spawn_blocking(move || {
        let cloud =
            |n: usize| http_get(&h, &format!("/api/v1/fleets/park/nodes/{n}/cloud")).map(|a| a.0);
        let kept = wait_for(std::time::Duration::from_secs(20), || {
            let kept: Vec<usize> = (0..6).filter(|&n| cloud(n) == Some(200)).collect();
            (kept.len() <= 2).then_some(kept)
        });
        (kept, http_get(&h, "/metrics").unwrap().1)
    })
    .await
    .unwrap();
    assert_eq!(kept, Some(vec![4, 5]), "the two newest clouds kept");
    assert_eq!(metric(&metrics, "levelmap_clouds_pruned_total"), 4);
    session.close().await.unwrap();
    mapper.stop().await.unwrap();
    std::fs::remove_dir_all(&dir).ok();
}

/// Passes are stored as spans, their path included: a mapper started again on the store of
/// two laps replays it to the same network (a difference would quarantine the fleet).
#[test]
fn a_store_with_passes_replays_to_the_same_map() {
    let dir = temp_dir("laps-replay");
    let run = dir.join("run");
    let report = laps(2, &run);
    assert!(report["nodes_passed"].as_u64().unwrap() > 10, "{report}");
    // The demo's mapping: slam::Mapper2dParams::precise_dead_reckoning() and the park's datum.
    let config = format!(
        "store_path = {:?}\ndatum = {{ latitude_deg = 52.39, longitude_deg = 9.71, height_m = 55.0 }}\n\
         [mapping]\nodometry_sigma_xy_m = 0.01\nodometry_sigma_xy_per_m = 0.01\n\
         odometry_sigma_theta_rad = 0.002\nodometry_sigma_theta_per_rad = 0.01\n\
         match_odometry_max_chi2 = 16.0\nfuse_odometry = true\n\
         [mapping.loop_consistency]\nenabled = false\n[mapping.idc]\nmin_correspondences = 10\n",
        run.join("mapper.redb")
    );
    let mapper = MapperProcess::start_with(&dir, format!("tcp/127.0.0.1:{}", free_port()), &config);
    let fleets = get_json(&mapper.http, "/api/v1/fleets").unwrap();
    assert_eq!(fleets["quarantined"], serde_json::json!([]), "{fleets}");
    let summary = get_json(&mapper.http, "/api/v1/fleets/park/summary").unwrap();
    assert_eq!(summary["nodes"], report["nodes"], "{summary}");
    assert_eq!(summary["edges"], report["edges"], "{summary}");
    // The passes' fixes, stored with the solves that took them, are given back there.
    assert_eq!(summary["gps_edges"], report["gps_edges"], "{summary}");
    assert!(
        summary["stats"]["pass_fixes"].as_u64().unwrap() > 0,
        "{summary}"
    );
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
