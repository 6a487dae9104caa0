//! Cross-implementation, end to end on the robot's side: the simulator's park run for one
//! robot is written to a ROS 2 recording by rosbags (PyPI; `sim_recording.py`: unorganized
//! PointCloud2 with per-point time, Odometry, Imu, NavSatFix, /tf_static, in rosbags' own
//! MCAP and CDR code), played through `[source.mcap]` and mapped with the mapper's own code;
//! its ATE must be within 0.02 m of the same run taken straight from `[source.sim]`. The
//! same recording put live on rmw_zenoh keys by the Python Zenoh (eclipse-zenoh, the edge's
//! `tests/zenoh_publisher.py`) must reach the same map through `[source.ros2]`.

use edge::source::ros::RosStreams;
use edge::{
    EdgeConfig, McapSource, McapSourceConfig, NodeBuilder, Ros2Source, Ros2SourceConfig, SimSource,
    SimSourceConfig, Source, SourceEvent,
};
use fleetlab::{FLEET, sim_mapping_params};
use mapper::{FleetMap, MapperConfig};
use sim::FleetRobot;
use slam::Pose2;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const EPOCH_NS: u64 = 1_700_000_000_000_000_000;
const DURATION_S: f64 = 60.0;

fn sim_config() -> SimSourceConfig {
    SimSourceConfig {
        duration_s: DURATION_S,
        ..SimSourceConfig::default()
    }
}

/// The sim source's events for robot 0.
fn sim_events() -> Vec<SourceEvent> {
    let mut source = SimSource::new(&sim_config(), EPOCH_NS, 10.0).expect("loop 0");
    std::iter::from_fn(|| source.next_event()).collect()
}

/// The events as the files `sim_recording.py` reads; returns the columns of a scan.
fn export(events: &[SourceEvent], dir: &Path) -> usize {
    let (mut odom, mut points, mut clouds, mut fixes) = (vec![], vec![], vec![], vec![]);
    let mut tf = serde_json::Value::Null;
    let mut columns = 0;
    for event in events {
        match event {
            SourceEvent::Odometry(p) => {
                let (t, q) = (p.pose.translation.vector, p.pose.rotation.coords);
                odom.extend(p.stamp_ns.to_le_bytes());
                for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
                    odom.extend(v.to_le_bytes());
                }
            }
            SourceEvent::Scan(scan) => {
                columns = scan.raw.columns.len();
                let start = scan.raw.start_stamp_ns();
                let first = points.len() / 16;
                for c in &scan.raw.columns {
                    let t = (c.stamp_ns - start) as u32;
                    let range = c.start as usize..(c.start + c.len) as usize;
                    for p in &scan.raw.points[range] {
                        let [x, y, z] = if p.is_valid() {
                            p.to_xyz()
                        } else {
                            [f32::NAN; 3]
                        };
                        for v in [x, y, z] {
                            points.extend(v.to_le_bytes());
                        }
                        points.extend(t.to_le_bytes());
                    }
                }
                let count = points.len() / 16 - first;
                clouds.push(serde_json::json!({"stamp": start, "first": first, "count": count}));
                for f in &scan.gps {
                    fixes.push(serde_json::json!({
                        "stamp": f.stamp_ns, "lat": f.latitude_deg, "lon": f.longitude_deg,
                        "alt": f.altitude_m, "sigma_h": f.sigma_horizontal_m,
                        "sigma_v": f.sigma_vertical_m,
                    }));
                    let a = f.antenna_in_robot_m;
                    tf["gps"] = serde_json::json!([a.x, a.y, a.z]);
                }
                let m = &scan.sensor_in_robot;
                let (t, q) = (m.translation.vector, m.rotation.coords);
                tf["lidar"] = serde_json::json!([t.x, t.y, t.z, q.x, q.y, q.z, q.w]);
            }
        }
    }
    let write = |name: &str, bytes: &[u8]| std::fs::write(dir.join(name), bytes).expect(name);
    write("odom.bin", &odom);
    write("clouds.bin", &points);
    write(
        "clouds.json",
        serde_json::to_string(&clouds).unwrap().as_bytes(),
    );
    write(
        "fixes.json",
        serde_json::to_string(&fixes).unwrap().as_bytes(),
    );
    write("tf.json", tf.to_string().as_bytes());
    columns
}

/// The recording's topics (`sim_recording.py`), clouds organized in `columns`.
fn streams(columns: usize) -> RosStreams {
    RosStreams {
        cloud_topic: "/points".into(),
        odometry_topic: "/odom".into(),
        imu_topic: "/imu".into(),
        gps_topic: "/fix".into(),
        columns,
        ..RosStreams::default()
    }
}

/// The events mapped as the mapper maps them: the ATE against the truth, and the nodes.
fn map(events: impl IntoIterator<Item = SourceEvent>) -> (f64, usize) {
    let defaults = MapperConfig::default();
    let datum = slam::geodesy::GeoDatum {
        origin: sim::PARK_DATUM.origin,
    };
    let mut map = FleetMap::new(
        FLEET,
        sim_mapping_params(),
        Some(datum),
        defaults.max_range_m,
    );
    let base = EdgeConfig::default();
    let mut builder = NodeBuilder::new(FLEET, "robot0", base.node.clone(), base.leveling, 0);
    let duration_ns = (DURATION_S * 1e9) as u64;
    let robot = FleetRobot::new(edge::park(), 0, duration_ns, 7).expect("loop 0");
    let mount = robot.scanner().mount;
    let mut truth = Vec::new();
    for event in events {
        let SourceEvent::Scan(scan) = event else {
            continue;
        };
        let Some(node) = builder.offer(&scan).expect("a node") else {
            continue;
        };
        map.ingest(&node).expect("ingested");
        map.optimize_pending().expect("optimized");
        let start = scan.raw.columns[0].stamp_ns - EPOCH_NS;
        truth.push(Pose2::from_isometry3(&(robot.truth_at(start) * mount)));
    }
    map.optimize_now().expect("optimized");
    let ate = slam::position_rmse(
        map.poses()
            .iter()
            .copied()
            .zip(&truth)
            .map(|(a, b)| (a, *b)),
    );
    (ate, truth.len())
}

#[test]
fn the_park_run_recorded_by_rosbags_maps_as_the_simulated_source_does() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("mcap-sim");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let events = sim_events();
    let columns = export(&events, &dir);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/sim_recording.py");
    testdata::run_reference_python(&script, &[&dir]);

    let (sim_ate, sim_nodes) = map(events);
    let mut source = McapSource::new(&McapSourceConfig {
        path: dir.join("rec"),
        streams: streams(columns),
        ..McapSourceConfig::default()
    })
    .expect("the recording opens");
    let played: Vec<SourceEvent> = std::iter::from_fn(|| source.next_event()).collect();
    let counts = source.counts().expect("read to the end");
    let live = live_events(&dir.join("rec"), columns, played.len());
    let stamps = |events: &[SourceEvent]| -> Vec<u64> {
        events
            .iter()
            .map(|e| match e {
                SourceEvent::Odometry(p) => p.stamp_ns,
                SourceEvent::Scan(s) => s.raw.start_stamp_ns(),
            })
            .collect()
    };
    assert_eq!(
        stamps(&live),
        stamps(&played),
        "live and recorded events differ"
    );
    let (live_ate, live_nodes) = map(live);
    let (mcap_ate, mcap_nodes) = map(played);
    assert_eq!((live_nodes, live_ate), (mcap_nodes, mcap_ate));
    eprintln!(
        "sim: {sim_nodes} nodes, ATE {sim_ate:.4} m; mcap and live rmw_zenoh: {mcap_nodes} nodes, ATE {mcap_ate:.4} m; {counts:?}"
    );
    assert!(counts.refused.is_empty(), "{counts:?}");
    assert!(
        mcap_nodes + 1 >= sim_nodes,
        "{mcap_nodes} vs {sim_nodes} nodes"
    );
    assert!(
        (mcap_ate - sim_ate).abs() <= 0.02,
        "ATE {mcap_ate:.4} m from the recording, {sim_ate:.4} m from the simulator"
    );
}

/// The recording at `rec` put live on rmw_zenoh keys by the Python Zenoh, through
/// `[source.ros2]`: the first `wanted` events (live topics never end).
fn live_events(rec: &Path, columns: usize, wanted: usize) -> Vec<SourceEvent> {
    let endpoint = format!(
        "tcp/127.0.0.1:{}",
        sitelog::local::free_local_port().expect("a free port")
    );
    let publisher_script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../edge/tests/zenoh_publisher.py");
    let mut publisher = Command::new(testdata::reference_python())
        .arg(publisher_script)
        .arg(&endpoint)
        .arg(rec)
        .arg("rmw_zenoh")
        .stderr(Stdio::inherit())
        .spawn()
        .map(testdata::KillOnDrop::from)
        .expect("the publisher starts");
    let mut config = Ros2SourceConfig {
        streams: streams(columns),
        ..Ros2SourceConfig::default()
    };
    config.zenoh.connect = Some(vec![endpoint]);
    let started = Instant::now();
    // The publisher listens first; the source connects as a client.
    let mut source = loop {
        match Ros2Source::new(&config) {
            Ok(s) => break s,
            Err(e) if started.elapsed() < Duration::from_secs(20) => {
                eprintln!("{e}; again");
                std::thread::sleep(Duration::from_millis(300));
            }
            Err(e) => panic!("{e}"),
        }
    };
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let events: Vec<SourceEvent> = (0..wanted).map_while(|_| source.next_event()).collect();
        let _ = tx.send((events, source.dropped()));
    });
    let (events, dropped) = rx
        .recv_timeout(Duration::from_secs(120))
        .expect("every event within two minutes");
    assert!(publisher.wait().expect("the publisher ends").success());
    assert_eq!(dropped, 0);
    events
}
