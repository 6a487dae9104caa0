//! A 3DTK scan (`levelmap level FILE.3d`, the edge's files source): the `.3d` text, and after
//! a NUL byte (if any) its `.pose` text. `scanio::threedtk::parse` and `parse_pose`, the
//! functions `load(path)` calls on the files, then the leveling the robot runs on the scan.
#![no_main]

use leveling::{Leveler, PoseTrack, SegmentParams};
use libfuzzer_sys::fuzz_target;
use scanio::threedtk::{POINTS_PER_LINE, parse, parse_pose};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let (scan_bytes, pose_bytes) = match data.iter().position(|&b| b == 0) {
        Some(nul) => (&data[..nul], Some(&data[nul + 1..])),
        None => (data, None),
    };
    // `load_pose` reads the file with `read_to_string`: only UTF-8 text gets to the parser.
    let pose = pose_bytes
        .and_then(|b| std::str::from_utf8(b).ok())
        .and_then(|text| parse_pose(text, Path::new("fuzz.pose")).ok());
    let Ok(mut scan) = parse(scan_bytes, Path::new("fuzz.3d")) else {
        return;
    };
    assert_eq!(scan.raw.columns.len(), POINTS_PER_LINE);
    assert_eq!(scan.file_index.len(), scan.raw.points.len());
    if let Some(pose) = pose {
        scan.track = PoseTrack::stationary(pose);
    }
    Leveler::new(SegmentParams::default())
        .level(&scan.raw, &scan.track, &scan.sensor_in_robot)
        .expect("a standing robot deskews");
});
