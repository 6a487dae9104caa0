//! `levelmap optimize` through the real binary: the JSON report on a benchmark graph, and
//! bad input (malformed lines, NaN, a missing vertex, a non-positive-definite information
//! matrix, a disconnected graph): a one-line error naming the file and line, never a panic.

use std::path::PathBuf;
use std::process::{Command, Output};

fn levelmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_levelmap"))
        .args(args)
        .output()
        .expect("run levelmap")
}

fn graph_file(test: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelmap-test-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("graph.g2o");
    std::fs::write(&path, text).expect("write");
    path
}

fn assert_error(text: &str, test: &str, needles: &[&str]) {
    let path = graph_file(test, text);
    let out = levelmap(&["optimize", path.to_str().unwrap(), "--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("graph.g2o"), "{stderr}");
    for needle in needles {
        assert!(stderr.contains(needle), "{needle:?} missing: {stderr}");
    }
}

const EDGE: &str = "1 0 0 1 0 0 1 0 1";

#[test]
fn reports_chi2_in_json_on_a_benchmark() {
    let path = testdata::shared_data("pose_graph_2d/se-sync/intel.g2o");
    let out = tempfile_out("report");
    let result = levelmap(&[
        "optimize",
        path.to_str().unwrap(),
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&result.stdout).expect("JSON");
    assert_eq!(r["nodes"], 1728);
    assert_eq!(r["edges"], 2512);
    assert!(
        (r["final_chi2"].as_f64().unwrap() - 45.004696).abs() < 1e-3,
        "{r}"
    );
    assert!(r["initial_chi2"].as_f64().unwrap() > r["final_chi2"].as_f64().unwrap());
    for key in ["iterations", "solve_ms", "init_ms"] {
        assert!(r[key].is_number(), "{key}: {r}");
    }
    let written = std::fs::read_to_string(&out).expect("--out written");
    assert_eq!(
        written
            .lines()
            .filter(|l| l.starts_with("VERTEX_SE2"))
            .count(),
        1728
    );
}

fn tempfile_out(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelmap-test-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join("out.g2o")
}

#[test]
fn malformed_line_is_named() {
    assert_error(
        &format!("EDGE_SE2 0 1 {EDGE}\nEDGE_SE2 1 2 1 0\n"),
        "short",
        &[":2:", "expected 11 fields"],
    );
    assert_error(
        &format!("EDGE_SE2 0 1 {EDGE}\nEDGE_SE2 1 two {EDGE}\n"),
        "id",
        &[":2:", "not an integer"],
    );
    assert_error(
        "VERTEX_SE2 0 0 0 0\nFOO 1 2\n",
        "tag",
        &[":2:", "unknown element"],
    );
}

#[test]
fn nan_is_refused() {
    assert_error(
        &format!("EDGE_SE2 0 1 {EDGE}\nEDGE_SE2 1 2 NaN 0 0 1 0 0 1 0 1\n"),
        "nan",
        &[":2:", "finite"],
    );
}

#[test]
fn missing_vertex_is_refused() {
    let text = format!(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 {EDGE}\nEDGE_SE2 1 7 {EDGE}\n"
    );
    assert_error(&text, "missing", &[":4:", "vertex 7"]);
}

#[test]
fn non_positive_definite_information_is_refused() {
    assert_error(
        "EDGE_SE2 0 1 1 0 0 1 2 0 1 0 1\n",
        "pd",
        &[":1:", "positive definite"],
    );
}

#[test]
fn disconnected_graph_is_refused() {
    let text = format!("EDGE_SE2 0 1 {EDGE}\nEDGE_SE2 5 6 {EDGE}\n");
    assert_error(&text, "disconnected", &["disconnected", "vertex 5"]);
}

#[test]
fn init_from_file_needs_vertices() {
    let path = graph_file("noverts", &format!("EDGE_SE2 0 1 {EDGE}\n"));
    let out = levelmap(&["optimize", path.to_str().unwrap(), "--init", "file"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr.contains("--init file needs a vertex line"),
        "{stderr}"
    );
}

/// `levelmap bench-incremental`: intel node by node through the window and the background
/// solve ends at the batch optimum, every node timed and the graph checked as it grew.
#[test]
fn an_incremental_replay_ends_at_the_batch_optimum() {
    let path = testdata::shared_data("pose_graph_2d/se-sync/intel.g2o");
    let result = levelmap(&[
        "bench-incremental",
        path.to_str().unwrap(),
        "--json",
        "--sizes",
        "1000",
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&result.stdout).expect("JSON");
    assert_eq!(
        (r["nodes"].as_u64(), r["edges"].as_u64()),
        (Some(1728), Some(2512))
    );
    assert_eq!(r["per_node"]["count"], 1727, "{r}");
    assert_eq!(r["at_sizes"][0]["nodes"], 1000, "{r}");
    // Every 500 nodes and the last.
    assert_eq!(r["checks"], 4, "{r}");
    assert!(r["background_solves"].as_u64().unwrap() >= 1, "{r}");
    let relative = r["relative_chi2"].as_f64().unwrap();
    assert!(relative.abs() <= 1e-4, "{r}");
    assert!(
        (r["batch_chi2"].as_f64().unwrap() - 45.004696).abs() < 1e-3,
        "{r}"
    );
}

/// `levelmap bench-incremental --solver bayes-tree`: intel node by node through the Bayes
/// tree; the newest node is the batch answer at every check (within 1 cm) and the end is the
/// batch optimum.
#[test]
fn a_bayes_tree_replay_is_the_batch_answer_at_every_check() {
    let path = testdata::shared_data("pose_graph_2d/se-sync/intel.g2o");
    let result = levelmap(&[
        "bench-incremental",
        path.to_str().unwrap(),
        "--solver",
        "bayes-tree",
        "--check-every",
        "100",
        "--json",
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&result.stdout).expect("JSON");
    assert_eq!(r["solver"], "bayes-tree", "{r}");
    assert_eq!(r["per_node"]["count"], 1727, "{r}");
    assert_eq!(r["checks"], 18, "{r}");
    assert_eq!(r["newest_within_1cm"], 1.0, "{r}");
    assert_eq!(r["background_solves"], 0, "{r}");
    assert!(r["relative_chi2"].as_f64().unwrap().abs() <= 1e-4, "{r}");
    assert!(r["tree"]["depth_max"].as_u64().unwrap() >= 1, "{r}");
}
