//! Speed of the correlative branch-and-bound search (`slam::matching::correlative`) on one
//! core, release build: a 361-beam 360° scan of the synthetic park against a submap of five
//! scans of it (about 40 × 40 m at 0.05 m cells, the default parameters), in a ±5 m × ±30°
//! window and over the whole submap at every heading. Each prints the branch-and-bound
//! nodes (candidates scored) of one search, against the window's poses. And what making a
//! submap's grids costs the mapper when it first searches the submap: rasterizing its scans,
//! then pooling the grid into its levels.
//!
//!     cargo bench -p slam --bench correlative

use slam::Pose2;
use slam::matching::Scan2;
use slam::matching::correlative::{
    CorrelativeParams, PrecomputedGrids, ProbabilityGrid, SearchWindow, precompute, search,
};
use slam::matching::synthetic::{Scene, uniform_bearings};
use std::f64::consts::PI;

fn main() {
    divan::main();
}

fn scan_at(scene: &Scene, pose: &Pose2, seed: u64) -> Scan2 {
    let bearings = uniform_bearings(361, -PI, PI / 180.0);
    let ranges = scene.scan(pose, &bearings, 40.0, 0.01, seed);
    Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths")
}

/// The submap, the scan (at its true pose in the submap) and the parameters.
fn setup() -> (PrecomputedGrids, Scan2, Pose2, CorrelativeParams) {
    let scene = Scene::park();
    let params = CorrelativeParams::default();
    let poses = [
        (0.0, 0.0, 0.0),
        (2.0, 0.5, 0.3),
        (-3.0, -1.0, 1.0),
        (5.0, -2.0, -0.5),
        (-6.0, 2.0, 2.0),
    ];
    let scans: Vec<(Pose2, Scan2)> = poses
        .iter()
        .enumerate()
        .map(|(k, &(x, y, t))| {
            let pose = Pose2::new(x, y, t);
            (pose, scan_at(&scene, &pose, k as u64))
        })
        .collect();
    let grids = precompute(scans.iter().map(|(p, s)| (*p, s)), &params).expect("grid");
    let truth = Pose2::new(1.0, -1.5, 0.7);
    (grids, scan_at(&scene, &truth, 99), truth, params)
}

fn bench_window(
    bencher: divan::Bencher,
    window: SearchWindow,
    initial: impl Fn(&PrecomputedGrids, Pose2) -> Pose2,
    name: &str,
) {
    let (grids, scan, truth, params) = setup();
    let initial = initial(&grids, truth);
    let m = search(&grids, &scan, initial, &window, 0.5, &params).expect("found");
    let side = 2.0 * (window.linear_m / params.resolution_m).ceil() + 1.0;
    let (lo, hi) = grids.grid().bounds();
    eprintln!(
        "{name}: submap {:.0} × {:.0} m, score {:.3}, error {:.3} m, {} nodes scored ({:.0} translations per angle)",
        hi[0] - lo[0],
        hi[1] - lo[1],
        m.score,
        (m.pose.x - truth.x).hypot(m.pose.y - truth.y),
        m.nodes,
        side * side
    );
    bencher.bench_local(|| search(&grids, &scan, initial, &window, 0.5, &params));
}

/// ±5 m × ±30°, the guess 3 m and 20° off.
#[divan::bench]
fn window_5m_30deg(bencher: divan::Bencher) {
    let window = SearchWindow {
        linear_m: 5.0,
        angular_rad: 30f64.to_radians(),
    };
    let off = |_: &PrecomputedGrids, t: Pose2| {
        Pose2::new(t.x + 2.4, t.y - 1.8, t.theta - 20f64.to_radians())
    };
    bench_window(bencher, window, off, "±5 m × ±30°");
}

/// The whole submap at every heading, from its centre.
#[divan::bench]
fn whole_submap_360deg(bencher: divan::Bencher) {
    let window = SearchWindow {
        linear_m: 20.0,
        angular_rad: PI,
    };
    let centre = |g: &PrecomputedGrids, _: Pose2| {
        let (lo, hi) = g.grid().bounds();
        Pose2::new((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, 0.0)
    };
    bench_window(bencher, window, centre, "whole submap × 360°");
}

/// A submap as the mapper pools it (`SubmapSearchParams::default().grid`: 0.1 m cells, 20 m of
/// returns, 9 levels): 21 scans over 10 m of path, rasterized and then pooled.
fn mapper_submap() -> (Vec<(Pose2, Scan2)>, CorrelativeParams) {
    let scene = Scene::park();
    let params = slam::SubmapSearchParams::default().grid;
    let scans = (0..21)
        .map(|k| {
            let pose = Pose2::new(0.5 * k as f64, 0.1 * k as f64, 0.02 * k as f64);
            (pose, scan_at(&scene, &pose, k as u64))
        })
        .collect();
    (scans, params)
}

fn returns(scans: &[(Pose2, Scan2)]) -> impl Iterator<Item = (Pose2, &[[f64; 2]])> {
    scans.iter().map(|(p, s)| (*p, s.points()))
}

/// Rasterizing the mapper's submap (the probability grid, no levels).
#[divan::bench]
fn rasterize_mapper_submap(bencher: divan::Bencher) {
    let (scans, params) = mapper_submap();
    bencher.bench_local(|| ProbabilityGrid::from_scans(returns(&scans), &params));
}

/// Pooling the mapper's submap grid into its levels.
#[divan::bench]
fn pool_mapper_submap(bencher: divan::Bencher) {
    let (scans, params) = mapper_submap();
    let grid = ProbabilityGrid::from_scans(returns(&scans), &params).expect("grid");
    let (w, h) = grid.bounds();
    let grids = PrecomputedGrids::new(grid.clone(), params.max_depth);
    eprintln!(
        "mapper submap: {:.0} × {:.0} m, {} levels, {:.1} MB of cells",
        h[0] - w[0],
        h[1] - w[1],
        grids.depth() + 1,
        grids.cell_bytes() as f64 / 1e6
    );
    bencher.bench_local(|| PrecomputedGrids::new(grid.clone(), params.max_depth));
}
