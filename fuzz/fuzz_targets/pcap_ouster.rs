//! An Ouster capture (`levelmap level FILE.pcap --meta FILE.json`, the edge's files source):
//! the bytes as a pcap file through `scanio::pcap::PcapReader` (the reader
//! `FrameReader::open` makes of the file) and `ouster::FrameReader` (datagrams on the lidar
//! port decoded as packets, grouped into frames), every complete frame projected into a scan
//! (`to_scan`), and the read's report. The same bytes are read with four fixed metadata: the
//! shared OS-1-128 file (`ouster/`, low-bandwidth profile, 8448-byte packets), and one tiny
//! sensor per packet profile built here (2 beams, 16 columns a frame, 4 a packet: 144 to
//! 208-byte packets), so that a whole frame fits in a few hundred bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scanio::ouster::{FrameReader, Profile, SensorMeta, XyzLut, to_scan};
use scanio::pcap::PcapReader;
use std::path::Path;
use std::sync::LazyLock;

/// Each metadata with its lookup table (the OS-1-128's is 131,072 pixels: made once).
static SENSORS: LazyLock<Vec<(SensorMeta, XyzLut)>> = LazyLock::new(|| {
    let os1 = SensorMeta::parse(
        include_bytes!("../ouster/OS-1-128_v2.3.0_1024x10.json"),
        Path::new("OS-1-128_v2.3.0_1024x10.json"),
    )
    .expect("the shared metadata parses");
    [os1]
        .into_iter()
        .chain(
            [
                Profile::Legacy,
                Profile::Rng19Rfl8Sig16Nir16,
                Profile::Rng15Rfl8Nir8,
            ]
            .map(tiny),
        )
        .map(|meta| {
            let lut = XyzLut::new(&meta);
            (meta, lut)
        })
        .collect()
});

/// A sensor of 2 beams, 16 columns a frame in packets of 4, sending columns 2 to 13 (the
/// window of an OS sensor's narrowed field of view), each row shifted.
fn tiny(profile: Profile) -> SensorMeta {
    SensorMeta {
        prod_line: "tiny".into(),
        udp_port_lidar: 7502,
        profile,
        columns_per_frame: 16,
        columns_per_packet: 4,
        pixels_per_column: 2,
        pixel_shift_by_row: vec![3, -1],
        column_window: (2, 13),
        beam_altitude_deg: vec![10.0, -10.0],
        beam_azimuth_deg: vec![1.5, -1.5],
        beam_origin_mm: (15.8, 0.0),
        lidar_to_sensor: [
            -1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 36.18, 0.0, 0.0, 0.0, 1.0,
        ],
    }
}

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.pcap");
    for (meta, lut) in SENSORS.iter() {
        let Ok(pcap) = PcapReader::new(data, path) else {
            return;
        };
        let mut reader = FrameReader::new(pcap, meta.clone());
        let (w, h) = (meta.columns_per_frame, meta.pixels_per_column);
        let mut frames = 0;
        while let Some(frame) = reader.next_frame() {
            frames += 1;
            assert_eq!(frame.ranges_mm.len(), w * h);
            let scan = to_scan(&frame, meta, lut);
            assert_eq!(scan.file_index.len(), w * h);
            assert_eq!(scan.raw.points.len(), w * h);
        }
        let report = reader.report();
        let counts = &report.counts;
        assert_eq!(counts.frames, frames);
        assert_eq!(
            counts.pcap.udp,
            counts.lidar_packets + counts.bad_packets + counts.other_ports,
            "every datagram is counted once"
        );
        report.warnings(path);
    }
});
