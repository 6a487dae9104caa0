//! Speed on one core of the sensor files: reading an Ouster frame (packets → organized scan)
//! and leveling one (segmentation + projection, what `levelmap level` reports as
//! `elapsed_ms`) next to a KITTI frame. The aim (issue 13): ≤ 1 ms to level either.
//!
//!     cargo bench -p scanio --bench sensor_files
//!
//! Needs ../shared/data beside the repository (or LEVELMAP_DATA); fails loudly without it.

use leveling::{Leveler, Scan3d, SegmentParams, deskew};
use scanio::{LoadedScan, ScanFormat, ouster};
use testdata::shared_data;

fn main() {
    divan::main();
}

const OS1: (&str, &str) = (
    "ouster_organized_scans/OS-1-128_v2.3.0_1024x10_lb_n3.pcap",
    "ouster_organized_scans/OS-1-128_v2.3.0_1024x10.json",
);

fn os1_frames() -> Vec<LoadedScan> {
    ouster::load_all(&shared_data(OS1.0), &shared_data(OS1.1))
        .expect("load")
        .0
}

fn segmentation_input(loaded: &LoadedScan) -> Scan3d {
    deskew(&loaded.raw, &loaded.track, &loaded.sensor_in_robot).expect("deskew")
}

/// Segmentation + projection of the first OS-1-128 1024×10 frame (131,072 pixels).
#[divan::bench]
fn ouster_os1_segment_and_project(bencher: divan::Bencher) {
    let cloud = segmentation_input(&os1_frames()[0]);
    let mut leveler = Leveler::new(SegmentParams::default());
    bencher
        .with_inputs(|| cloud.clone())
        .bench_local_values(|cloud| leveler.segment_and_project(cloud));
}

/// Segmentation + projection of KITTI 00 frame 0 (124,668 points, 2,048 columns).
#[divan::bench]
fn kitti_segment_and_project(bencher: divan::Bencher) {
    let path = shared_data("kitti_velodyne/patchwork-plusplus/000000.bin");
    let cloud = segmentation_input(&scanio::load(&path, ScanFormat::Kitti).expect("load"));
    let mut leveler = Leveler::new(SegmentParams::default());
    bencher
        .with_inputs(|| cloud.clone())
        .bench_local_values(|cloud| leveler.segment_and_project(cloud));
}

/// Decoding one OS-1 frame into its organized scan (lookup table made once).
#[divan::bench]
fn ouster_os1_frame_to_scan(bencher: divan::Bencher) {
    let meta = ouster::SensorMeta::load(&shared_data(OS1.1)).expect("meta");
    let lut = ouster::XyzLut::new(&meta);
    let mut reader = ouster::FrameReader::open(&shared_data(OS1.0), meta.clone()).expect("open");
    let frame = reader.next_frame().expect("a frame");
    bencher.bench_local(|| ouster::to_scan(&frame, &meta, &lut));
}

/// Motion compensation of one OS-1 frame (standing still: the frame as read).
#[divan::bench]
fn ouster_os1_deskew(bencher: divan::Bencher) {
    let loaded = &os1_frames()[0];
    bencher.bench_local(|| segmentation_input(loaded));
}
