//! `levelmap level` on bad input: a one-line error naming the file, a non-zero exit, no panic;
//! or, for scans without a single usable point, zero beams and a warning.

use std::path::PathBuf;
use std::process::{Command, Output};

fn levelmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_levelmap"))
        .args(args)
        .output()
        .expect("run levelmap")
}

/// A file in a fresh temporary folder of this test.
fn temp_file(test: &str, name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelmap-test-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write temp file");
    path
}

fn kitti_bytes(points: &[[f32; 4]]) -> Vec<u8> {
    points
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// Fails unless the run failed cleanly with one error line mentioning every `needles`.
fn assert_clean_failure(out: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "expected failure, got success; stderr: {stderr}"
    );
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "panic: {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "expected one error line, got: {stderr}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    for needle in needles {
        assert!(
            lines[0].contains(needle),
            "{needle:?} missing from: {stderr}"
        );
    }
    assert!(out.stdout.is_empty(), "no report on failure");
}

#[test]
fn truncated_bin_names_file_and_problem() {
    let mut bytes = kitti_bytes(&[[5.0, 0.0, -1.7, 0.1]; 10]);
    bytes.truncate(bytes.len() - 3);
    let path = temp_file("truncated", "cut.bin", &bytes);
    let out = levelmap(&["level", path.to_str().unwrap(), "--json"]);
    assert_clean_failure(&out, &["cut.bin", "truncated", "157 bytes"]);
}

#[test]
fn empty_file_is_refused() {
    let path = temp_file("empty", "empty.bin", b"");
    assert_clean_failure(
        &levelmap(&["level", path.to_str().unwrap()]),
        &["empty.bin", "empty file"],
    );
}

#[test]
fn missing_file_is_refused() {
    let out = levelmap(&["level", "/nonexistent/scan.bin", "--json"]);
    assert_clean_failure(&out, &["/nonexistent/scan.bin", "No such file"]);
}

#[test]
fn unknown_format_is_refused() {
    let path = temp_file("format", "scan.bin", &kitti_bytes(&[[5.0, 0.0, -1.7, 0.1]]));
    let out = levelmap(&["level", path.to_str().unwrap(), "--format", "pcd"]);
    assert_clean_failure(&out, &["scan.bin", "unknown format \"pcd\""]);
}

#[test]
fn wrong_format_for_the_file_is_refused() {
    // Binary KITTI bytes read as 3DTK text.
    let path = temp_file(
        "wrong-format",
        "scan.bin",
        &kitti_bytes(&[[5.0, 0.0, -1.7, 0.1]; 4]),
    );
    let out = levelmap(&["level", path.to_str().unwrap(), "--format", "3dtk"]);
    assert_clean_failure(&out, &["scan.bin"]);
    // A .3d file with a malformed line names the line.
    let path = temp_file("bad-line", "scan.3d", b"1 2 3\n4 five 6\n");
    assert_clean_failure(
        &levelmap(&["level", path.to_str().unwrap()]),
        &["scan.3d", "line 2"],
    );
}

#[test]
fn labels_of_another_scan_are_refused() {
    let scan = temp_file(
        "labels",
        "scan.bin",
        &kitti_bytes(&[[5.0, 0.0, -1.7, 0.1]; 3]),
    );
    let labels = temp_file("labels", "scan.label", &[0u8; 8]);
    let out = levelmap(&[
        "level",
        scan.to_str().unwrap(),
        "--labels",
        labels.to_str().unwrap(),
    ]);
    assert_clean_failure(&out, &["scan.label", "2 labels for a scan of 3 points"]);
}

fn assert_zero_beams_with_warning(points: &[[f32; 4]], test: &str) {
    let path = temp_file(test, "scan.bin", &kitti_bytes(points));
    let out = levelmap(&["level", path.to_str().unwrap(), "--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("warning:") && stderr.contains("no beams"),
        "{stderr}"
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON report");
    assert_eq!(report["beams"], 0);
    assert_eq!(report["points"], points.len());
    assert_eq!(report["invalid"], points.len());
    assert_eq!(report["landmark"], 0);
}

#[test]
fn nan_scan_gives_zero_beams_and_a_warning() {
    let nan = f32::NAN;
    assert_zero_beams_with_warning(
        &[
            [nan, nan, nan, 0.0],
            [nan, 1.0, 2.0, 0.0],
            [3.0, nan, 0.0, 0.0],
            [f32::INFINITY, 0.0, 1.0, 0.0],
        ],
        "nan",
    );
}

#[test]
fn out_of_range_scan_gives_zero_beams_and_a_warning() {
    // A wall 1,000 km away, and points on the sensor axis.
    let mut points: Vec<[f32; 4]> = (0..40).map(|i| [1.0e6, 0.0, i as f32 * 0.1, 0.0]).collect();
    points.extend((0..5).map(|i| [0.0, 0.0, i as f32, 0.0]));
    assert_zero_beams_with_warning(&points, "out-of-range");
}

#[test]
fn bad_thresholds_in_the_config_are_refused() {
    let scan = temp_file("config", "scan.bin", &kitti_bytes(&[[5.0, 0.0, -1.7, 0.1]]));
    let config = temp_file(
        "config",
        "bad.toml",
        b"[segment]\nmax_misalignment_deg = 120.0\n",
    );
    let out = levelmap(&[
        "level",
        scan.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    assert_clean_failure(&out, &["max_misalignment_deg", "(0, 90)"]);
    let config = temp_file(
        "config",
        "typo.toml",
        b"[segment]\nmin_landmark_heigth_m = 0.3\n",
    );
    let out = levelmap(&[
        "level",
        scan.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("typo.toml") && stderr.contains("min_landmark_heigth_m"),
        "{stderr}"
    );
}

/// An Ouster capture: every frame leveled with `--meta`; without it, or cut before a frame
/// is complete, or with metadata lacking a field, a one-line error naming the file.
#[test]
fn ouster_captures_need_their_metadata_and_whole_frames() {
    let data = testdata::shared_data("ouster_organized_scans");
    let pcap = data.join("OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
    let meta = data.join("OS-1-128_v2.3.0_1024x10.json");
    let (pcap_arg, meta_arg) = (pcap.to_str().unwrap(), meta.to_str().unwrap());
    let out = levelmap(&[
        "level", pcap_arg, "--meta", meta_arg, "--json", "--repeat", "1",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let frames = report["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 3, "{report}");
    for f in frames {
        assert!(f["beams"].as_u64().unwrap() > 500, "{f}");
        assert_eq!(f["points"], 131_072);
    }

    let out = levelmap(&["level", pcap_arg, "--json"]);
    assert_clean_failure(&out, &["lb_n3.pcap", "--meta"]);

    let bytes = std::fs::read(&pcap).expect("capture");
    let cut = temp_file("ouster", "cut.pcap", &bytes[..bytes.len() / 4]);
    let out = levelmap(&["level", cut.to_str().unwrap(), "--meta", meta_arg]);
    assert_clean_failure(&out, &["cut.pcap", "no complete frame"]);

    let text = std::fs::read_to_string(&meta).expect("metadata");
    let lacking = text.replace("\"beam_azimuth_angles\"", "\"renamed\"");
    let bad_meta = temp_file("ouster", "meta.json", lacking.as_bytes());
    let out = levelmap(&["level", pcap_arg, "--meta", bad_meta.to_str().unwrap()]);
    assert_clean_failure(&out, &["meta.json", "lacks beam_azimuth_angles"]);
}
