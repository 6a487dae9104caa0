//! The map on the Earth, checked by another implementation: the simulated fleet maps the
//! park (`levelmap demo --serve`), then rasterio (GDAL and PROJ, from PyPI) reads the
//! mapper's GeoTIFF and its XYZ tiles at two zoom levels (`tests/geo_check.py`): size, CRS,
//! transform, the trunks and posts the robots passed at their WGS84 places within one cell,
//! and the tiles lined up with the GeoTIFF within one cell.

mod common;

use common::*;
use std::io::{BufRead, BufReader};
use std::process::Stdio;

/// Seconds the robots drive.
const DURATION_S: u64 = 60;
/// Landmarks are the trunks and posts whose surface a robot passed this close to (m).
const LANDMARK_REACH_M: f64 = 6.0;

/// The trunks and posts the robots pass, as `{"east_m", "north_m", "radius_m"}` in the
/// park's frame (the datum's east-north frame).
fn landmarks() -> serde_json::Value {
    let world = sim::World::park();
    let paths: Vec<[f64; 2]> = (0..3)
        .flat_map(|i| {
            let robot = sim::FleetRobot::new(&world, i, DURATION_S * 1_000_000_000, 7).unwrap();
            fleetlab::map_score::path_of(&robot)
        })
        .collect();
    let upright = |p: &&sim::Part| {
        matches!(p.kind, sim::SurfaceKind::TreeTrunk | sim::SurfaceKind::Pole)
            && matches!(p.shape, sim::Shape::Cylinder(_))
    };
    let landmarks: Vec<serde_json::Value> = world
        .parts()
        .iter()
        .filter(upright)
        .filter_map(|p| {
            let (c, r) = p.shape.bounding_circle();
            let near = paths
                .iter()
                .any(|q| (q[0] - c[0]).hypot(q[1] - c[1]) - r <= LANDMARK_REACH_M);
            near.then(|| serde_json::json!({"east_m": c[0], "north_m": c[1], "radius_m": r}))
        })
        .collect();
    serde_json::Value::Array(landmarks)
}

#[test]
fn rasterio_reads_the_geotiff_and_the_tiles_put_landmarks_at_their_wgs84_places() {
    let dir = temp_dir("geo");
    let http = format!("127.0.0.1:{}", free_port());
    let mut demo = levelmap()
        .args([
            "demo",
            "--duration",
            &DURATION_S.to_string(),
            "--speed",
            "0",
        ])
        .args(["--json", "--serve", "--http", &http])
        .args(["--zenoh", &format!("tcp/127.0.0.1:{}", free_port())])
        .arg("--dir")
        .arg(dir.join("run"))
        .stdout(Stdio::piped())
        .spawn()
        .map(KillOnDrop::from)
        .expect("levelmap demo starts");
    // The report is printed once the robots are done; the map is served from then on.
    let mut report = String::new();
    for line in BufReader::new(demo.stdout.take().unwrap()).lines() {
        let line = line.expect("the demo's output");
        report.push_str(&line);
        if line == "}" {
            break;
        }
    }
    let report: serde_json::Value = serde_json::from_str(&report).expect("the demo's report");
    assert!(report["nodes"].as_u64().unwrap() > 20, "{report}");
    let datum = serde_json::to_string(&sim::PARK_DATUM.origin).unwrap();
    let out = dir.join("geo");
    std::fs::create_dir_all(&out).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/geo_check.py");
    // Kept beside the fetched files, for a look after a failure.
    let landmarks = landmarks().to_string();
    std::fs::write(out.join("landmarks.json"), &landmarks).unwrap();
    let figures = testdata::run_reference_python(
        &script,
        &[
            http.as_str(),
            "park",
            &datum,
            &landmarks,
            out.to_str().unwrap(),
        ],
    );
    eprintln!("{figures}");
    sigterm(&demo);
    assert!(demo.wait().unwrap().success(), "the demo stops cleanly");
    std::fs::remove_dir_all(&dir).ok();
}
