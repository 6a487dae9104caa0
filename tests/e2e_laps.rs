//! Bounded growth (docs/services.md, "Bounded growth"): one robot drives ten laps of the same
//! loop; where the map has nodes already it passes over them. The network's nodes and the
//! store after ten laps are within 1.2× of what they were after the first, and the map's ATE
//! is no worse. The same drive keeping every node grows tenfold.

mod common;

use common::*;
use serde_json::Value;

fn laps(name: &str, extra: &[&str]) -> Value {
    let dir = temp_dir(name);
    let out = levelmap()
        .args([
            "demo",
            "--robots",
            "1",
            "--laps",
            "10",
            "--no-baseline",
            "--speed",
            "0",
        ])
        .args(["--json", "--http", "127.0.0.1:0"])
        .args(["--zenoh", &format!("tcp/127.0.0.1:{}", free_port())])
        .args(extra)
        .arg("--dir")
        .arg(dir.join("run"))
        .output()
        .expect("levelmap demo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    eprintln!("{report:#}");
    std::fs::remove_dir_all(&dir).ok();
    report
}

#[test]
fn ten_laps_of_one_loop_keep_the_map_the_size_of_one() {
    let r = laps("laps", &[]);
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
    // Measured: 29 → 30 nodes, 3.2 MB → 3.2 MB, ATE 0.118 → 0.109 m; 261 nodes passed.
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
