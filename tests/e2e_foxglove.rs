//! The fleet live in Foxglove: a mapper with `[foxglove]` on and a read token, a robot
//! driving. A Foxglove client written from the published protocol (`tests/foxglove_check.py`:
//! Python's websockets and PyPI's foxglove-schemas-protobuf, outside the crate), started
//! before the robot, is refused without the token (401), then with it takes the robot's first
//! leveled scans, clouds and GPS fixes and checks each against its node in the HTTP API. Once
//! the robot is done, it checks the fleet's grid and the robot's pose: the grid's size, cell
//! and origin against `map.json`, each of its cells against `map.pgm`, the pose against the
//! robot's `pose`.

mod common;

use common::*;
use std::time::Duration;

const READ_TOKEN: &str = "fox-read-token";

#[test]
fn a_foxglove_client_with_the_token_sees_what_the_http_api_serves() {
    let dir = temp_dir("foxglove");
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    let foxglove = format!("127.0.0.1:{}", free_port());
    let extra =
        format!("read_token = {READ_TOKEN:?}\n[foxglove]\nenabled = true\nlisten = {foxglove:?}\n");
    let mapper = MapperProcess::start_with(&dir, zenoh, &extra);
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/foxglove_check.py");
    let ws = format!("ws://{foxglove}/?token={READ_TOKEN}");
    let base = format!("http://{}", mapper.http);
    let python = testdata::reference_python();
    let args = [ws.as_str(), &base, "park", "robot0", READ_TOKEN];
    let live = std::process::Command::new(&python)
        .arg(&script)
        .arg("live")
        .args(args)
        .arg("3")
        .stdout(std::process::Stdio::piped())
        .spawn()
        .map(KillOnDrop::from)
        .expect("the Foxglove client starts");
    // The client is connected before the first node: give it the time to open.
    std::thread::sleep(Duration::from_secs(3));
    // 40 s of park at 4x: 10 s of driving.
    let edge = spawn_edge(&dir, 0, &mapper.zenoh, 40.0, 4.0);
    let report = edge_report(edge, Duration::from_secs(120));
    assert_eq!(report["outbox_pending"], 0, "{report}");
    let live = live
        .into_inner()
        .wait_with_output()
        .expect("the client ends");
    let out = String::from_utf8_lossy(&live.stdout);
    eprintln!("foxglove live: {out}");
    assert!(live.status.success(), "the live check failed: {out}");
    let checked: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(checked["refused_without_token"], 401, "{checked}");
    for what in ["scans", "clouds", "fixes"] {
        assert_eq!(checked[what].as_array().map(Vec::len), Some(3), "{checked}");
    }
    assert!(
        checked["scans"][0]["returns"].as_u64().unwrap() > 0,
        "{checked}"
    );

    // The last solve applied: the map holds still.
    let summary = || {
        get_json_with(
            &mapper.http,
            "/api/v1/fleets/park/summary",
            Some(READ_TOKEN),
        )
    };
    let mut last = summary();
    wait_for(Duration::from_secs(30), || {
        std::thread::sleep(Duration::from_secs(2));
        let now = summary();
        let still = now.is_some() && now == last;
        last = now;
        still.then_some(())
    })
    .expect("the map holds still after the robot stopped");
    let mut map_args = vec!["map"];
    map_args.extend(args);
    let out = testdata::run_reference_python(&script, &map_args);
    eprintln!("foxglove map: {out}");
    let checked: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON");
    let cells = &checked["grid"]["cells"];
    assert!(cells["occupied"].as_u64().unwrap() > 0, "{checked}");
    assert!(cells["free"].as_u64().unwrap() > 0, "{checked}");
    assert_eq!(checked["pose"]["frame_id"], "park/map", "{checked}");
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
