use super::packet::build_packet;
use super::*;
use crate::pcap::build;
use std::path::PathBuf;

/// 32 columns per frame in packets of 16, two beams: +10° and −10°, no azimuth offsets,
/// beam origin 10 mm, sensor frame = lidar frame.
fn meta(profile: &str) -> SensorMeta {
    let json = serde_json::json!({
        "beam_altitude_angles": [10.0, -10.0],
        "beam_azimuth_angles": [0.0, 0.0],
        "lidar_origin_to_beam_origin_mm": 10.0,
        "lidar_to_sensor_transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
        "data_format": {
            "columns_per_frame": 32, "columns_per_packet": 16, "pixels_per_column": 2,
            "pixel_shift_by_row": [1, 0], "column_window": [0, 31],
            "udp_profile_lidar": profile
        }
    });
    SensorMeta::parse(json.to_string().as_bytes(), Path::new("m.json")).unwrap()
}

struct Temp(PathBuf);
impl Drop for Temp {
    fn drop(&mut self) {
        std::fs::remove_file(&self.0).ok();
    }
}

fn write_capture(name: &str, packets: &[Vec<u8>]) -> Temp {
    let mut bytes = build::header();
    for (i, p) in packets.iter().enumerate() {
        bytes.extend(build::record(i as u32, 7502, p));
    }
    bytes.extend(build::record(99, 7503, b"imu"));
    let path = std::env::temp_dir().join(format!("scanio-{}-{name}.pcap", std::process::id()));
    std::fs::write(&path, bytes).unwrap();
    Temp(path)
}

/// Range (mm) of beam `row` at measurement `id`.
fn range(id: u16, row: usize) -> u32 {
    if id == 3 && row == 0 {
        0
    } else {
        2000 + 8 * id as u32 + 800 * row as u32
    }
}

fn read(path: &Path, meta: SensorMeta) -> (Vec<Frame>, OusterReport) {
    let mut reader = FrameReader::open(path, meta).unwrap();
    let mut frames = Vec::new();
    while let Some(f) = reader.next_frame() {
        frames.push(f);
    }
    (frames, reader.report())
}

#[test]
fn frames_are_assembled_by_id_and_incomplete_ones_counted() {
    for profile in ["LEGACY", "RNG19_RFL8_SIG16_NIR16", "RNG15_RFL8_NIR8"] {
        let meta = meta(profile);
        let layout = PacketLayout::of(&meta);
        let p = |frame, first| build_packet(&layout, frame, first, range);
        let mut wrong = p(6, 0);
        wrong.pop();
        let capture = write_capture(profile, &[p(5, 16), p(6, 0), wrong, p(6, 16), p(7, 0)]);
        let (frames, report) = read(&capture.0, meta.clone());
        assert_eq!(frames.len(), 1, "{profile}: {report:?}");
        let c = &report.counts;
        assert_eq!((c.frames, c.incomplete_frames, c.bad_packets), (1, 2, 1));
        assert_eq!((c.lidar_packets, c.other_ports), (4, 1));
        assert!(
            report
                .first_bad_packet
                .as_ref()
                .unwrap()
                .contains("expected")
        );
        let f = &frames[0];
        assert_eq!(f.frame_id, 6);
        assert_eq!(f.ranges_mm[32 + 17], range(17, 1));
        assert!(f.column_valid.iter().all(|&v| v));
        let warnings = report.warnings(&capture.0);
        assert!(
            warnings
                .iter()
                .all(|w| w.starts_with(&*capture.0.to_string_lossy()))
        );
    }
}

#[test]
fn scans_are_destaggered_bottom_up_and_projected_with_the_beam_origin() {
    let meta = meta("RNG19_RFL8_SIG16_NIR16");
    let layout = PacketLayout::of(&meta);
    let capture = write_capture(
        "scan",
        &[
            build_packet(&layout, 1, 0, range),
            build_packet(&layout, 1, 16, range),
        ],
    );
    let (frames, _) = read(&capture.0, meta.clone());
    let scan = to_scan(&frames[0], &meta, &XyzLut::new(&meta));
    assert_eq!(scan.raw.columns.len(), 32);
    // Column 4: the lower beam (row 1, shift 0) at id 4, the upper (row 0, shift 1) at id 3,
    // which has no return.
    let column = scan.raw.column_points(4);
    assert!(column[0].is_valid() && !column[1].is_valid());
    assert_eq!(&scan.file_index[8..10], &[32 + 4, 3]);
    // Column 0 (encoder 2π: straight ahead): the upper beam is id 31 (shift 1).
    let upper = scan.raw.column_points(0)[1].to_xyz();
    let (r, n) = (range(31, 0) as f64 / 1000.0, 0.010);
    let encoder = 2.0 * std::f64::consts::PI * (1.0 - 31.0 / 32.0);
    let alt = 10f64.to_radians();
    let want = [
        (r - n) * encoder.cos() * alt.cos() + n * encoder.cos(),
        (r - n) * encoder.sin() * alt.cos() + n * encoder.sin(),
        (r - n) * alt.sin(),
    ];
    for i in 0..3 {
        assert!(
            (upper[i] as f64 - want[i]).abs() < 1e-5,
            "{upper:?} vs {want:?}"
        );
    }
    // Stamps: the middle beam's (row 1, shift 0) measurement.
    assert_eq!(scan.raw.columns[5].stamp_ns, frames[0].stamps_ns[5]);
}

#[test]
fn a_capture_without_a_complete_frame_is_an_error_naming_it() {
    let meta = meta("RNG15_RFL8_NIR8");
    let layout = PacketLayout::of(&meta);
    let capture = write_capture("none", &[build_packet(&layout, 1, 0, range)]);
    let meta_path = std::env::temp_dir().join(format!("scanio-{}-m.json", std::process::id()));
    let _m = Temp(meta_path.clone());
    let json = serde_json::json!({
        "beam_altitude_angles": [10.0, -10.0], "beam_azimuth_angles": [0.0, 0.0],
        "lidar_origin_to_beam_origin_mm": 10.0,
        "lidar_to_sensor_transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
        "data_format": {"columns_per_frame": 32, "columns_per_packet": 16,
            "pixels_per_column": 2, "pixel_shift_by_row": [1, 0],
            "udp_profile_lidar": "RNG15_RFL8_NIR8"}
    });
    std::fs::write(&meta_path, json.to_string()).unwrap();
    assert_eq!(SensorMeta::load(&meta_path).unwrap(), meta);
    let e = load_all(&capture.0, &meta_path).unwrap_err().to_string();
    assert!(e.starts_with(&*capture.0.to_string_lossy()), "{e}");
    assert!(
        e.contains("no complete frame") && e.contains("1 incomplete"),
        "{e}"
    );
}

/// Found by the `pcap_ouster` fuzz target: a packet with a column outside the window was
/// counted both as a lidar packet and a bad one, its columns before that one were kept, and
/// a frame id of its own ended the frame being filled.
#[test]
fn a_packet_outside_the_window_is_dropped_whole() {
    let meta = meta("RNG19_RFL8_SIG16_NIR16");
    let layout = PacketLayout::of(&meta);
    // Columns 20 to 35 of a 32-column frame, of another frame id, with other ranges.
    let outside = build_packet(&layout, 9, 20, |_, _| 8);
    let mut bytes = build::header();
    for (i, p) in [
        build_packet(&layout, 6, 0, range),
        outside,
        build_packet(&layout, 6, 16, range),
    ]
    .iter()
    .enumerate()
    {
        bytes.extend(build::record(i as u32, 7502, p));
    }
    let pcap = crate::pcap::PcapReader::new(&bytes[..], Path::new("t.pcap")).unwrap();
    let mut reader = FrameReader::new(pcap, meta);
    let frame = reader.next_frame().expect("frame 6, whole");
    assert!(reader.next_frame().is_none());
    for m in 0..32 {
        for row in 0..2 {
            assert_eq!(
                frame.ranges_mm[row * 32 + m],
                range(m as u16, row),
                "{m}, {row}"
            );
        }
    }
    let report = reader.report();
    let c = &report.counts;
    assert_eq!((c.lidar_packets, c.bad_packets), (2, 1));
    assert_eq!((c.frames, c.incomplete_frames), (1, 0));
    let why = report.first_bad_packet.expect("a bad packet");
    assert!(why.contains("measurement id 32 outside"), "{why}");
}
