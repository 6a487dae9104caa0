//! The public Ouster captures (../shared/data/ouster_organized_scans): frames, geometry and
//! bad input. A missing data folder fails these tests: they never skip.

use scanio::ouster::{self, FrameReader, OusterScans, SensorMeta};
use std::path::{Path, PathBuf};
use testdata::shared_data as data;

const OS1: (&str, &str) = (
    "ouster_organized_scans/OS-1-128_v2.3.0_1024x10_lb_n3.pcap",
    "ouster_organized_scans/OS-1-128_v2.3.0_1024x10.json",
);
const OS2: (&str, &str) = (
    "ouster_organized_scans/OS-2-128-U1_v2.3.0_1024x10.pcap",
    "ouster_organized_scans/OS-2-128-U1_v2.3.0_1024x10.json",
);

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("scanio-ouster-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn the_captures_hold_their_frames_and_every_row_its_beam_elevation() {
    for ((pcap, meta), frames) in [(OS1, 3), (OS2, 1)] {
        let (pcap, meta) = (data(pcap), data(meta));
        let (scans, report) = ouster::load_all(&pcap, &meta).expect("load");
        let c = &report.counts;
        assert_eq!(scans.len(), frames, "{report:?}");
        assert_eq!((c.incomplete_frames, c.bad_packets), (0, 0), "{report:?}");
        assert_eq!(c.lidar_packets, 64 * frames as u64);
        assert_eq!(report.truncated, None);
        let meta = SensorMeta::load(&meta).unwrap();
        let (angles, lidar_z_m) = (&meta.beam_altitude_deg, meta.lidar_to_sensor[11] * 1e-3);
        let scan = &scans[0].raw;
        assert_eq!((scan.columns.len(), scan.points.len()), (1024, 131_072));
        assert!(scan.valid_points() > 100_000, "{}", scan.valid_points());
        // Far points: the elevation seen from the lidar origin (above the sensor's) is the
        // beam's (the beam origin's 15 mm matter little beyond 10 m). Rows are bottom-up.
        let mut worst = 0f64;
        for c in 0..scan.columns.len() {
            for (k, p) in scan.column_points(c).iter().enumerate() {
                if p.is_valid() && p.r_m > 10.0 {
                    let beam = angles[angles.len() - 1 - k];
                    let elevation = (p.z_m as f64 - lidar_z_m).atan2(p.r_m as f64).to_degrees();
                    worst = worst.max((elevation - beam).abs());
                }
            }
        }
        println!(
            "{}: worst elevation vs beam angle {worst:.3}°",
            pcap.display()
        );
        assert!(worst < 0.1, "{worst}");
        // Columns are stamped in measurement order, about 100 ms for a rotation.
        assert!(
            scan.columns
                .windows(2)
                .all(|c| c[0].stamp_ns <= c[1].stamp_ns)
        );
        let span = scan.columns.last().unwrap().stamp_ns - scan.columns[0].stamp_ns;
        assert!((90_000_000..110_000_000).contains(&span), "{span}");
    }
}

/// The first pixels of the OS-1 capture's first packet, decoded by hand from the bytes
/// (RNG15: u16 range in 8 mm units at offset 32 + 12 + 4·row of the packet).
#[test]
fn ranges_match_the_first_packets_bytes() {
    let pcap = data(OS1.0);
    let bytes = std::fs::read(&pcap).unwrap();
    // Global header 24, record header 16, Ethernet 14, IPv4 20, UDP 8.
    let packet = &bytes[24 + 16 + 42..];
    let meta = SensorMeta::load(&data(OS1.1)).unwrap();
    let mut reader = FrameReader::open(&pcap, meta.clone()).unwrap();
    let frame = reader.next_frame().unwrap();
    assert_eq!(frame.frame_id, u16::from_le_bytes([packet[2], packet[3]]));
    let mut checked = 0;
    for row in 0..128 {
        let at = 32 + 12 + 4 * row;
        let by_hand = (u16::from_le_bytes([packet[at], packet[at + 1]]) as u32 & 0x7fff) * 8;
        assert_eq!(frame.ranges_mm[row * 1024], by_hand, "row {row}");
        checked += (by_hand > 0) as usize;
    }
    assert!(checked > 30, "{checked} returns in the first column");
}

#[test]
fn a_truncated_capture_is_a_partial_read_naming_the_file() {
    let bytes = std::fs::read(data(OS1.0)).unwrap();
    let meta = data(OS1.1);
    let path = scratch("cut.pcap");
    // Inside the second frame's data, inside a record header, inside the global header.
    for (cut, frames) in [(bytes.len() * 2 / 3, 1), (24 + 10, 0), (10, 0)] {
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let mut scans = match OusterScans::open(&path, &meta) {
            Ok(s) => s,
            Err(e) => {
                assert_eq!(frames, 0);
                assert!(e.to_string().starts_with(&*path.to_string_lossy()), "{e}");
                continue;
            }
        };
        let mut n = 0;
        while scans.next_scan().is_some() {
            n += 1;
        }
        assert_eq!(n, frames, "cut at {cut}");
        let report = scans.report();
        let why = report.truncated.expect("reported");
        assert!(why.starts_with(&*path.to_string_lossy()), "{why}");
        if frames == 0 {
            let e = ouster::load_all(&path, &meta).unwrap_err().to_string();
            assert!(e.contains("no complete frame"), "{e}");
        }
    }
    std::fs::remove_file(&path).ok();
}

#[test]
fn a_packet_of_the_wrong_size_is_dropped_with_its_frame_and_reported() {
    let bytes = std::fs::read(data(OS1.0)).unwrap();
    // Cut 4 bytes off the UDP payload of the first lidar record (lengths kept consistent).
    let mut damaged = bytes[..24].to_vec();
    let incl = u32::from_le_bytes(bytes[32..36].try_into().unwrap()) as usize;
    let mut record = bytes[24..24 + 16 + incl].to_vec();
    let shorter = |at: usize, width: usize, r: &mut Vec<u8>| {
        let mut v = 0u32;
        for i in 0..width {
            v = (v << 8) | r[at + i] as u32;
        }
        let v = (v - 4).to_be_bytes();
        r[at..at + width].copy_from_slice(&v[4 - width..]);
    };
    shorter(16 + 16, 2, &mut record); // IPv4 total length
    shorter(16 + 38, 2, &mut record); // UDP length
    record.truncate(record.len() - 4);
    let len = (incl as u32 - 4).to_le_bytes();
    record[8..12].copy_from_slice(&len);
    record[12..16].copy_from_slice(&len);
    damaged.extend(record);
    damaged.extend(&bytes[24 + 16 + incl..]);
    let path = scratch("short-packet.pcap");
    std::fs::write(&path, damaged).unwrap();
    let (scans, report) = ouster::load_all(&path, &data(OS1.1)).expect("two frames left");
    assert_eq!(scans.len(), 2);
    assert_eq!(
        (report.counts.bad_packets, report.counts.incomplete_frames),
        (1, 1)
    );
    let warnings = report.warnings(&path).join("\n");
    assert!(warnings.contains("8444 bytes, expected 8448"), "{warnings}");
    assert!(warnings.starts_with(&*path.to_string_lossy()), "{warnings}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn metadata_missing_a_field_is_an_error_naming_the_file() {
    let text = std::fs::read_to_string(data(OS1.1)).unwrap();
    let full: serde_json::Value = serde_json::from_str(&text).unwrap();
    let path = scratch("meta.json");
    for field in [
        "beam_altitude_angles",
        "beam_azimuth_angles",
        "lidar_origin_to_beam_origin_mm",
        "lidar_to_sensor_transform",
        "data_format",
    ] {
        let mut v = full.clone();
        v.as_object_mut().unwrap().remove(field);
        std::fs::write(&path, v.to_string()).unwrap();
        let e = OusterScans::open(&data(OS1.0), &path)
            .err()
            .expect(field)
            .to_string();
        assert!(
            e.starts_with(&*path.to_string_lossy()) && e.contains("lacks"),
            "{e}"
        );
    }
    std::fs::write(&path, &text[..text.len() / 2]).unwrap();
    let e = SensorMeta::load(&path).unwrap_err().to_string();
    assert!(e.contains("not JSON"), "{e}");
    let missing = Path::new("/nonexistent/meta.json");
    assert!(
        SensorMeta::load(missing)
            .unwrap_err()
            .to_string()
            .starts_with("/nonexistent")
    );
    std::fs::remove_file(&path).ok();
}
