//! The fleet live in Foxglove: a mapper with `[foxglove]` on, a robot driving; once it is done,
//! a Foxglove client written from the published protocol (`tests/foxglove_check.py`: Python's
//! websockets and PyPI's foxglove-schemas-protobuf, outside the crate) subscribes to the
//! fleet's grid and the robot's pose, decodes them and checks them against the HTTP API: the
//! grid's size, cell and origin against `map.json`, each of its cells against `map.pgm`, the
//! pose against the robot's `pose`.

mod common;

use common::*;
use std::time::Duration;

#[test]
fn a_foxglove_client_sees_the_grid_and_pose_the_http_api_serves() {
    let dir = temp_dir("foxglove");
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let foxglove = format!("127.0.0.1:{}", free_port());
    let extra = format!("[foxglove]\nenabled = true\nlisten = {foxglove:?}\n");
    let mapper = MapperProcess::start_with(&dir, zenoh, &extra);
    // 40 s of park at 4x: 10 s of driving.
    let edge = spawn_edge(&dir, 0, &mapper.zenoh, 40.0, 4.0);
    let report = edge_report(edge, Duration::from_secs(120));
    assert_eq!(report["outbox_pending"], 0, "{report}");
    // The last solve applied: the map holds still.
    let summary = || get_json(&mapper.http, "/api/v1/fleets/park/summary");
    let mut last = summary();
    wait_for(Duration::from_secs(30), || {
        std::thread::sleep(Duration::from_secs(2));
        let now = summary();
        let still = now.is_some() && now == last;
        last = now;
        still.then_some(())
    })
    .expect("the map holds still after the robot stopped");
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/foxglove_check.py");
    let ws = format!("ws://{foxglove}");
    let base = format!("http://{}", mapper.http);
    let out = testdata::run_reference_python(&script, &[ws.as_str(), &base, "park", "robot0"]);
    eprintln!("foxglove: {out}");
    let checked: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON");
    let cells = &checked["grid"]["cells"];
    assert!(cells["occupied"].as_u64().unwrap() > 0, "{checked}");
    assert!(cells["free"].as_u64().unwrap() > 0, "{checked}");
    assert_eq!(checked["pose"]["frame_id"], "park/map", "{checked}");
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
