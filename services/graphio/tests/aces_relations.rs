//! The ACES relations (Kümmerle et al. 2009) against the ACES log: every relation's
//! timestamps are FLASER timestamps of the log, and the relation metric of the raw odometry.

use graphio::{carmen, relations};
use slam::Pose2;
use slam::matching::metric::relation_metric;
use testdata::shared_data;

#[test]
fn aces_relations_refer_to_flaser_scans() {
    let rel = relations::read(&shared_data("radish_2d_laser_logs/aces.relations"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rel.len(), 1279);
    let log = carmen::read(&shared_data("radish_2d_laser_logs/aces.clf.bz2"))
        .unwrap_or_else(|e| panic!("{e}"));
    let mut stamps: Vec<(f64, Pose2)> = log
        .scans
        .iter()
        .map(|s| (s.stamp_s, s.laser_pose))
        .collect();
    stamps.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Both files print the stamps with 6 decimals, so the parsed values are equal exactly.
    let pose_at = |t: &f64| {
        let i = stamps.partition_point(|(s, _)| s < t);
        stamps.get(i).filter(|(s, _)| s == t).map(|&(_, pose)| pose)
    };
    for (k, r) in rel.iter().enumerate() {
        assert!(
            pose_at(&r.t1_s).is_some() && pose_at(&r.t2_s).is_some(),
            "relation {k}: {r:?} has no scan"
        );
    }
    // The raw odometry, scored: the metric runs on real data. Odometry drifts, so it scores far
    // worse than the published SLAM results (0.04–0.17 m mean).
    let m = relation_metric(rel.iter().map(|r| (r.t1_s, r.t2_s, r.delta)), pose_at)
        .expect("all stamps found");
    eprintln!(
        "ACES raw odometry: {} relations, translation {:.3} ± {:.3} m (max {:.3}), rotation {:.4} ± {:.4} rad (max {:.3})",
        m.count,
        m.translation_mean_m,
        m.translation_std_m,
        m.translation_max_m,
        m.rotation_mean_rad,
        m.rotation_std_rad,
        m.rotation_max_rad
    );
    assert_eq!(m.count, 1279);
    assert!(m.translation_mean_m.is_finite() && m.translation_mean_m > 0.0);
}
