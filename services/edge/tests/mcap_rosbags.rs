//! `[source.mcap]` on a recording written by rosbags (PyPI, its own MCAP and CDR code; the
//! script is `rosbags_recording.py`, run by `testdata::reference_python`): odometry with the
//! IMU's roll, scans with their columns' times and the lidar's mount from /tf_static, fixes
//! with their odometry, and the bad samples counted. The same recording cut mid-file still
//! yields what came before the cut.

mod common;

use common::{play, recording};
use edge::SourceEvent;

const T0: u64 = 1_700_000_000_000_000_000;

#[test]
fn a_rosbags_recording_plays_as_odometry_scans_and_fixes() {
    let rec = recording("mcap-whole");
    let (events, counts) = play(&rec);
    eprintln!("{counts:?}");
    let odometry: Vec<_> = events
        .iter()
        .filter_map(|e| match e {
            SourceEvent::Odometry(p) => Some(p),
            _ => None,
        })
        .collect();
    let scans: Vec<_> = events
        .iter()
        .filter_map(|e| match e {
            SourceEvent::Scan(s) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(odometry.len(), 61);
    // Roll from the IMU (0.05 rad), heading and position from odometry.
    let last = odometry.last().unwrap();
    let (roll, pitch, yaw) = last.pose.rotation.euler_angles();
    assert!((roll - 0.05).abs() < 1e-9 && pitch.abs() < 1e-9 && yaw.abs() < 1e-9);
    assert!((last.pose.translation.x - 3.0).abs() < 1e-9);
    // Six clouds, the one at 1 s cut short.
    assert_eq!(scans.len(), 5, "{counts:?}");
    let refused: u64 = counts
        .refused
        .iter()
        .filter(|(k, _)| k.starts_with("/points"))
        .map(|(_, n)| n)
        .sum();
    assert_eq!(refused, 1, "{counts:?}");
    for scan in &scans {
        assert!((scan.sensor_in_robot.translation.vector.x - 0.2).abs() < 1e-12);
        let stamps: Vec<u64> = scan.raw.columns.iter().map(|c| c.stamp_ns).collect();
        assert!(
            stamps.windows(2).all(|w| w[0] <= w[1]),
            "columns in time order"
        );
        let span = stamps.last().unwrap() - stamps[0];
        assert!(
            span > 80_000_000 && span <= 100_000_000,
            "the sweep's 0.1 s: {span}"
        );
        let start = scan.raw.start_stamp_ns();
        assert!(
            scan.track.at(start).is_some() && scan.track.at(stamps[stamps.len() - 1]).is_some()
        );
    }
    // Fixes at 0, 1 and 3 s (2 s has no fix), each with the next scan that starts after it.
    let fixes: Vec<_> = scans.iter().flat_map(|s| &s.gps).collect();
    let stamps: Vec<u64> = fixes
        .iter()
        .map(|f| (f.stamp_ns - T0) / 1_000_000_000)
        .collect();
    assert_eq!(
        stamps,
        vec![0, 1],
        "the fix at 3 s comes after the last scan"
    );
    for fix in &fixes {
        assert!((fix.antenna_in_robot_m.x + 0.3).abs() < 1e-12);
        assert!((fix.sigma_horizontal_m - 0.2).abs() < 1e-9);
        let x = fix.odometry_at_fix.translation.x;
        assert!(
            (x - (fix.stamp_ns - T0) as f64 * 1e-9).abs() < 1e-6,
            "odometry at the fix"
        );
    }
    assert_eq!(counts.refused.get("/fix: no fix"), Some(&1), "{counts:?}");
}

#[test]
fn a_recording_cut_mid_file_yields_what_came_before() {
    let rec = recording("mcap-cut");
    let file = rec.join("rec.mcap");
    let bytes = std::fs::read(&file).unwrap();
    let cut = rec.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let (events, _) = play(&cut);
    let odometry = events
        .iter()
        .filter(|e| matches!(e, SourceEvent::Odometry(_)))
        .count();
    assert!(odometry > 10 && odometry < 61, "{odometry} odometry events");
}
