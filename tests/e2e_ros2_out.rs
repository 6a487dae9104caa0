//! ROS 2 out, read by another implementation: a simulated robot maps with a mapper, both with
//! `[ros2_out]` on rmw_zenoh keys (and, in the second test, zenoh-bridge-ros2dds's);
//! `ros2_out_reader.py` (eclipse-zenoh and rosbags from PyPI) subscribes as an rmw_zenoh
//! subscription would, with keys made from rosbags' own type hashes (or on the bridge's plain
//! topic keys), and decodes with rosbags' CDR. The map→odom transform it read last must be the
//! edge's last correction and the HTTP API's `map_from_odometry`; the grid it got (published
//! and queried as a late joiner) must be, cell for cell, what Nav2's map_server reads from the
//! HTTP API's `map.pgm` and `map.yaml` (and publishes: trinary).

mod common;

use common::*;
use serde_json::Value;
use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

fn http_bytes(addr: &str, path: &str) -> Vec<u8> {
    let mut answer = agent()
        .get(format!("http://{addr}{path}"))
        .call()
        .unwrap_or_else(|e| panic!("{path}: {e}"));
    assert_eq!(answer.status(), 200, "{path}");
    let mut bytes = Vec::new();
    answer
        .body_mut()
        .as_reader()
        .read_to_end(&mut bytes)
        .expect("body");
    bytes
}

/// A P5 PGM's width, height and pixels (top row first).
fn parse_pgm(bytes: &[u8]) -> (usize, usize, Vec<u8>) {
    let mut fields = Vec::new();
    let mut at = 0;
    while fields.len() < 4 {
        while bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        if bytes[at] == b'#' {
            while bytes[at] != b'\n' {
                at += 1;
            }
            continue;
        }
        let start = at;
        while !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        fields.push(String::from_utf8_lossy(&bytes[start..at]).into_owned());
    }
    assert_eq!(fields[0], "P5");
    let (w, h): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    let pixels = bytes[at + 1..].to_vec();
    assert_eq!(pixels.len(), w * h);
    (w, h, pixels)
}

/// A map_server YAML key's value.
fn yaml_value<'a>(yaml: &'a str, key: &str) -> &'a str {
    yaml.lines()
        .find_map(|l| l.strip_prefix(&format!("{key}: ")))
        .unwrap_or_else(|| panic!("no {key} in {yaml}"))
}

/// map_server's trinary reading: occupied 100, free 0, unknown −1, from an occupancy `p`.
fn trinary(p: f64, occupied: f64, free: f64) -> i8 {
    if p > occupied {
        100
    } else if p < free {
        0
    } else {
        -1
    }
}

fn yaw_of(quaternion: &Value) -> f64 {
    let q: Vec<f64> = serde_json::from_value(quaternion.clone()).unwrap();
    2.0 * q[2].atan2(q[3])
}

fn angle_diff(a: f64, b: f64) -> f64 {
    (a - b + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
}

#[test]
fn ros2_tools_read_the_transform_and_the_map_the_http_api_serves() {
    read_back("rmw_zenoh", "");
}

/// zenoh-bridge-ros2dds's keys: plain CDR on `<namespace>/<topic>`, no attachment, no tokens.
#[test]
fn the_bridge_style_puts_the_same_on_plain_topic_keys() {
    read_back("ros2dds", "site7");
}

fn read_back(style: &str, namespace: &str) {
    let rmw_zenoh = style == "rmw_zenoh";
    let python = testdata::reference_python();
    let dir = temp_dir(&format!("ros2-out-{style}"));
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let ros_out = |node: &str| {
        format!(
            "[ros2_out]\nkey_style = {style:?}\nnamespace = {namespace:?}\nnode_name = {node:?}\n\
             map_period_ms = 300\n[ros2_out.zenoh]\nconnect = [{zenoh:?}]\n"
        )
    };
    let mapper = MapperProcess::start_with(&dir, zenoh.clone(), &ros_out("levelmap_mapper"));
    let mut reader = Command::new(&python)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/ros2_out_reader.py"))
        .args([
            zenoh.as_str(),
            dir.to_str().unwrap(),
            "park",
            style,
            namespace,
        ])
        .stderr(Stdio::inherit())
        .spawn()
        .map(KillOnDrop::from)
        .expect("the reader starts");
    assert!(
        wait_for(Duration::from_secs(60), || dir
            .join("ready")
            .exists()
            .then_some(()))
        .is_some(),
        "the reader did not subscribe"
    );

    let source = format!(
        "[source.sim]\nloop_index = 0\nduration_s = 40\n{}",
        ros_out("levelmap_edge")
    );
    let edge = spawn_edge_with(&dir, 0, &zenoh, 0.0, &source);
    let report = edge_report(edge, Duration::from_secs(180));
    assert_eq!(report["outbox_pending"], 0, "{report}");
    let published = report["tf_published"].as_u64().unwrap();
    assert!(published > 10, "{report}");
    let edge_correction = &report["map_from_odometry"];

    // The map of the last view has gone out (a period is 300 ms).
    let robots = get_json(&mapper.http, "/api/v1/fleets/park/robots").expect("robots");
    let summary = get_json(&mapper.http, "/api/v1/fleets/park/summary").expect("summary");
    std::thread::sleep(Duration::from_millis(1500));
    let summary_after = get_json(&mapper.http, "/api/v1/fleets/park/summary").expect("summary");
    assert_eq!(
        summary["updated_ns"], summary_after["updated_ns"],
        "the map still changes"
    );
    std::fs::write(dir.join("stop"), "").unwrap();
    assert!(reader.wait().expect("reader ends").success());
    let read: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ros2_out.json")).unwrap()).unwrap();

    // The transform: every one published came, in order (rmw_zenoh: with its attachment).
    let transforms = read["transforms"].as_array().unwrap();
    assert_eq!(transforms.len() as u64, published, "{}", read["tf_key"]);
    for (i, t) in transforms.iter().enumerate() {
        assert_eq!(
            (t["frame_id"].as_str(), t["child_frame_id"].as_str()),
            (Some("map"), Some("odom"))
        );
        if rmw_zenoh {
            assert_eq!(t["attachment_len"], 32);
            assert_eq!(t["sequence"], i as u64 + 1);
        } else {
            assert_eq!(t["attachment_len"], 0);
        }
    }
    let last = transforms.last().unwrap();
    let (x, y, yaw) = (
        last["x"].as_f64().unwrap(),
        last["y"].as_f64().unwrap(),
        yaw_of(&last["quaternion"]),
    );
    let close = |c: &Value, tolerance: f64| {
        (x - c["x"].as_f64().unwrap()).abs() < tolerance
            && (y - c["y"].as_f64().unwrap()).abs() < tolerance
            && angle_diff(yaw, c["theta"].as_f64().unwrap()).abs() < tolerance
    };
    assert!(
        close(edge_correction, 1e-9),
        "{last} vs the edge's {edge_correction}"
    );
    let robot = &robots["robots"][0];
    assert!(
        close(&robot["map_from_odometry"], 1e-6),
        "{last} vs the API's {}",
        robot["map_from_odometry"]
    );

    // The grid: published, and answered to a late joiner's query, the same.
    assert!(read["grids_received"].as_u64().unwrap() >= 1);
    let queried = read["queried"].as_array().unwrap();
    assert_eq!(queried.len(), 1);
    let grid = &queried[0];
    assert_eq!(grid, &read["last_grid_received"]);
    assert_eq!(grid["frame_id"], "map");
    let pgm = http_bytes(&mapper.http, "/api/v1/fleets/park/map.pgm");
    let yaml = String::from_utf8(http_bytes(&mapper.http, "/api/v1/fleets/park/map.yaml")).unwrap();
    let (w, h, pixels) = parse_pgm(&pgm);
    assert_eq!(
        (grid["width"].as_u64(), grid["height"].as_u64()),
        (Some(w as u64), Some(h as u64))
    );
    let resolution: f64 = yaml_value(&yaml, "resolution").parse().unwrap();
    assert!((grid["resolution"].as_f64().unwrap() - resolution).abs() < 1e-6);
    let origin: Vec<f64> = yaml_value(&yaml, "origin")
        .trim_matches(['[', ']'])
        .split(',')
        .map(|v| v.trim().parse().unwrap())
        .collect();
    let grid_origin: Vec<f64> = serde_json::from_value(grid["origin"].clone()).unwrap();
    assert!((origin[0] - grid_origin[0]).abs() < 1e-6 && (origin[1] - grid_origin[1]).abs() < 1e-6);
    let occupied: f64 = yaml_value(&yaml, "occupied_thresh").parse().unwrap();
    let free: f64 = yaml_value(&yaml, "free_thresh").parse().unwrap();
    let data: Vec<i64> = serde_json::from_value(grid["data"].clone()).unwrap();
    let mut counts = [0usize; 3];
    for row in 0..h {
        for col in 0..w {
            // The PGM's top row is the grid's last.
            let pixel = pixels[(h - 1 - row) * w + col];
            let from_pgm = trinary((255.0 - f64::from(pixel)) / 255.0, occupied, free);
            let from_ros = data[row * w + col];
            assert_eq!(
                from_ros,
                i64::from(from_pgm),
                "cell ({col}, {row}): pixel {pixel}"
            );
            counts[match from_ros {
                -1 => 0,
                0 => 1,
                _ => 2,
            }] += 1;
        }
    }
    assert!(
        counts[1] > 1000 && counts[2] > 100,
        "unknown, free, occupied: {counts:?}"
    );

    // rmw_zenoh's graph saw both nodes and their publishers, with the hashes rosbags made.
    let hash = |key: &str| {
        read[key]
            .as_str()
            .unwrap()
            .rsplit('/')
            .next()
            .unwrap()
            .to_owned()
    };
    let tokens: Vec<String> = serde_json::from_value(read["tokens"].clone()).unwrap();
    if !rmw_zenoh {
        assert!(tokens.is_empty(), "{tokens:?}");
        assert_eq!(read["tf_key"], format!("{namespace}/tf"));
        drop(mapper);
        std::fs::remove_dir_all(&dir).ok();
        return;
    }
    for wanted in [
        "/NN/%/%/levelmap_edge".to_owned(),
        "/NN/%/%/levelmap_mapper".to_owned(),
        format!(
            "/MP/%/%/levelmap_edge/%tf/tf2_msgs::msg::dds_::TFMessage_/{}/",
            hash("tf_key")
        ),
        format!(
            "/MP/%/%/levelmap_mapper/%levelmap%park%map/nav_msgs::msg::dds_::OccupancyGrid_/{}/",
            hash("map_key")
        ),
    ] {
        assert!(
            tokens.iter().any(|t| t.contains(&wanted)),
            "{wanted} not in {tokens:?}"
        );
    }
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
