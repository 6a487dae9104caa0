//! The leveling pipeline on simulated scans with ground truth: what the paper claims of
//! leveled range scans must hold in the park.

use leveling::deskew::leveled_xyz;
use leveling::{Leveled, Leveler, PointClass, PoseTrack, SegmentParams, leveled_frame};
use nalgebra::{Point2, Point3};
use sim::scenario::{SCAN_START_NS, pavilion_hill_robot_pose, wall_drive_route};
use sim::{Shape, SimScanFile, SurfaceKind, World, demo_scan, pavilion_hill_scan, wall_drive_scan};
use std::collections::BTreeMap;

fn level(file: &SimScanFile, track: &PoseTrack) -> Leveled {
    Leveler::new(SegmentParams::default())
        .level(&file.raw, track, &file.sensor_in_robot)
        .expect("the odometry covers the scan")
}

fn deskewed(file: &SimScanFile) -> Leveled {
    level(
        file,
        &PoseTrack::new(file.odometry.clone()).expect("ordered odometry"),
    )
}

/// Per beam with a return: the ground truth of its source point and its leveled (x, y).
fn beams_with_truth(file: &SimScanFile, leveled: &Leveled) -> Vec<(SurfaceKind, Point2<f64>)> {
    leveled
        .first_landmarks
        .iter()
        .zip(&leveled.cloud.columns)
        .filter_map(|(first, column)| {
            let index = (*first)? as usize;
            let kind = file.truth[index].expect("a landmark point is a return");
            let p = leveled_xyz(&leveled.cloud.points[index], column.origin_xy_m);
            Some((kind, Point2::new(p.x as f64, p.y as f64)))
        })
        .collect()
}

fn histogram(beams: &[(SurfaceKind, Point2<f64>)]) -> BTreeMap<SurfaceKind, usize> {
    let mut h = BTreeMap::new();
    for (kind, _) in beams {
        *h.entry(*kind).or_insert(0) += 1;
    }
    h
}

/// Largest distance (m) of the points from their total-least-squares line.
fn line_residual(points: &[Point2<f64>]) -> f64 {
    let n = points.len() as f64;
    let mean = points
        .iter()
        .fold(nalgebra::Vector2::zeros(), |s, p| s + p.coords)
        / n;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in points {
        let d = p.coords - mean;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
    }
    // The normal is the direction of least spread.
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy) + std::f64::consts::FRAC_PI_2;
    let normal = nalgebra::Vector2::new(angle.cos(), angle.sin());
    points
        .iter()
        .map(|p| (p.coords - mean).dot(&normal).abs())
        .fold(0.0, f64::max)
}

#[test]
fn the_pavilion_on_the_hill_is_seen_and_the_hill_is_not() {
    let (file, beams_2d) = pavilion_hill_scan(7);
    let leveled = deskewed(&file);
    let beams = beams_with_truth(&file, &leveled);
    let h = histogram(&beams);
    println!("pavilion scan: beams per source {h:?}");
    let pillars = h.get(&SurfaceKind::PavilionPillar).copied().unwrap_or(0);
    let ground: usize = h
        .iter()
        .filter(|(k, _)| k.is_ground())
        .map(|(_, n)| n)
        .sum();
    assert!(
        pillars >= 5,
        "only {pillars} beams from the pavilion's pillars"
    );
    assert_eq!(ground, 0, "beams from the ground: {h:?}");

    // The pillar beams lie on real pillars: leveled frame → world with the true pose.
    let world = World::park();
    let robot = pavilion_hill_robot_pose(&world);
    let to_world = leveled_frame(&robot, &file.sensor_in_robot).inverse();
    let pillars_xy: Vec<(Point2<f64>, f64)> = world
        .parts()
        .iter()
        .filter_map(|p| match (p.kind, p.shape) {
            (SurfaceKind::PavilionPillar, Shape::Cylinder(c)) => {
                Some((Point2::from(c.center_xy_m), c.radius_m))
            }
            _ => None,
        })
        .collect();
    for (kind, p) in &beams {
        if *kind == SurfaceKind::PavilionPillar {
            let w = to_world * Point3::new(p.x, p.y, 0.0);
            let off = pillars_xy
                .iter()
                .map(|(c, r)| ((w.xy() - c).norm() - r).abs())
                .fold(f64::INFINITY, f64::min);
            assert!(
                off < 0.1,
                "pillar beam {off:.3} m off the nearest pillar's surface"
            );
        }
    }

    // The fixed 2D scanner, looking the same way, sees only the hill's slope.
    let to_pavilion = robot.inverse() * world.pavilion_center();
    let bearing = to_pavilion.y.atan2(to_pavilion.x);
    let towards: Vec<_> = beams_2d
        .iter()
        .filter(|b| (b.bearing_rad - bearing).abs() < 20f64.to_radians())
        .collect();
    assert!(towards.len() > 70);
    for b in &towards {
        assert_eq!(
            b.kind,
            Some(SurfaceKind::Terrain),
            "2D beam at {:.1}°",
            b.bearing_rad.to_degrees()
        );
    }
    let pavilion_2d = beams_2d
        .iter()
        .filter(|b| {
            matches!(
                b.kind,
                Some(SurfaceKind::PavilionPillar | SurfaceKind::PavilionRoof)
            )
        })
        .count();
    assert_eq!(pavilion_2d, 0);
    let farthest = towards.iter().filter_map(|b| b.range_m).fold(0.0, f64::max);
    println!(
        "2D scanner towards the pavilion: {} beams, all terrain, farthest {farthest:.1} m",
        towards.len()
    );
}

#[test]
fn motion_compensation_straightens_the_wall() {
    let file = wall_drive_scan(5, 1.4);
    let compensated = deskewed(&file);
    let start_odometry = file.odometry[0].pose;
    let uncompensated = level(&file, &PoseTrack::stationary(start_odometry));

    let wall_points = |leveled: &Leveled| -> Vec<Point2<f64>> {
        beams_with_truth(&file, leveled)
            .into_iter()
            .filter(|(kind, _)| *kind == SurfaceKind::Wall)
            .map(|(_, p)| p)
            .collect()
    };
    let (with, without) = (wall_points(&compensated), wall_points(&uncompensated));
    assert!(
        with.len() >= 20 && without.len() >= 20,
        "{} / {} wall beams",
        with.len(),
        without.len()
    );
    let (r_with, r_without) = (line_residual(&with), line_residual(&without));
    println!(
        "wall at 1.4 m/s: {} beams, max line residual {r_with:.4} m with deskew, {r_without:.3} m without ({} beams)",
        with.len(),
        without.len()
    );
    assert!(r_with <= 0.05, "deskewed wall is not straight: {r_with} m");
    assert!(
        r_without > 0.25,
        "uncompensated wall should be bent: {r_without} m"
    );

    // And the deskewed wall is where the wall really is.
    let world = World::park();
    let wall = world.places().test_wall;
    let robot = wall_drive_route(&world, 1.4).pose_at(&world, SCAN_START_NS);
    let to_world = leveled_frame(&robot, &file.sensor_in_robot).inverse();
    for p in &with {
        let w = to_world * Point3::new(p.x, p.y, 0.0);
        let d = wall.signed_distance_m(&w.xy()).abs();
        assert!(
            (d - 0.5 * wall.thickness_m).abs() < 0.08,
            "{d} m from the centre line"
        );
    }
}

#[test]
fn the_same_seed_gives_the_same_scan() {
    let (a, a2d) = pavilion_hill_scan(11);
    let (b, b2d) = pavilion_hill_scan(11);
    assert_eq!(a, b);
    assert_eq!(a2d, b2d);
    assert_ne!(a.raw, pavilion_hill_scan(12).0.raw);
}

#[test]
fn landmarks_in_the_demo_scan_are_not_ground() {
    let file = demo_scan(1);
    let leveled = deskewed(&file);
    let mut landmarks = 0usize;
    let mut ground = 0usize;
    let mut by_kind: BTreeMap<SurfaceKind, usize> = BTreeMap::new();
    for (class, truth) in leveled.classes.iter().zip(&file.truth) {
        if *class == PointClass::Landmark {
            landmarks += 1;
            let kind = truth.expect("a landmark point is a return");
            *by_kind.entry(kind).or_insert(0) += 1;
            ground += kind.is_ground() as usize;
        }
    }
    let share = 1.0 - ground as f64 / landmarks as f64;
    println!("demo scan: {landmarks} landmark points, {share:.4} not ground; {by_kind:?}");
    println!("demo scan classes: {:?}", leveled.counts);
    println!(
        "demo beams: {:?}",
        histogram(&beams_with_truth(&file, &leveled))
    );
    assert!(landmarks > 150, "{landmarks} landmark points");
    assert!(
        share >= 0.99,
        "only {share} of landmark points are not ground: {by_kind:?}"
    );
    // Pavilion, trees and the bridge's railing are all in view.
    for kind in [
        SurfaceKind::PavilionPillar,
        SurfaceKind::TreeTrunk,
        SurfaceKind::Railing,
    ] {
        assert!(
            by_kind.get(&kind).copied().unwrap_or(0) > 0,
            "no {kind:?} in view"
        );
    }
}
