//! The CARMEN reader on small logs written here: each message, bearings, bad lines.

use super::*;

fn parse_str(text: &str) -> Result<CarmenLog, FileError> {
    parse(
        text.as_bytes(),
        Path::new("test.clf"),
        &ReadOptions::default(),
    )
}

const FLASER: &str = "FLASER 4 1.0 2.0 3.0 50.0 0.5 0.25 0.1 0.6 0.3 0.2 12.5 host 0.5";
const ODOM: &str = "ODOM 1.0 2.0 0.5 0.3 0.01 0.0 12.4 host 0.4";

#[test]
fn reads_flaser_odom_and_robotlaser1() {
    let robotlaser = "ROBOTLASER1 0 -1.570796 3.141593 0.017453 81.9 0.01 0 3 1.5 2.5 81.91 \
                      0 0.22 0.0 0.1 0.0 0.0 0.1 0.0 0.0 0.0 0.0 0.0 99.5 host 1.5";
    let text = format!(
        "# comment\nPARAM robot_front_laser_max 80.99 x 0\n{ODOM}\n{FLASER}\nNEFF 100\n{robotlaser}\n"
    );
    let log = parse_str(&text).expect("valid log");
    assert_eq!(log.odometry.len(), 1);
    assert_eq!(log.odometry[0].pose, Pose2::new(1.0, 2.0, 0.5));
    assert_eq!(log.odometry[0].stamp_s, 12.4);
    assert_eq!(log.scans.len(), 2);
    let s = &log.scans[0];
    assert_eq!(s.ranges_m, vec![1.0, 2.0, 3.0, 50.0]);
    assert_eq!(
        (s.stamp_s, s.logger_stamp_s, s.max_range_m),
        (12.5, 0.5, 80.99)
    );
    assert_eq!(s.laser_pose, Pose2::new(0.5, 0.25, 0.1));
    assert_eq!(s.odom_pose, Pose2::new(0.6, 0.3, 0.2));
    assert!((s.first_bearing_rad + FRAC_PI_2).abs() < 1e-12);
    assert!(
        (s.bearing_step_rad - PI / 3.0).abs() < 1e-12,
        "4 beams: π/(n − 1)"
    );
    let r = &log.scans[1];
    assert_eq!(r.ranges_m, vec![1.5, 2.5, 81.91]);
    assert_eq!((r.stamp_s, r.max_range_m), (99.5, 81.9));
    assert_eq!(r.laser_pose, Pose2::new(0.22, 0.0, 0.1));
    assert_eq!(r.odom_pose, Pose2::new(0.0, 0.0, 0.1));
    assert_eq!(log.skipped_messages.get("NEFF"), Some(&1));
    assert_eq!(log.skipped_messages.get("PARAM"), Some(&1));
}

#[test]
fn bearing_conventions() {
    assert!((FlaserBearings::Carmen.step_rad(180) - PI / 180.0).abs() < 1e-15);
    assert!((FlaserBearings::Carmen.step_rad(361) - PI / 360.0).abs() < 1e-15);
    assert!((FlaserBearings::PiOverNMinusOne.step_rad(180) - PI / 179.0).abs() < 1e-15);
    assert!((FlaserBearings::PiOverN.step_rad(361) - PI / 361.0).abs() < 1e-15);
}

fn line_error(text: &str) -> (usize, String) {
    match parse_str(text) {
        Err(FileError::Line { line, message, .. }) => (line, message),
        other => panic!("expected a line error, got {other:?}"),
    }
}

#[test]
fn truncated_line_names_the_line() {
    let text = format!("{ODOM}\n{ODOM}\nFLASER 4 1.0 2.0 3.0 4.0 0.5 0.25\n");
    let (line, message) = line_error(&text);
    assert_eq!(line, 3);
    assert!(message.contains("truncated"), "{message}");
    let shown = parse_str(&text).unwrap_err().to_string();
    assert!(
        shown.starts_with("test.clf:3: FLASER: truncated"),
        "{shown}"
    );
}

#[test]
fn nan_and_bad_numbers_name_the_line_and_field() {
    let (line, message) = line_error(&format!(
        "{ODOM}\nODOM 1.0 NaN 0.5 0.3 0.01 0.0 12.4 host 0.4\n"
    ));
    assert_eq!(line, 2);
    assert!(
        message.contains("not finite") && message.contains("x y theta"),
        "{message}"
    );
    let (line, message) = line_error(&format!("{}\n", FLASER.replace("2.0", "2.O")));
    assert_eq!(line, 1);
    assert!(
        message.contains("range") && message.contains("\"2.O\""),
        "{message}"
    );
    let (_, message) = line_error("FLASER four 1.0\n");
    assert!(message.contains("num_readings"), "{message}");
    let (_, message) = line_error(&format!("{FLASER} extra\n"));
    assert!(message.contains("16 fields, 15 expected"), "{message}");
    let (line, _) = line_error("PARAM robot_front_laser_max inf x 0\n");
    assert_eq!(line, 1);
}

#[test]
fn counts_beyond_the_line_are_errors() {
    // A count near usize::MAX overflowed the field positions computed from it.
    let max = usize::MAX;
    for (text, name) in [
        (format!("FLASER {max} 1.0 2.0\n"), "num_readings"),
        (
            format!("ROBOTLASER1 0 0 0 0 0 0 0 {max} 1.0\n"),
            "num_readings",
        ),
        (
            format!("ROBOTLASER1 0 0 0 0 0 0 0 1 1.0 {max} 0\n"),
            "num_remissions",
        ),
    ] {
        let (line, message) = line_error(&text);
        assert_eq!(line, 1);
        assert!(
            message.contains("truncated") && message.contains(name),
            "{message}"
        );
    }
}

#[test]
fn bad_lines_can_be_skipped_and_are_reported() {
    let text = format!("{ODOM}\nODOM 1.0\n{FLASER}\n");
    let options = ReadOptions {
        skip_bad_lines: true,
        ..ReadOptions::default()
    };
    let log = parse(text.as_bytes(), Path::new("t.log"), &options).expect("skipping");
    assert_eq!((log.odometry.len(), log.scans.len()), (1, 1));
    assert_eq!(log.bad_lines.len(), 1);
    assert_eq!(log.bad_lines[0].line, 2);
    assert!(
        log.bad_lines[0].message.starts_with("ODOM: truncated"),
        "{:?}",
        log.bad_lines
    );
}

#[test]
fn unknown_messages_are_tolerated_and_empty_input_is_an_error() {
    let log =
        parse_str("SYNC tag\nTRUEPOS 1 2 3 4 5 6 7 h 8\n\n").expect("nothing to read is fine");
    assert!(log.scans.is_empty() && log.odometry.is_empty());
    assert_eq!(log.skipped_messages.len(), 2);
    assert!(
        matches!(parse_str(""), Err(FileError::Invalid { message, .. }) if message == "empty log")
    );
}

#[test]
fn truncated_compressed_streams_are_errors() {
    use std::io::Write;
    let dir = std::env::temp_dir().join(format!("graphio-carmen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let text = format!("{ODOM}\n{FLASER}\n").repeat(200);
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(text.as_bytes()).expect("in memory");
    let gz = gz.finish().expect("in memory");
    let mut bz = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::default());
    bz.write_all(text.as_bytes()).expect("in memory");
    let bz = bz.finish().expect("in memory");
    for (name, bytes) in [("t.log.gz", gz), ("t.clf.bz2", bz)] {
        let path = dir.join(name);
        std::fs::write(&path, &bytes).expect("write");
        let log = read(&path).expect("whole file reads");
        assert_eq!((log.odometry.len(), log.scans.len()), (200, 200));
        std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("write");
        match read(&path) {
            Err(e @ FileError::Io { .. }) => assert!(e.to_string().contains(name), "{e}"),
            other => panic!("{name}: truncated stream read as {other:?}"),
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
