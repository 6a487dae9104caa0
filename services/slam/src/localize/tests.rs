use super::*;
use crate::matching::synthetic::{Scene, uniform_bearings};

const MAX_RANGE: f32 = 30.0;

fn scan_at(scene: &Scene, pose: &Pose2, seed: u64) -> Scan2 {
    let bearings = uniform_bearings(720, -std::f64::consts::PI, std::f64::consts::TAU / 720.0);
    let ranges = scene.scan(pose, &bearings, MAX_RANGE, 0.01, seed);
    Scan2::from_polar(&bearings, &ranges, MAX_RANGE).unwrap()
}

/// The synthetic park's free middle: a map scan every metre on a 7 m × 3 m patch
/// around the origin, headings varied.
fn map_poses() -> Vec<Pose2> {
    let mut poses = Vec::new();
    for i in -3..=3 {
        for j in -1..=1 {
            let theta = 0.4 * f64::from(i) - 0.7 * f64::from(j);
            poses.push(Pose2::new(f64::from(i), f64::from(j), theta));
        }
    }
    poses
}

/// Small tiles, so that the map has several and searches cross their borders.
fn params() -> LocalizeParams {
    LocalizeParams {
        tile_m: 4.0,
        ..LocalizeParams::default()
    }
}

fn park_map(params: LocalizeParams) -> (Scene, LocalizationMap) {
    let scene = Scene::park();
    let scans = map_poses()
        .into_iter()
        .enumerate()
        .map(|(k, pose)| (pose, scan_at(&scene, &pose, k as u64)))
        .collect();
    (scene, LocalizationMap::new(scans, params).unwrap())
}

/// Places between the map's scans, at headings none of them had.
fn query_poses() -> Vec<Pose2> {
    vec![
        Pose2::new(0.37, 0.42, 2.9),
        Pose2::new(-2.2, -0.6, -1.3),
        Pose2::new(2.6, 0.9, 0.25),
        Pose2::new(-0.8, 1.3, -2.6),
        Pose2::new(1.4, -1.2, 1.7),
    ]
}

fn error(a: &Pose2, b: &Pose2) -> (f64, f64) {
    (
        (a.x - b.x).hypot(a.y - b.y),
        wrap_angle(a.theta - b.theta).abs(),
    )
}

#[test]
fn a_scan_is_found_from_a_prior_within_its_window() {
    let (scene, map) = park_map(params());
    assert!(map.tile_count() > 1, "{} tiles", map.tile_count());
    for (k, truth) in query_poses().iter().enumerate() {
        let scan = scan_at(&scene, truth, 100 + k as u64);
        let prior = Prior {
            pose: Pose2::new(truth.x + 0.7, truth.y - 0.5, truth.theta + 0.12),
            linear_m: 1.0,
            angular_rad: 0.2,
        };
        let found = map.localize(&scan, Some(&prior)).unwrap();
        let (d, turn) = error(&found.pose, truth);
        assert!(
            d < 0.03 && turn < 0.01,
            "{truth:?}: off by {d:.3} m, {turn:.4} rad"
        );
        assert_eq!(found.search, SearchKind::Window);
        assert!(found.score >= map.params().min_score);
        // The covariance is a covariance: symmetric, positive on its diagonal.
        let c = found.covariance;
        assert!((0..3).all(|i| c[i][i] > 0.0 && (0..3).all(|j| (c[i][j] - c[j][i]).abs() < 1e-12)));
    }
}

#[test]
fn without_a_prior_the_global_search_finds_the_scan_at_any_heading() {
    let (scene, map) = park_map(params());
    for (k, truth) in query_poses().iter().enumerate() {
        let scan = scan_at(&scene, truth, 200 + k as u64);
        let found = map.localize(&scan, None).unwrap();
        let (d, turn) = error(&found.pose, truth);
        assert!(
            d < 0.03 && turn < 0.01,
            "{truth:?}: off by {d:.3} m, {turn:.4} rad"
        );
        assert_eq!(found.search, SearchKind::Global);
    }
}

#[test]
fn a_prior_far_off_finds_nothing_in_its_window_and_relocalizing_searches_everywhere() {
    let (scene, map) = park_map(params());
    let truth = Pose2::new(0.37, 0.42, 2.9);
    let scan = scan_at(&scene, &truth, 300);
    // 3 m off with a window of 0.5 m: the true pose is outside it.
    let wrong = Prior {
        pose: Pose2::new(truth.x - 3.0, truth.y, truth.theta),
        linear_m: 0.5,
        angular_rad: 0.1,
    };
    assert!(matches!(
        map.localize(&scan, Some(&wrong)),
        Err(LocalizeError::NotFound { .. })
    ));
    let found = map.relocalize(&scan, Some(&wrong)).unwrap();
    assert_eq!(found.search, SearchKind::Global);
    assert!(error(&found.pose, &truth).0 < 0.03);
}

#[test]
fn a_place_the_map_never_saw_is_not_found() {
    let (_, map) = park_map(params());
    // A different scene: a long corridor has nothing of the park.
    let corridor = Scene::corridor(3.0, 60.0);
    let scan = scan_at(&corridor, &Pose2::new(0.0, 0.0, 0.0), 400);
    let err = map.localize(&scan, None).unwrap_err();
    assert!(
        matches!(
            err,
            LocalizeError::NotFound { .. } | LocalizeError::Ambiguous { .. }
        ),
        "{err}"
    );
}

#[test]
fn a_symmetric_scene_is_ambiguous_to_the_global_search() {
    // Two identical squares of posts 20 m apart: a scan in one fits the other as well.
    let mut trunks = Vec::new();
    for cx in [-10.0, 10.0] {
        for (dx, dy) in [(-2.0, -1.5), (2.5, -1.0), (1.5, 2.0), (-1.0, 2.5)] {
            trunks.push(([cx + dx, dy], 0.2));
        }
    }
    let scene = Scene {
        walls: Vec::new(),
        trunks,
    };
    let short = LocalizeParams {
        grid: CorrelativeParams {
            max_range_m: 6.0,
            ..LocalizeParams::default().grid
        },
        ..params()
    };
    let scans = [-10.0, 10.0]
        .iter()
        .map(|&x| {
            let pose = Pose2::new(x, 0.0, 0.0);
            (pose, scan_at(&scene, &pose, 1))
        })
        .collect();
    let map = LocalizationMap::new(scans, short).unwrap();
    let scan = scan_at(&scene, &Pose2::new(-10.2, 0.1, 0.3), 2);
    let err = map.localize(&scan, None).unwrap_err();
    assert!(matches!(err, LocalizeError::Ambiguous { .. }), "{err}");
}

#[test]
fn a_map_without_returns_or_with_bad_parameters_is_refused() {
    assert_eq!(
        LocalizationMap::new(Vec::new(), params()).unwrap_err(),
        LocalizeError::EmptyMap
    );
    let bad = LocalizeParams {
        tile_m: 0.0,
        ..params()
    };
    let err = LocalizationMap::new(Vec::new(), bad).unwrap_err();
    assert!(matches!(err, LocalizeError::InvalidParams(_)), "{err}");
}

#[test]
fn the_tracker_follows_odometry_from_fix_to_fix_and_searches_again_when_lost() {
    let (scene, map) = park_map(params());
    let track = TrackParams::default();
    let mut tracker = Tracker::new();
    // A drive across the patch; odometry has its own frame (turned and shifted) and drifts.
    let odom_frame = Pose2::new(5.0, -3.0, 1.0);
    let path: Vec<Pose2> = (0..12)
        .map(|k| {
            Pose2::new(
                -2.5 + 0.45 * k as f64,
                0.3 * (k as f64 * 0.5).sin(),
                0.1 * k as f64,
            )
        })
        .collect();
    for (k, truth) in path.iter().enumerate() {
        let drift = Pose2::new(0.02 * k as f64, -0.01 * k as f64, 0.004 * k as f64);
        let odometry = odom_frame.compose(truth).compose(&drift);
        let step = tracker.step(
            &map,
            &track,
            odometry,
            &scan_at(&scene, truth, 500 + k as u64),
        );
        assert_eq!(
            step.status,
            TrackStatus::Localized,
            "node {k}: {:?}",
            step.error
        );
        let (d, _) = error(&step.pose.unwrap(), truth);
        assert!(d < 0.03, "node {k}: off by {d:.3} m");
        let expected = if k == 0 {
            SearchKind::Global
        } else {
            SearchKind::Window
        };
        assert_eq!(step.found.unwrap().search, expected, "node {k}");
    }
    // Kidnapped: a scan of nowhere leaves it dead reckoning, then lost; a scan of the map
    // finds it again by the global search.
    let corridor = Scene::corridor(3.0, 60.0);
    let here = odom_frame.compose(&path[11]);
    let nowhere = scan_at(&corridor, &Pose2::IDENTITY, 600);
    let step = tracker.step(&map, &track, here, &nowhere);
    assert_eq!(step.status, TrackStatus::DeadReckoned);
    let far = here.compose(&Pose2::new(track.lost_after_m + 1.0, 0.0, 0.0));
    let step = tracker.step(&map, &track, far, &nowhere);
    assert_eq!(step.status, TrackStatus::Lost);
    assert_eq!(step.pose, None);
    let truth = Pose2::new(0.37, 0.42, 2.9);
    let step = tracker.step(&map, &track, far, &scan_at(&scene, &truth, 601));
    assert_eq!(step.status, TrackStatus::Localized);
    assert_eq!(step.found.as_ref().unwrap().search, SearchKind::Global);
    assert!(error(&step.pose.unwrap(), &truth).0 < 0.03);
}

#[test]
fn a_wrong_prior_along_a_wall_is_not_trusted_when_relocalizing() {
    // A long corridor with one post: the walls fit any shift along them.
    let mut scene = Scene::corridor(4.0, 80.0);
    scene.trunks.push(([10.0, 1.2], 0.15));
    let scans = (-20..=20)
        .step_by(2)
        .map(|x| {
            let pose = Pose2::new(f64::from(x), 0.0, 0.0);
            (pose, scan_at(&scene, &pose, (x + 50) as u64))
        })
        .collect();
    let map = LocalizationMap::new(scans, LocalizeParams::default()).unwrap();
    let truth = Pose2::new(10.3, -0.2, 0.05);
    let scan = scan_at(&scene, &truth, 7);
    // 8 m off along the corridor, with a window of 1.5 m: the walls fit there.
    let wrong = Prior {
        pose: Pose2::new(2.3, -0.2, 0.05),
        linear_m: 1.5,
        angular_rad: 0.2,
    };
    let trusted = map.localize(&scan, Some(&wrong)).unwrap();
    assert!(
        error(&trusted.pose, &truth).0 > 5.0,
        "the window alone is fooled"
    );
    match map.relocalize(&scan, Some(&wrong)) {
        Ok(found) => {
            assert!(error(&found.pose, &truth).0 < 0.05, "{found:?}");
            assert_eq!(found.search, SearchKind::Global);
        }
        Err(e) => assert!(matches!(e, LocalizeError::Ambiguous { .. }), "{e}"),
    }
}
