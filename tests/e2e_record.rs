//! `levelmap record` during a real run: a mapper and two simulated robots (processes, Zenoh
//! TCP on loopback), the recorder beside them. The file is read back by the reference MCAP
//! reader in Python, every node decoded with the schema embedded in the file; its counts must
//! match the recorder's report and the mapper's map. Recorded with `--foxglove`, the file holds
//! each node's scan, cloud and fixes in Foxglove's schemas too, and the frames on `/tf`. A fresh mapper fed the file then holds
//! the same network (every edge and its measurement) and the same poses: the feed solves
//! where the live mapper solved (its recorded `map/poses` puts), so the replay is exact. A copy cut in the middle fails `levelmap mapper
//! --from-recording`, naming the file.

mod common;

use common::*;
use serde_json::Value;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::process::Stdio;
use std::time::Duration;

const TOKEN: &str = "record-token";

/// Pose of every node of the fleet's graph by (robot, node_seq): (x, y, theta).
fn graph_poses(http: &str) -> BTreeMap<(String, u64), [f64; 3]> {
    let graph = get_json(http, "/api/v1/fleets/park/graph").expect("the graph");
    let nodes = graph["nodes"].as_array().expect("nodes");
    nodes
        .iter()
        .map(|n| {
            let p = &n["pose"];
            let key = (
                n["robot"].as_str().unwrap().to_owned(),
                n["node_seq"].as_u64().unwrap(),
            );
            (key, ["x", "y", "theta"].map(|k| p[k].as_f64().unwrap()))
        })
        .collect()
}

/// Every edge of the fleet's graph, its ends named by robot and node_seq, sorted.
fn graph_edges(http: &str) -> Vec<String> {
    let graph = get_json(http, "/api/v1/fleets/park/graph").expect("the graph");
    let nodes = graph["nodes"].as_array().expect("nodes");
    let name = |i: &Value| {
        let n = &nodes[i.as_u64().unwrap() as usize];
        format!("{}/{}", n["robot"], n["node_seq"])
    };
    let edges = graph["edges"].as_array().expect("edges");
    let mut named: Vec<String> = edges
        .iter()
        .map(|e| {
            let (from, to) = (name(&e["from"]), name(&e["to"]));
            format!("{from} {to} {} {}", e["kind"], e["measurement"])
        })
        .collect();
    named.sort();
    named
}

fn per_robot(poses: &BTreeMap<(String, u64), [f64; 3]>) -> BTreeMap<String, u64> {
    let mut counts = BTreeMap::new();
    for (robot, _) in poses.keys() {
        *counts.entry(robot.clone()).or_default() += 1;
    }
    counts
}

/// `levelmap record` on the fleet, once it has subscribed.
fn start_recorder(connect: &str, out: &std::path::Path) -> KillOnDrop {
    let mut child = levelmap()
        .args([
            "record",
            "--fleet",
            "park",
            "--json",
            "--foxglove",
            "--connect",
            connect,
            "--out",
        ])
        .arg(out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map(KillOnDrop::from)
        .expect("levelmap record starts");
    let stderr = child.stderr.take().expect("stderr");
    let mut lines = BufReader::new(stderr).lines();
    let first = lines.next().expect("a line").expect("text");
    assert!(first.starts_with("recording levelmap/park/**"), "{first}");
    // The rest (progress) is drained so the recorder never blocks on a full pipe.
    std::thread::spawn(move || lines.for_each(drop));
    // Let the router learn the subscription before the robots publish.
    std::thread::sleep(Duration::from_millis(500));
    child
}

#[test]
fn a_recorded_run_reads_back_in_python_and_replays_to_the_same_map() {
    let dir = temp_dir("record");
    let live = MapperProcess::start_with(
        &dir,
        format!("tcp/127.0.0.1:{}", free_port()),
        &format!("token = {TOKEN:?}"),
    );
    let out = dir.join("run.mcap");
    let recorder = start_recorder(&live.zenoh, &out);
    let edges: Vec<KillOnDrop> = (0..2)
        .map(|robot| spawn_edge(&dir, robot, &live.zenoh, 40.0, 0.0))
        .collect();
    let sent: u64 = edges
        .into_iter()
        .map(|e| {
            edge_report(e, Duration::from_secs(180))["nodes"]
                .as_u64()
                .unwrap()
        })
        .sum();
    let mapped = wait_for(Duration::from_secs(30), || {
        let poses = graph_poses(&live.http);
        (poses.len() as u64 == sent).then_some(poses)
    });
    assert!(
        mapped.is_some(),
        "the live map never held the {sent} nodes sent"
    );
    // An operator's solve: recorded (a `map/poses` put) like the timed ones, and replayed.
    let auth = format!("Bearer {TOKEN}");
    let solved = http_call(
        &live.http,
        "POST",
        "/api/v1/fleets/park/optimize",
        &[("Authorization", &auth)],
    );
    assert_eq!(solved.map(|a| a.status), Some(200));
    // A background solve taken before the operator's may still land after it: the map is
    // settled when a second passes without a change. Then the last solve's poses reach the
    // recorder (a loaded machine delays them: CI once stopped the recorder first).
    let live_poses = wait_for(Duration::from_secs(30), || {
        let before = graph_poses(&live.http);
        std::thread::sleep(Duration::from_secs(1));
        (graph_poses(&live.http) == before).then_some(before)
    })
    .expect("the live map settles");
    assert!(per_robot(&live_poses).len() == 2, "both robots mapped");
    std::thread::sleep(Duration::from_millis(1500));
    sigterm(&recorder);
    let output = recorder
        .into_inner()
        .wait_with_output()
        .expect("the recorder ends");
    assert!(output.status.success(), "the recorder failed");
    let report: Value = serde_json::from_slice(&output.stdout).expect("the JSON report");
    eprintln!("recorder: {report:#}");
    assert_eq!(report["dropped"], 0);
    assert_eq!(report["skipped"], 0);

    // The reference reader, with the schemas in the file.
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/record_check.py");
    let read: Value =
        serde_json::from_str(&testdata::run_reference_python(&script, &[&out])).expect("JSON");
    eprintln!("python mcap: {read:#}");
    assert_eq!(read["topics"], report["topics"], "per-topic counts");
    let (levelmap_messages, foxglove_messages) = (
        report["messages"].as_u64().unwrap(),
        report["foxglove_messages"].as_u64().unwrap(),
    );
    let messages = levelmap_messages + foxglove_messages;
    assert_eq!(read["messages"], messages);
    assert_eq!(read["summary_messages"], messages);
    assert_eq!(report["foxglove_unreadable"], 0);
    for robot in ["robot0", "robot1"] {
        let key = |t: &str| format!("levelmap/park/robots/{robot}/{t}");
        assert_eq!(read["schemas"][key("node")], "levelmap.v1.Node");
        assert_eq!(read["schemas"][key("odom")], "levelmap.v1.Odometry");
        assert_eq!(read["schemas"][key("ack")], "levelmap.v1.Ack");
        assert_eq!(read["schemas"][key("scan")], "levelmap.v1.LiveScan");
        // Every node sent (re-sends too) in Foxglove's schemas, placed by its odometry.
        let topic = |t: &str| format!("/park/robots/{robot}/{t}");
        assert_eq!(read["schemas"][topic("scan")], "foxglove.LaserScan");
        assert_eq!(read["schemas"][topic("cloud")], "foxglove.PointCloud");
        assert_eq!(read["schemas"][topic("gps")], "foxglove.LocationFix");
        assert_eq!(read["topics"][topic("scan")], read["topics"][key("node")]);
        assert_eq!(read["topics"][topic("cloud")], read["topics"][key("node")]);
        assert!(read["topics"][topic("gps")].as_u64() > Some(0), "{read}");
        let frames = read["foxglove"]["frames"].as_array().unwrap();
        for link in [
            format!("park/map>park/{robot}/odom"),
            format!("park/{robot}/odom>park/{robot}"),
        ] {
            assert!(
                frames.contains(&Value::from(link.clone())),
                "{link}: {read}"
            );
        }
    }
    assert_eq!(read["schemas"]["/tf"], "foxglove.FrameTransforms");
    assert!(read["foxglove"]["returns"].as_u64() > Some(0), "{read}");
    assert_eq!(
        read["schemas"]["levelmap/park/map/poses"],
        "levelmap.v1.MapPoses"
    );
    let live_counts = per_robot(&live_poses);
    let read_counts: BTreeMap<String, u64> =
        serde_json::from_value(read["nodes_per_robot"].clone()).unwrap();
    assert_eq!(
        read_counts, live_counts,
        "distinct nodes in the file and in the map"
    );

    // A fresh mapper fed the file, through the same call as `levelmap mapper --from-recording`.
    let replay_dir = temp_dir("record-replay");
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let (replayed, replayed_edges) = runtime.block_on(async {
        let (mapper, _session, http) =
            in_process_mapper_with(&replay_dir, mapper::MapperConfig::default()).await;
        let fed = mapper.feed_recording(&out).await.expect("fed");
        eprintln!("fed: {fed:?}");
        assert_eq!(
            fed.messages, messages,
            "the feed reads the Foxglove topics past"
        );
        let read = tokio::task::spawn_blocking(move || (graph_poses(&http), graph_edges(&http)));
        let read = read.await.unwrap();
        mapper.stop().await.unwrap();
        read
    });
    assert_eq!(replayed_edges, graph_edges(&live.http), "the same network");
    assert_eq!(
        per_robot(&replayed),
        live_counts,
        "nodes per robot after the replay"
    );
    let (mut worst_m, mut worst_rad) = (0.0f64, 0.0f64);
    for (node, [x, y, theta]) in &live_poses {
        let [rx, ry, rtheta] = replayed[node];
        worst_m = worst_m.max((x - rx).hypot(y - ry));
        worst_rad = worst_rad.max((theta - rtheta).abs());
    }
    eprintln!("replay against live: {worst_m:.3e} m, {worst_rad:.3e} rad at most");
    assert!(
        worst_m <= 1e-6 && worst_rad <= 1e-6,
        "{worst_m} m, {worst_rad} rad"
    );

    // Cut in the middle: the mapper stops, naming the file.
    let bytes = std::fs::read(&out).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let config = dir.join("cut-mapper.toml");
    std::fs::write(
        &config,
        format!(
            "http_listen = \"127.0.0.1:{}\"\nstore_path = {:?}\n[zenoh]\nlisten = [\"tcp/127.0.0.1:{}\"]\n",
            free_port(),
            dir.join("cut.redb"),
            free_port()
        ),
    )
    .unwrap();
    let failed = levelmap()
        .args(["mapper", "--exit-when-done", "--config"])
        .arg(&config)
        .arg("--from-recording")
        .arg(&cut)
        .output()
        .expect("levelmap mapper runs");
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert!(!failed.status.success());
    let named = format!("error: {}: cut short or damaged after ", cut.display());
    assert!(stderr.contains(&named), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_dir_all(&replay_dir).ok();
}
