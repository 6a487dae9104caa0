use super::*;
use crate::matching::synthetic::{Scene, uniform_bearings};
use crate::wrap_angle;
use std::f64::consts::PI;

fn scan_at(scene: &Scene, pose: &Pose2, seed: u64) -> Scan2 {
    let bearings = uniform_bearings(361, -PI, PI / 180.0);
    let ranges = scene.scan(pose, &bearings, 40.0, 0.01, seed);
    Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths")
}

/// A submap of the park from a few scans around the origin, in the map frame.
fn park_submap(params: &CorrelativeParams) -> (Scene, PrecomputedGrids) {
    let scene = Scene::park();
    let poses = [
        Pose2::new(0.0, 0.0, 0.0),
        Pose2::new(1.0, 0.3, 0.2),
        Pose2::new(2.0, 0.5, 0.4),
    ];
    let scans: Vec<(Pose2, Scan2)> = poses
        .iter()
        .enumerate()
        .map(|(k, p)| (*p, scan_at(&scene, p, k as u64)))
        .collect();
    let grids = precompute(scans.iter().map(|(p, s)| (*p, s)), params).expect("grid");
    (scene, grids)
}

fn coarse() -> CorrelativeParams {
    CorrelativeParams {
        resolution_m: 0.1,
        hit_sigma_m: 0.1,
        max_range_m: 15.0,
        ..CorrelativeParams::default()
    }
}

/// The angular step of `search` for scans reaching `range_m`.
fn angular_step(params: &CorrelativeParams) -> f64 {
    let (r, d) = (params.resolution_m, params.max_range_m);
    (1.0 - r * r / (2.0 * d * d)).acos()
}

#[test]
fn finds_a_known_offset_to_a_cell_and_an_angular_step() {
    let params = CorrelativeParams::default();
    let (scene, grids) = park_submap(&params);
    let truth = Pose2::new(1.3, -0.4, 0.3);
    let scan = scan_at(&scene, &truth, 9);
    let initial = Pose2::new(1.3 + 1.7, -0.4 - 2.2, 0.3 - 0.35);
    let window = SearchWindow {
        linear_m: 5.0,
        angular_rad: 30f64.to_radians(),
    };
    let m = search(&grids, &scan, initial, &window, 0.5, &params).expect("found");
    assert!(
        (m.pose.x - truth.x).abs() <= params.resolution_m
            && (m.pose.y - truth.y).abs() <= params.resolution_m,
        "{m:?}"
    );
    assert!(
        wrap_angle(m.pose.theta - truth.theta).abs() <= angular_step(&params) * 1.5,
        "{m:?}"
    );
    assert!(m.score > 0.7, "{m:?}");
}

#[test]
fn branch_and_bound_equals_the_exhaustive_search() {
    let params = CorrelativeParams {
        max_depth: 3,
        max_range_m: 10.0,
        ..coarse()
    };
    let (scene, grids) = park_submap(&params);
    let window = SearchWindow {
        linear_m: 0.8,
        angular_rad: 4f64.to_radians(),
    };
    for (k, offset) in [
        (0.0, 0.0, 0.0),
        (0.35, -0.52, 0.05),
        (-0.7, 0.2, -0.06),
        (3.0, 3.0, 1.0),
    ]
    .into_iter()
    .enumerate()
    {
        let truth = Pose2::new(0.6, 0.1 * k as f64, 0.1);
        let scan = scan_at(&scene, &truth, 20 + k as u64);
        let initial = Pose2::new(
            truth.x + offset.0,
            truth.y + offset.1,
            truth.theta + offset.2,
        );
        for min_score in [0.0, 0.6] {
            let fast = search(&grids, &scan, initial, &window, min_score, &params);
            let slow = exhaustive_search(&grids, &scan, initial, &window, min_score, &params);
            assert_eq!(fast.map(|m| m.score), slow.map(|m| m.score), "case {k}");
            if let (Some(f), Some(s)) = (fast, slow) {
                assert!(f.nodes < s.nodes, "{} vs {}", f.nodes, s.nodes);
            }
        }
    }
}

#[test]
fn a_whole_submap_search_finds_a_scan_moved_far_away() {
    let params = coarse();
    let (scene, grids) = park_submap(&params);
    let truth = Pose2::new(-1.0, 1.5, 2.0);
    let scan = scan_at(&scene, &truth, 5);
    let (lo, hi) = grids.grid().bounds();
    let centre = Pose2::new((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, -1.0);
    let window = SearchWindow {
        linear_m: (hi[0] - lo[0]).max(hi[1] - lo[1]) / 2.0,
        angular_rad: PI,
    };
    let m = search(&grids, &scan, centre, &window, 0.5, &params).expect("found");
    assert!(
        (m.pose.x - truth.x).abs() <= params.resolution_m
            && (m.pose.y - truth.y).abs() <= params.resolution_m
            && wrap_angle(m.pose.theta - truth.theta).abs() <= 2.0 * angular_step(&params),
        "{m:?}"
    );
}

/// A window far larger than the grid (a localize request's prior of σ = 10⁵ m: 3·10⁶ cells
/// each way, 10¹⁰ roots per angle) is searched as far as an offset puts a return in the
/// grid: the same search whatever the window beyond it, and still the true pose. It ran
/// out of memory before.
#[test]
fn a_window_beyond_the_grid_is_searched_as_far_as_the_grid() {
    let params = coarse();
    let (scene, grids) = park_submap(&params);
    let truth = Pose2::new(-1.0, 1.5, 2.0);
    let scan = scan_at(&scene, &truth, 5);
    let initial = Pose2::new(-0.6, 1.2, 1.95);
    let (lo, hi) = grids.grid().bounds();
    let window = |linear_m| SearchWindow {
        linear_m,
        angular_rad: 0.1,
    };
    // Wide enough to put the scan anywhere in the grid.
    let grid_wide = 2.0 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let m = search(&grids, &scan, initial, &window(grid_wide), 0.5, &params).expect("found");
    assert!(
        (m.pose.x - truth.x).abs() <= params.resolution_m
            && (m.pose.y - truth.y).abs() <= params.resolution_m,
        "{m:?}"
    );
    for linear_m in [1e5, 3e6, f64::MAX, f64::INFINITY] {
        let far = search(&grids, &scan, initial, &window(linear_m), 0.5, &params);
        assert_eq!(far, Some(m), "window {linear_m} m");
        let excluded = Exclusion {
            pose: m.pose,
            radius_m: 1.0,
        };
        let rival = |w| runner_up(&grids, &scan, initial, &w, &excluded, 0.3, &params);
        assert_eq!(rival(window(linear_m)), rival(window(grid_wide)));
    }
}

#[test]
fn nothing_to_match_gives_none() {
    let params = coarse();
    let (_, grids) = park_submap(&params);
    let window = SearchWindow {
        linear_m: 5.0,
        angular_rad: PI,
    };
    // A corridor's scan, searched where the submap has nothing (100 m away) and over it.
    let corridor = Scene::corridor(2.0, 60.0);
    let scan = scan_at(&corridor, &Pose2::IDENTITY, 1);
    let far = Pose2::new(100.0, 0.0, 0.0);
    assert_eq!(search(&grids, &scan, far, &window, 0.05, &params), None);
    let m = search(&grids, &scan, Pose2::IDENTITY, &window, 0.0, &params).expect("some pose");
    assert!(m.score < 0.5, "{m:?}");
    assert_eq!(
        search(&grids, &scan, Pose2::IDENTITY, &window, 0.5, &params),
        None
    );
}

fn around(best: &CorrelativeMatch) -> Exclusion {
    Exclusion {
        pose: best.pose,
        radius_m: 1.0,
    }
}

#[test]
fn a_corridor_has_a_runner_up_and_a_corner_has_none() {
    let params = coarse();
    let window = SearchWindow {
        linear_m: 3.0,
        angular_rad: 10f64.to_radians(),
    };
    let submap = |scene: &Scene| {
        let scan = scan_at(scene, &Pose2::IDENTITY, 3);
        precompute([(Pose2::IDENTITY, &scan)], &params).expect("grid")
    };
    // Along a corridor every shift fits about as well.
    let corridor = Scene::corridor(2.0, 60.0);
    let grids = submap(&corridor);
    let scan = scan_at(&corridor, &Pose2::new(0.5, 0.0, 0.0), 4);
    let initial = Pose2::new(0.3, 0.2, 0.05);
    let best = search(&grids, &scan, initial, &window, 0.5, &params).expect("best");
    let second = runner_up(
        &grids,
        &scan,
        initial,
        &window,
        &around(&best),
        0.0,
        &params,
    )
    .expect("runner-up");
    assert!(second.score > 0.8 * best.score, "{best:?} {second:?}");
    assert!((second.pose.x - best.pose.x).hypot(second.pose.y - best.pose.y) > 1.0);
    // The park pins the pose: the best elsewhere scores far lower.
    let (scene, grids) = park_submap(&params);
    let scan = scan_at(&scene, &Pose2::new(1.0, 0.2, 0.1), 5);
    let best = search(&grids, &scan, initial, &window, 0.5, &params).expect("best");
    let second = runner_up(
        &grids,
        &scan,
        initial,
        &window,
        &around(&best),
        0.0,
        &params,
    )
    .expect("runner-up");
    assert!(second.score < 0.7 * best.score, "{best:?} {second:?}");
}
