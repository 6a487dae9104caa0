//! The README's first command and the simulate → level round trip, through the real binary.

use std::path::PathBuf;
use std::process::Command;

fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelmap-test-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn run_json(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_levelmap"))
        .args(args)
        .output()
        .expect("run levelmap");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "levelmap {args:?} failed: {stderr}");
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

/// Paper Fig. 4 in the simulator: the leveled scan sees the pavilion and not the hill, the
/// fixed 2D scanner sees the hill and not the pavilion; the picture is written.
#[test]
fn pavilion_shows_the_pavilion_that_a_fixed_2d_scanner_misses() {
    let dir = temp_dir("pavilion");
    let report = run_json(&["pavilion", "--out-dir", dir.to_str().unwrap(), "--json"]);
    assert!(
        report["beams_on_pavilion"].as_u64().unwrap() >= 5,
        "{report}"
    );
    assert_eq!(report["beams_on_ground"], 0, "{report}");
    assert_eq!(report["fixed2d_on_pavilion"], 0, "{report}");
    assert!(
        report["fixed2d_on_ground"].as_u64().unwrap() >= 50,
        "{report}"
    );
    assert!(
        report["landmark_precision"].as_f64().unwrap() >= 0.99,
        "{report}"
    );
    let svg = std::fs::read_to_string(dir.join("pavilion.svg")).expect("SVG written");
    assert!(
        svg.starts_with("<svg")
            && svg.trim_end().ends_with("</svg>")
            && svg.contains("leveled range scan")
    );
}

/// A simulated scan written to disk and read back levels to the same result as in memory,
/// and scores against the simulator's truth.
#[test]
fn simulated_scan_round_trips_through_a_file() {
    let dir = temp_dir("simulate");
    let file = dir.join("wall.json");
    let written = run_json(&[
        "simulate",
        "--scene",
        "wall",
        "--seed",
        "3",
        "--out",
        file.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(written["points"], 27_000);
    let report = run_json(&["level", file.to_str().unwrap(), "--json", "--repeat", "1"]);
    assert_eq!(report["format"], "sim");
    assert_eq!(report["points"], 27_000);
    assert!(report["beams"].as_u64().unwrap() > 20, "{report}");
    assert!(
        report["landmark_precision"].as_f64().unwrap() >= 0.99,
        "{report}"
    );
    for key in ["invalid", "ground", "landmark", "overhang"] {
        assert!(report[key].is_u64(), "{key} missing: {report}");
    }
    let total: u64 = ["invalid", "ground", "landmark", "overhang"]
        .iter()
        .map(|k| report[k].as_u64().unwrap())
        .sum();
    assert_eq!(total, 27_000);
}
