//! Every CARMEN log of the shared data reads without error, with the message counts the data
//! manifest (MANIFEST.md §2) states.

use graphio::carmen::{self, CarmenLog, LaserScan};
use std::f64::consts::{FRAC_PI_2, PI};
use testdata::shared_data;

fn read(relative: &str) -> CarmenLog {
    let path = shared_data(relative);
    carmen::read(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Every scan has `beams` ranges and finite poses. (Timestamps need not ascend: Intel's
/// ipc_timestamps go back 631 times by up to 0.6 s.)
fn check_scans(name: &str, scans: &[LaserScan], beams: &[usize]) {
    for (i, s) in scans.iter().enumerate() {
        assert!(
            beams.contains(&s.ranges_m.len()),
            "{name} scan {i}: {} beams",
            s.ranges_m.len()
        );
        assert!(
            s.laser_pose.is_finite() && s.odom_pose.is_finite(),
            "{name} scan {i}"
        );
        assert!(
            s.ranges_m.iter().all(|r| r.is_finite() && *r >= 0.0),
            "{name} scan {i}"
        );
    }
}

/// Reads a log and checks its scan and odometry counts and every scan's shape.
fn read_counted(relative: &str, scans: usize, odometry: usize, beams: &[usize]) -> CarmenLog {
    let log = read(relative);
    eprintln!(
        "{relative}: {} scans, {} odometry, skipped {:?}",
        log.scans.len(),
        log.odometry.len(),
        log.skipped_messages
    );
    assert_eq!(
        (log.scans.len(), log.odometry.len()),
        (scans, odometry),
        "{relative}"
    );
    check_scans(relative, &log.scans, beams);
    log
}

#[test]
fn raw_logs_have_the_manifest_counts() {
    // (file, FLASER or ROBOTLASER1 scans, ODOM lines, beams per scan)
    let expected: [(&str, usize, usize, &[usize]); 5] = [
        ("aces.clf.bz2", 7374, 7375, &[180]),
        ("intel.clf.bz2", 13631, 26915, &[180]),
        ("fr079.clf.bz2", 4934, 8951, &[360]),
        ("mit-csail.clf.bz2", 1988, 0, &[361]),
        ("fr-clinic_robotlaser.clf.bz2", 6917, 0, &[180, 181]),
    ];
    for (file, scans, odometry, beams) in expected {
        let log = read_counted(
            &format!("radish_2d_laser_logs/{file}"),
            scans,
            odometry,
            beams,
        );
        assert!(log.bad_lines.is_empty());
    }
}

#[test]
fn flaser_max_range_comes_from_the_log_or_the_default() {
    // ACES has no robot_front_laser_max and clips at 50.00; fr079 sets 80.99 and marks no
    // return with 81.91.
    let aces = read("radish_2d_laser_logs/aces.clf.bz2");
    assert!(aces.scans.iter().all(|s| s.max_range_m == 50.0));
    let fr079 = read("radish_2d_laser_logs/fr079.clf.bz2");
    assert!(fr079.scans.iter().all(|s| s.max_range_m == 80.99));
}

#[test]
fn robotlaser1_fields_match_the_fr_clinic_log() {
    let log = read("radish_2d_laser_logs/fr-clinic_robotlaser.clf.bz2");
    let first = &log.scans[0];
    // From the first line: start −1.570796, resolution 0.017453 (1°), max range 81.9,
    // 181 beams, laser pose 0.22 m ahead of the robot, stamps 1232658478.161285 / −0.055208.
    assert_eq!(first.ranges_m.len(), 181);
    assert!((first.first_bearing_rad + FRAC_PI_2).abs() < 1e-6);
    assert!((first.bearing_step_rad - PI / 180.0).abs() < 1e-6);
    assert_eq!(first.max_range_m, 81.9);
    assert_eq!((first.laser_pose.x, first.odom_pose.x), (0.22, 0.0));
    assert_eq!(
        (first.stamp_s, first.logger_stamp_s),
        (1232658478.161285, -0.055208)
    );
    // Four interleaved start angles (0.25° apart) cover the scan at 0.25° over time.
    let mut starts: Vec<i64> = log
        .scans
        .iter()
        .map(|s| (s.first_bearing_rad * 1e6).round() as i64)
        .collect();
    starts.sort_unstable();
    starts.dedup();
    assert_eq!(starts, vec![-1570796, -1566433, -1562070, -1557706]);
    // The laser is 0.22 m ahead of the robot, along its heading, in every scan.
    for s in &log.scans {
        let offset = s.odom_pose.between(&s.laser_pose);
        assert!(
            (offset.x - 0.22).abs() < 1e-3 && offset.y.abs() < 1e-3 && offset.theta.abs() < 1e-4,
            "{offset:?}"
        );
    }
}

#[test]
fn corrected_logs_have_the_manifest_counts() {
    // (file, FLASER scans, ODOM lines, beams per scan)
    let expected: [(&str, usize, usize, &[usize]); 5] = [
        ("aces-corrected.log.gz", 440, 7814, &[180]),
        ("csail-corrected.log.gz", 406, 2394, &[361]),
        ("intel-corrected.log.gz", 910, 14541, &[180]),
        ("freiburg-079-corrected.log.gz", 4791, 9725, &[360]),
        ("freiburg-campus-corrected.log.gz", 2008, 17691, &[360]),
    ];
    for (file, scans, odometry, beams) in expected {
        let log = read_counted(
            &format!("radish_2d_corrected_logs/{file}"),
            scans,
            odometry,
            beams,
        );
        assert_eq!(
            log.skipped_messages.get("NEFF"),
            Some(&scans),
            "{file}: one NEFF per scan"
        );
        // In these logs the FLASER pose fields both hold the corrected pose (MANIFEST 2b).
        assert!(
            log.scans.iter().all(|s| s.laser_pose == s.odom_pose),
            "{file}"
        );
    }
}
