//! The ROS 2 tests' shared recording (`rosbags_recording.py`, written by rosbags) and the
//! streams it holds.

use edge::source::ros::{RosCounts, RosStreams};
use edge::{McapSource, McapSourceConfig, Source, SourceEvent};
use std::path::{Path, PathBuf};

/// The recording, written afresh under `name`: its rosbag2 folder.
pub fn recording(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/rosbags_recording.py");
    testdata::run_reference_python(&script, &[&dir]);
    dir.join("rec")
}

/// The recording's topics.
pub fn streams() -> RosStreams {
    RosStreams {
        cloud_topic: "/points".into(),
        odometry_topic: "/odom".into(),
        imu_topic: "/imu".into(),
        gps_topic: "/fix".into(),
        columns: 64,
        ..RosStreams::default()
    }
}

/// The recording at `path` through `[source.mcap]`: every event, and the counts.
pub fn play(path: &Path) -> (Vec<SourceEvent>, RosCounts) {
    let mut source = McapSource::new(&McapSourceConfig {
        path: path.to_owned(),
        streams: streams(),
        ..McapSourceConfig::default()
    })
    .expect("the recording opens");
    let events: Vec<SourceEvent> = std::iter::from_fn(|| source.next_event()).collect();
    (events, source.counts().expect("read to the end"))
}
