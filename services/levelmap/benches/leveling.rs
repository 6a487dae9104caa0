//! Speed of leveling on one core: segmentation + projection (what `elapsed_ms` reports) on
//! the real KITTI frames and on seed-sized simulated scans (27,000 points), plus motion
//! compensation and the simulator's ray casting for scale.
//!
//!     cargo bench -p levelmap --bench leveling
//!
//! Needs ../shared/data beside the repository (or LEVELMAP_DATA); fails loudly without it.

use leveling::{Leveler, Scan3d, SegmentParams, deskew};
use scanio::ScanFormat;
use testdata::shared_data;

fn main() {
    divan::main();
}

/// A scan file, loaded and leveled up to the segmentation input.
fn leveled_cloud(relative: &str, format: ScanFormat) -> Scan3d {
    let loaded = scanio::load(&shared_data(relative), format).expect("load");
    deskew(&loaded.raw, &loaded.track, &loaded.sensor_in_robot).expect("deskew")
}

const KITTI_FRAMES: [&str; 4] = [
    "kitti_velodyne/patchwork-plusplus/000000.bin",
    "kitti_velodyne/segregator/000020.bin",
    "kitti_velodyne/segregator/000030.bin",
    "kitti_velodyne/segregator/004413.bin",
];

/// Segmentation + projection of a KITTI HDL-64E scan (~124,000 points, 2,048 columns).
#[divan::bench(args = KITTI_FRAMES)]
fn kitti_segment_and_project(bencher: divan::Bencher, frame: &str) {
    let cloud = leveled_cloud(frame, ScanFormat::Kitti);
    let mut leveler = Leveler::new(SegmentParams::default());
    bencher
        .with_inputs(|| cloud.clone())
        .bench_local_values(|cloud| leveler.segment_and_project(cloud));
}

/// Segmentation + projection of the 3DTK nodding-SICK scan (81,360 points, 360 columns).
#[divan::bench]
fn threedtk_segment_and_project(bencher: divan::Bencher) {
    let cloud = leveled_cloud(
        "rotating_2d_laser_3d_scans_3dtk/scan000.3d",
        ScanFormat::ThreeDtk,
    );
    let mut leveler = Leveler::new(SegmentParams::default());
    bencher
        .with_inputs(|| cloud.clone())
        .bench_local_values(|cloud| leveler.segment_and_project(cloud));
}

const SCENES: [&str; 3] = ["pavilion", "wall", "demo"];

fn seed_scan(scene: &str) -> sim::SimScanFile {
    match scene {
        "pavilion" => sim::scenario::pavilion_hill_scan(1).0,
        "wall" => sim::scenario::wall_drive_scan(1, 1.4),
        _ => sim::scenario::demo_scan(1),
    }
}

/// Segmentation + projection of a seed-sized scan (the paper's sensor: 270 × 100 points).
#[divan::bench(args = SCENES)]
fn seed_segment_and_project(bencher: divan::Bencher, scene: &str) {
    let file = seed_scan(scene);
    let cloud = deskew(
        &file.raw,
        &file.track().expect("track"),
        &file.sensor_in_robot,
    )
    .expect("deskew");
    let mut leveler = Leveler::new(SegmentParams::default());
    bencher
        .with_inputs(|| cloud.clone())
        .bench_local_values(|cloud| leveler.segment_and_project(cloud));
}

/// Motion compensation of a seed-sized scan taken while driving at 1.4 m/s.
#[divan::bench]
fn seed_deskew(bencher: divan::Bencher) {
    let file = seed_scan("wall");
    let track = file.track().expect("track");
    bencher.bench_local(|| deskew(&file.raw, &track, &file.sensor_in_robot).expect("deskew"));
}

/// The simulator: ray casting one 27,000-point scan in the park.
#[divan::bench(sample_count = 20)]
fn sim_scan_raycast(bencher: divan::Bencher) {
    let world = sim::World::park();
    let route = sim::scenario::demo_route(&world);
    let truth = route.truth(&world);
    let scanner = sim::YawingScanner::default();
    let mut rng = sim::Rng::new(1);
    bencher.bench_local(|| scanner.scan(&world, &truth, sim::scenario::SCAN_START_NS, &mut rng));
}
