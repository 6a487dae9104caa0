//! Cross-implementation: every message levelmap reads, encoded by rosbags (PyPI, its own
//! CDR code) in both byte orders, decodes here to the message rosbags describes in JSON;
//! the messages levelmap writes, decoded by rosbags, are the ones written. The Python side
//! is `rosbags_messages.py`, run by `testdata::reference_python` (a venv made once beside the build).

use ros2msg::{
    CloudPoints, Imu, NavSatFix, OccupancyGrid, Odometry, TfMessage, decode, decode_cloud, encode,
};
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

fn rosbags(mode: &str, dir: &Path) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/rosbags_messages.py");
    testdata::run_reference_python(&script, &[std::ffi::OsStr::new(mode), dir.as_os_str()]);
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

fn json<T: DeserializeOwned>(path: &Path) -> T {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn both_orders(dir: &Path, name: &str) -> [Vec<u8>; 2] {
    ["le", "be"].map(|order| std::fs::read(dir.join(format!("{name}.{order}.cdr"))).expect("cdr"))
}

fn check<T: DeserializeOwned + PartialEq + std::fmt::Debug>(dir: &Path, name: &str) {
    let expected: T = json(&dir.join(format!("{name}.json")));
    for sample in both_orders(dir, name) {
        let decoded: T = decode(&sample).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(decoded, expected, "{name}");
    }
}

#[test]
fn messages_encoded_by_rosbags_decode_to_what_rosbags_says() {
    let dir = scratch("rosbags-write");
    rosbags("write", &dir);
    check::<NavSatFix>(&dir, "navsatfix");
    check::<Imu>(&dir, "imu");
    check::<Odometry>(&dir, "odometry");
    check::<TfMessage>(&dir, "tf_static");
    check::<OccupancyGrid>(&dir, "occupancy_grid");
    for name in ["cloud_ouster", "cloud_velodyne"] {
        let expected: serde_json::Value = json(&dir.join(format!("{name}.json")));
        let points = &expected["points"];
        for sample in both_orders(&dir, name) {
            let cloud = decode_cloud(&sample).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(cloud.width, expected["width"].as_u64().unwrap() as u32);
            assert_eq!(cloud.is_dense, expected["is_dense"].as_bool().unwrap());
            let got = CloudPoints::from_cloud(&cloud).unwrap_or_else(|e| panic!("{name}: {e}"));
            let xyz = points["xyz"].as_array().unwrap();
            assert_eq!(got.xyz.len(), xyz.len());
            for (p, e) in got.xyz.iter().zip(xyz) {
                for (v, w) in p.iter().zip(e.as_array().unwrap()) {
                    match w.as_f64() {
                        Some(w) => assert_eq!(*v, w as f32, "{name}"),
                        None => assert!(v.is_nan(), "{name}"),
                    }
                }
            }
            let ring: Vec<u16> = serde_json::from_value(points["ring"].clone()).unwrap();
            assert_eq!(got.ring.as_ref(), Some(&ring), "{name}");
            let offsets: Vec<i64> = serde_json::from_value(points["offset_ns"].clone()).unwrap();
            let got_offsets = got.offset_ns.expect("a time field");
            for (g, e) in got_offsets.iter().zip(&offsets) {
                // f32 seconds carry about 0.1 µs.
                assert!((g - e).abs() <= 1_000, "{name}: {g} vs {e} ns");
            }
        }
    }
}

#[test]
fn messages_encoded_here_decode_in_rosbags() {
    let dir = scratch("rosbags-read");
    let source = scratch("rosbags-read-source");
    rosbags("write", &source);
    let tf: TfMessage = json(&source.join("tf_static.json"));
    let grid: OccupancyGrid = json(&source.join("occupancy_grid.json"));
    std::fs::write(dir.join("tf_static.rust.cdr"), encode(&tf)).unwrap();
    std::fs::write(dir.join("occupancy_grid.rust.cdr"), encode(&grid)).unwrap();
    rosbags("read", &dir);
    assert_eq!(json::<TfMessage>(&dir.join("tf_static.rust.json")), tf);
    assert_eq!(
        json::<OccupancyGrid>(&dir.join("occupancy_grid.rust.json")),
        grid
    );
}

#[test]
fn type_hashes_are_the_ones_rosbags_computes() {
    let dir = scratch("rosbags-hashes");
    let names: Vec<&str> = ros2msg::types::ALL.iter().map(|t| t.name).collect();
    std::fs::write(dir.join("types.json"), serde_json::to_vec(&names).unwrap()).unwrap();
    rosbags("hashes", &dir);
    let hashes: std::collections::BTreeMap<String, String> = json(&dir.join("hashes.json"));
    for t in ros2msg::types::ALL {
        assert_eq!(
            hashes.get(t.name).map(String::as_str),
            Some(t.hash),
            "{}",
            t.name
        );
    }
}
