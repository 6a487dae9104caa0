//! `[source.ros2]` live: a rosbags-written recording (`rosbags_recording.py`) is put on
//! rmw_zenoh keys, or zenoh-bridge-ros2dds's, by the Python Zenoh (`zenoh_publisher.py`,
//! eclipse-zenoh from PyPI, in the venv `testdata::reference_python` makes); the live source
//! must give the events the same recording gives through `[source.mcap]`.

mod common;

use common::{play, recording, streams};
use edge::{Ros2Source, Ros2SourceConfig, Source, SourceEvent};
use runtime::ros2::KeyStyle;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Odometry stamps, and each scan's column stamps and fix stamps.
type Summary = (Vec<u64>, Vec<(Vec<u64>, Vec<u64>)>);

fn summary(events: &[SourceEvent]) -> Summary {
    let mut odometry = Vec::new();
    let mut scans = Vec::new();
    for e in events {
        match e {
            SourceEvent::Odometry(p) => odometry.push(p.stamp_ns),
            SourceEvent::Scan(s) => scans.push((
                s.raw.columns.iter().map(|c| c.stamp_ns).collect(),
                s.gps.iter().map(|g| g.stamp_ns).collect(),
            )),
        }
    }
    (odometry, scans)
}

#[test]
fn live_rmw_zenoh_topics_give_what_the_recording_gives() {
    live_topics_give_what_the_recording_gives(KeyStyle::RmwZenoh, "rmw_zenoh");
}

#[test]
fn live_ros2dds_bridge_topics_give_what_the_recording_gives() {
    live_topics_give_what_the_recording_gives(KeyStyle::Ros2dds, "ros2dds");
}

fn live_topics_give_what_the_recording_gives(style: KeyStyle, name: &str) {
    let python = testdata::reference_python();
    let rec = recording(&format!("ros2-live-{name}"));
    let expected = summary(&play(&rec).0);
    let tests = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");

    let endpoint = format!(
        "tcp/127.0.0.1:{}",
        sitelog::local::free_local_port().expect("a free port")
    );
    let mut publisher = Command::new(&python)
        .arg(tests.join("zenoh_publisher.py"))
        .arg(&endpoint)
        .arg(&rec)
        .arg(name)
        .stderr(Stdio::inherit())
        .spawn()
        .map(testdata::KillOnDrop::from)
        .expect("the publisher starts");
    // The publisher listens first; the source connects as a client.
    let started = Instant::now();
    let mut config = Ros2SourceConfig {
        key_style: style,
        streams: streams(),
        ..Ros2SourceConfig::default()
    };
    config.zenoh.connect = Some(vec![endpoint]);
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
    let (odometry, scans) = &expected;
    let wanted = odometry.len() + scans.len();
    // Live topics never end: read on a thread, and give up after a minute.
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let events: Vec<SourceEvent> = (0..wanted).map_while(|_| source.next_event()).collect();
        let _ = tx.send((events, source.dropped()));
    });
    let (events, dropped) = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("every event within a minute");
    assert!(publisher.wait().expect("the publisher ends").success());
    assert_eq!(dropped, 0);
    assert_eq!(summary(&events), expected);
}
