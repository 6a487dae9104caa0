//! A KITTI Velodyne `.bin` scan (`levelmap level FILE --format kitti [--labels FILE.label]`,
//! the edge's files source): `scanio::kitti::parse`, the function `load(path)` calls on the
//! file's bytes, then the leveling the robot runs on it. The input's first quarter is also
//! read as the scan's SemanticKITTI `.label` file (`Labels::parse`: one u32 per point, so a
//! whole scan has a whole label file) and scores the segmentation, as `--labels` does.
#![no_main]

use leveling::{Leveler, Precision, SegmentParams};
use libfuzzer_sys::fuzz_target;
use scanio::kitti::{DEFAULT_COLUMNS, POINT_BYTES, parse};
use scanio::labels::Labels;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(scan) = parse(data, Path::new("fuzz.bin"), DEFAULT_COLUMNS) else {
        return;
    };
    let points = data.len() / POINT_BYTES;
    assert_eq!(scan.file_index.len(), points);
    assert_eq!(scan.raw.points.len(), points);
    let labels = Labels::parse(&data[..data.len() / 4], Path::new("fuzz.label"), points)
        .expect("a label per point");
    let leveled = Leveler::new(SegmentParams::default())
        .level(&scan.raw, &scan.track, &scan.sensor_in_robot)
        .expect("a standing robot deskews");
    Precision::score(&leveled.classes, &leveled.first_landmarks, |i| {
        labels.is_ground(scan.file_index[i] as usize)
    });
});
