//! Speed of IDC scan matching on one core: two 360-beam scans, from an initial guess off by
//! about 0.3 m and 3–5°. Target: ≤ 0.5 ms per match (release). Measured (divan medians, a
//! shared machine): 0.25 ms synthetic, 0.31 ms Freiburg (from 0.30 and 0.36 ms before the
//! contour's per-segment data and branch work; docs/measurements/slam.md).
//!
//!     cargo bench -p slam --bench idc
//!
//! The real pair needs ../shared/data beside the repository (or LEVELMAP_DATA); it fails
//! loudly without it.

use slam::Pose2;
use slam::matching::synthetic::{Scene, uniform_bearings};
use slam::matching::{IdcParams, Scan2, idc};
use std::f64::consts::PI;

fn main() {
    divan::main();
}

/// Synthetic: the outdoor-like park (walls, a car, trees), 360 beams at 0.5° over 180°, 1 cm
/// range noise; the second scan 1.2 m ahead and turned 8°; the guess 0.3 m and 5° off.
#[divan::bench]
fn synthetic_park_360_beams(bencher: divan::Bencher) {
    let scene = Scene::park();
    let bearings = uniform_bearings(360, -PI / 2.0, PI / 360.0);
    let scan = |pose: &Pose2, seed| {
        let ranges = scene.scan(pose, &bearings, 40.0, 0.01, seed);
        Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths")
    };
    let (from, to) = (Pose2::new(0.0, 0.0, 0.1), Pose2::new(1.2, 0.3, 0.24));
    let (reference, current) = (scan(&from, 1), scan(&to, 2));
    let truth = from.between(&to);
    let guess = truth.compose(&Pose2::new(0.21, -0.21, 5f64.to_radians()));
    let params = IdcParams::default();
    bencher.bench_local(|| idc(&reference, &current, guess, &params).expect("overlapping scans"));
}

/// Real: two consecutive scans of the outdoor Freiburg campus log (360 beams over 180°,
/// 1.1 m apart), from their corrected relative pose perturbed by (0.2 m, 0.2 m, 3°).
#[divan::bench]
fn freiburg_campus_pair(bencher: divan::Bencher) {
    let path = testdata::shared_data("radish_2d_corrected_logs/freiburg-campus-corrected.log.gz");
    let log = graphio::carmen::read(&path).unwrap_or_else(|e| panic!("{e}"));
    let (a, b) = (&log.scans[7], &log.scans[8]);
    let scan = |s: &graphio::carmen::LaserScan| s.to_scan2();
    let (reference, current) = (scan(a), scan(b));
    let truth = a.laser_pose.between(&b.laser_pose);
    let guess = truth.compose(&Pose2::new(0.2, 0.2, 3f64.to_radians()));
    let params = IdcParams::default();
    bencher.bench_local(|| idc(&reference, &current, guess, &params).expect("overlapping scans"));
}
