//! Speed of the point-to-line refinement (`slam::matching::refine`) on one core, from IDC's
//! match of the same pairs as `benches/idc.rs`: what it adds to each match.
//!
//!     cargo bench -p slam --bench refine
//!
//! The real pair needs ../shared/data beside the repository (or LEVELMAP_DATA).

use slam::Pose2;
use slam::matching::synthetic::{Scene, uniform_bearings};
use slam::matching::{IdcParams, Match, RefineParams, Scan2, idc, refine};
use std::f64::consts::PI;

fn main() {
    divan::main();
}

fn bench_refine(bencher: divan::Bencher, reference: &Scan2, current: &Scan2, start: &Match) {
    let (params, refine_params) = (IdcParams::default(), RefineParams::default());
    bencher.bench_local(|| {
        refine(reference, current, start, &params, &refine_params).expect("overlapping scans")
    });
}

/// Synthetic: the park, 360 beams over 180°, 1 cm noise, 1.2 m and 8° apart.
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
    let guess = from
        .between(&to)
        .compose(&Pose2::new(0.21, -0.21, 5f64.to_radians()));
    let start = idc(&reference, &current, guess, &IdcParams::default()).expect("overlap");
    bench_refine(bencher, &reference, &current, &start);
}

/// Real: two consecutive scans of the Freiburg campus log, 1.1 m apart.
#[divan::bench]
fn freiburg_campus_pair(bencher: divan::Bencher) {
    let path = testdata::shared_data("radish_2d_corrected_logs/freiburg-campus-corrected.log.gz");
    let log = graphio::carmen::read(&path).unwrap_or_else(|e| panic!("{e}"));
    let (a, b) = (&log.scans[7], &log.scans[8]);
    let (reference, current) = (a.to_scan2(), b.to_scan2());
    let guess =
        a.laser_pose
            .between(&b.laser_pose)
            .compose(&Pose2::new(0.2, 0.2, 3f64.to_radians()));
    let start = idc(&reference, &current, guess, &IdcParams::default()).expect("overlap");
    bench_refine(bencher, &reference, &current, &start);
}
