//! The demo's claims, measured: three simulated robots map the hilly park over Zenoh; the
//! map's nodes are within 0.10 m RMSE of ground truth, robots that meet close loops with each
//! other, and the same run mapped from fixed horizontal 2D scanners is at least 3× worse (the
//! paper's claim). Run as fast as the machine goes (`--speed 0`). Without GPS and with the
//! robots started at places the mapper does not know, they still end in one map.

mod common;

use common::*;

/// `levelmap demo --duration 120 --speed 0 --json` with `extra` arguments: its report.
fn demo(name: &str, extra: &[&str]) -> serde_json::Value {
    let dir = temp_dir(name);
    let report = json_report(
        levelmap()
            .args([
                "demo",
                "--duration",
                "120",
                "--speed",
                "0",
                "--json",
                "--http",
                "127.0.0.1:0",
            ])
            .args(extra)
            .args(["--zenoh", &format!("tcp/127.0.0.1:{}", free_port())])
            .arg("--dir")
            .arg(dir.join("run")),
    );
    std::fs::remove_dir_all(&dir).ok();
    report
}

#[test]
fn the_fleet_demo_maps_the_park_and_beats_a_fixed_2d_scanner_threefold() {
    let report = demo("demo", &[]);
    let ate = report["ate_rmse_m"].as_f64().unwrap();
    let fixed = report["ate_rmse_fixed2d_m"].as_f64().unwrap();
    assert_eq!(report["robots"], 3);
    assert_eq!(report["outbox_pending"], 0, "every node reached the map");
    assert!(
        report["inter_robot_closures"].as_u64().unwrap() >= 1,
        "{report}"
    );
    // Measured: 0.072 m and 0.246 m (3.4×).
    assert!(ate <= 0.10, "ATE {ate:.3} m");
    assert!(
        fixed >= 3.0 * ate,
        "fixed 2D {fixed:.3} m vs leveled {ate:.3} m"
    );
    // The grid against the simulator's truth (docs/slam.md, "Scored against the truth"),
    // held to issue 28's goals. Measured: recall 0.974, false free 0.14 %, free coverage
    // 0.907; the fixed 2D scanners' map 0.966, 10.9 %, 0.830.
    let (map, map_fixed) = (&report["map"], &report["map_fixed2d"]);
    let score = |m: &serde_json::Value, key: &str| m[key].as_f64().expect(key);
    assert!(map["obstacles"].as_u64().unwrap() >= 100, "{map}");
    assert!(score(map, "obstacle_recall") >= 0.95, "{map}");
    assert!(score(map, "false_free") <= 0.005, "{map}");
    assert!(score(map, "free_coverage") >= 0.90, "{map}");
    assert!(score(map, "free_coverage") > score(map_fixed, "free_coverage"));
    assert!(score(map, "false_free") < score(map_fixed, "false_free"));
}

#[test]
fn robots_without_gps_or_a_known_start_meet_in_one_map() {
    let report = demo(
        "demo-scattered",
        &["--no-gps", "--scatter-starts", "--seed", "8"],
    );
    assert_eq!(report["robots"], 3);
    assert_eq!(report["gps_edges"], 0, "{report}");
    assert_eq!(report["outbox_pending"], 0, "every node reached the map");
    assert_eq!(report["components"], 1, "one connected network: {report}");
    assert!(
        report["inter_robot_closures"].as_u64().unwrap() >= 2,
        "{report}"
    );
    assert_eq!(report["ate_aligned"], true);
    let ate = report["ate_rmse_m"].as_f64().unwrap();
    assert!(ate <= 0.15, "ATE after an SE(2) fit {ate:.3} m");
}

/// `--dir` naming a folder that holds a user's file: refused at once, the file untouched.
#[test]
fn a_dir_holding_a_users_file_is_refused_and_left_as_it_is() {
    let dir = temp_dir("demo-users-dir");
    std::fs::write(dir.join("notes.txt"), b"mine").unwrap();
    let out = levelmap()
        .args(["demo", "--duration", "5", "--speed", "0", "--dir"])
        .arg(&dir)
        .output()
        .expect("levelmap runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the demo ran in a user's folder");
    assert!(
        stderr.contains("did not make") && stderr.contains(".levelmap-lab"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(dir.join("notes.txt")).unwrap(), b"mine");
    std::fs::remove_dir_all(&dir).ok();
}
