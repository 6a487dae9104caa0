//! Leveling on real scans from ../shared/data (see its MANIFEST.md), with the default
//! thresholds. A missing data folder fails these tests: they never skip.

use leveling::{Leveled, Leveler, Precision, SegmentParams};
use scanio::labels::Labels;
use scanio::{LoadedScan, ScanFormat};
use testdata::shared_data as data;

fn level(loaded: &LoadedScan) -> Leveled {
    Leveler::new(SegmentParams::default())
        .level(&loaded.raw, &loaded.track, &loaded.sensor_in_robot)
        .expect("level")
}

/// The four labelled KITTI frames: landmark precision ≥ 0.99 and beam precision ≥ 0.97
/// against Segregator's predicted labels (ground classes 8, 9, 10, 11, 16).
#[test]
fn kitti_landmarks_and_beams_are_not_ground() {
    for (scan, label) in [
        (
            "kitti_velodyne/segregator/000020.bin",
            "kitti_velodyne/segregator/000020.pred.label",
        ),
        (
            "kitti_velodyne/segregator/000030.bin",
            "kitti_velodyne/segregator/000030.pred.label",
        ),
        (
            "kitti_velodyne/segregator/004413.bin",
            "kitti_velodyne/segregator/004413.pred.label",
        ),
        (
            "kitti_velodyne/patchwork-plusplus/000000.bin",
            "kitti_velodyne/segregator/000000.pred.label",
        ),
    ] {
        let loaded = scanio::load(&data(scan), ScanFormat::Kitti).expect("load");
        let labels = Labels::load(&data(label), loaded.file_index.len()).expect("labels");
        let leveled = level(&loaded);
        let p = Precision::score(&leveled.classes, &leveled.first_landmarks, |i| {
            labels.is_ground(loaded.file_index[i] as usize)
        });
        println!(
            "{scan}: landmark {:.4} of {}, beams {:.4} of {}",
            p.landmark_precision(),
            p.landmark_scored,
            p.beam_precision(),
            p.beam_scored
        );
        assert!(
            p.landmark_scored > 10_000 && p.beam_scored > 1_000,
            "{scan}: too few landmarks to judge: {p:?}"
        );
        assert!(p.landmark_precision() >= 0.99, "{scan}: {p:?}");
        assert!(p.beam_precision() >= 0.97, "{scan}: {p:?}");
    }
}

/// A KITTI frame organized into columns keeps every file point, bottom-up in each column.
#[test]
fn kitti_columns_are_bottom_up_and_complete() {
    let loaded = scanio::load(
        &data("kitti_velodyne/patchwork-plusplus/000000.bin"),
        ScanFormat::Kitti,
    )
    .expect("load");
    assert_eq!(loaded.raw.points.len(), 124_668);
    let mut seen = loaded.file_index.clone();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), 124_668);
    for c in 0..loaded.raw.columns.len() {
        let elevations: Vec<f32> = loaded
            .raw
            .column_points(c)
            .iter()
            .map(|p| p.elevation_rad())
            .collect();
        assert!(
            elevations.windows(2).all(|w| w[0] <= w[1]),
            "column {c} not bottom-up"
        );
    }
}

/// 3DTK scan000 (nodding SICK, a corridor between buildings): the leveled beams trace the walls.
/// On the right, beams 3–15 m ahead (past a step in the wall) lie within 10 cm of one line.
#[test]
fn threedtk_beams_trace_the_walls() {
    let loaded = scanio::load(
        &data("rotating_2d_laser_3d_scans_3dtk/scan000.3d"),
        ScanFormat::ThreeDtk,
    )
    .expect("load");
    assert_eq!(
        (loaded.raw.columns.len(), loaded.raw.points.len()),
        (360, 81_360)
    );
    let leveled = level(&loaded);
    let right: Vec<(f32, f32)> = leveled
        .scan
        .returns()
        .map(|(phi, r)| (r * phi.cos(), r * phi.sin()))
        .filter(|&(x, y)| (3.0..15.0).contains(&x) && y < 0.0)
        .collect();
    let (slope, intercept) = fit_line(&right);
    let near = right
        .iter()
        .filter(|&&(x, y)| (y - (slope * x + intercept)).abs() < 0.10)
        .count();
    println!(
        "3dtk: {} beams, {} on the right, {near} within 10 cm of y = {slope:.3} x + {intercept:.3}",
        leveled.scan.return_count(),
        right.len()
    );
    assert!(
        leveled.scan.return_count() > 250,
        "{}",
        leveled.scan.return_count()
    );
    assert!(
        right.len() >= 25 && near as f32 >= 0.9 * right.len() as f32,
        "{near} of {}",
        right.len()
    );
    assert!(slope.abs() < 0.1, "the wall runs along the corridor");
}

/// Least-squares line y = a x + b.
fn fit_line(points: &[(f32, f32)]) -> (f32, f32) {
    let n = points.len() as f32;
    let (sx, sy) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0, b + p.1));
    let (mx, my) = (sx / n, sy / n);
    let (sxx, sxy) = points.iter().fold((0.0, 0.0), |(a, b), p| {
        (a + (p.0 - mx).powi(2), b + (p.0 - mx) * (p.1 - my))
    });
    let slope = sxy / sxx;
    (slope, my - slope * mx)
}
