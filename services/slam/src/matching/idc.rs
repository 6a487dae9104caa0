//! Iterative dual correspondence (Lu & Milios 1997, section 4). Each iteration moves the
//! current scan into the reference frame by the current estimate, then
//! 1. pairs every point with its closest point on the reference polyline and takes the
//!    translation of the least-squares motion of these pairs (point-to-line), and
//! 2. pairs every point with its matching-range point (same range from the reference origin,
//!    within a rotation window) and takes the rotation of those pairs (weighted least
//!    squares about the reference origin);
//!
//! and applies both ("(ω₂, T₁)" in the paper). Pairs further apart than an outlier distance
//! are dropped. The distance and the window shrink geometrically to their floors; the
//! iteration stops when the update is negligible (or alternates between two poses). The
//! closest-point rule pins translation but turns slowly; the range rule turns quickly but
//! is blind to translation. Together they converge in about ten iterations on real scans.

mod pairs;
mod params;

pub use params::IdcParams;

use super::contour::Contour;
use super::validate::validate;
use super::{MatchError, Scan2};
use crate::{Pose2, wrap_angle};
use pairs::{Pairs, correspond};
use serde::{Deserialize, Serialize};

/// The result of matching the current scan against the reference scan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Match {
    /// The current scan's frame in the reference scan's frame (m, rad): a point p of the
    /// current scan is at `pose.transform_point(p)` in the reference frame.
    pub pose: Pose2,
    /// Covariance of (x, y, theta) of `pose` (m², m·rad, rad²). See `validate` for how.
    pub covariance: [[f64; 3]; 3],
    /// What the match is worth, 0 (nothing) to 1: inlier share × (1 − conflict share) × a
    /// factor in [0.5, 1] for conditioning. See `validate` for the heuristic.
    pub quality: f64,
    /// Share of the points of either scan visible to the other (it has a return near their
    /// bearing) that lie within `inlier_distance_m` of the other's polyline.
    pub inlier_share: f64,
    /// Share of points that lie in space the other scan saw free, among those it explains or
    /// contradicts (conflicts / (inliers + conflicts)); the smaller of the two directions.
    pub conflict_share: f64,
    /// Mean distance of the inliers to the other scan's polyline, both ways (m).
    pub mean_residual_m: f64,
    /// Smallest over largest eigenvalue of the information matrix, rotation scaled by the
    /// RMS point range to be unitless: near 0 for a degenerate scene (corridor), up to 1.
    pub conditioning: f64,
    /// Closest-point pairs behind the covariance.
    pub correspondences: usize,
    /// Iterations run.
    pub iterations: u32,
    /// True when the update became negligible before `max_iterations`.
    pub converged: bool,
}

/// Matches `current` against `reference` by IDC, starting from `initial` (the current scan's
/// frame in the reference frame, e.g. from odometry). Fails on bad parameters, a non-finite
/// initial pose, scans with too few returns, or an iteration with too few pairs (the scans
/// do not overlap there); never panics.
pub fn idc(
    reference: &Scan2,
    current: &Scan2,
    initial: Pose2,
    params: &IdcParams,
) -> Result<Match, MatchError> {
    params.check()?;
    if !initial.is_finite() {
        return Err(MatchError::NonFiniteInitial);
    }
    for (scan, name) in [(reference, "reference"), (current, "current")] {
        if scan.len() < params.min_correspondences {
            return Err(MatchError::TooFewPoints {
                scan: name,
                found: scan.len(),
                needed: params.min_correspondences,
            });
        }
    }
    let contour = Contour::new(
        reference,
        params.join_distance_m,
        params.join_distance_per_m,
    );
    let mut pose = initial;
    let mut before = initial; // the pose one iteration back
    let mut converged = false;
    let mut iterations = 0;
    let mut max_distance_m = params.initial_max_distance_m;
    let mut window_rad = params.initial_rotation_window_rad;
    let mut pairs = Pairs::with_capacity(current.len());
    while iterations < params.max_iterations && !converged {
        iterations += 1;
        let at_floor = max_distance_m <= params.final_max_distance_m
            && window_rad <= params.final_rotation_window_rad;
        let stride = if at_floor { 1 } else { params.coarse_stride };
        correspond(
            &contour,
            current,
            &pose,
            max_distance_m,
            window_rad,
            stride,
            &mut pairs,
        );
        let needed = params.min_correspondences.div_ceil(stride);
        for (rule, found) in [
            ("closest-point", pairs.closest.len()),
            ("matching-range", pairs.matching),
        ] {
            if found < needed {
                return Err(MatchError::TooFewCorrespondences {
                    iteration: iterations,
                    rule,
                    found,
                    needed,
                });
            }
        }
        let mut next = pairs.update().compose(&pose);
        let close = |a: &Pose2, b: &Pose2| {
            (a.x - b.x).hypot(a.y - b.y) < params.converged_translation_m
                && wrap_angle(a.theta - b.theta).abs() < params.converged_rotation_rad
        };
        converged = at_floor && close(&next, &pose);
        if at_floor && !converged && iterations > 2 && close(&next, &before) {
            // A pair at the outlier distance flips in and out: the estimate alternates between
            // two poses. Stop at their mean.
            next = Pose2::new(
                (next.x + pose.x) / 2.0,
                (next.y + pose.y) / 2.0,
                wrap_angle(pose.theta + wrap_angle(next.theta - pose.theta) / 2.0),
            );
            converged = true;
        }
        before = pose;
        pose = next;
        max_distance_m = (max_distance_m * params.shrink).max(params.final_max_distance_m);
        window_rad = (window_rad * params.shrink).max(params.final_rotation_window_rad);
    }
    Ok(Match {
        iterations,
        converged,
        ..validate(&contour, current, &pose, params)
    })
}

/// `pose` as a function on points, with its sine and cosine computed once.
pub(super) fn motion(pose: &Pose2) -> impl Fn([f64; 2]) -> [f64; 2] + use<> {
    let (s, c) = pose.theta.sin_cos();
    let (x, y) = (pose.x, pose.y);
    move |p: [f64; 2]| [x + c * p[0] - s * p[1], y + s * p[0] + c * p[1]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::synthetic::{Scene, uneven_bearings, uniform_bearings};
    use crate::matching::{QualityGate, accept};
    use std::f64::consts::PI;

    const MAX_RANGE_M: f32 = 40.0;

    fn scan_at(scene: &Scene, pose: &Pose2, bearings: &[f32], seed: u64) -> Scan2 {
        let ranges = scene.scan(pose, bearings, MAX_RANGE_M, 0.01, seed);
        Scan2::from_polar(bearings, &ranges, MAX_RANGE_M).expect("same lengths")
    }

    /// Error of a match to the true relative pose: (translation m, rotation rad).
    fn error(m: &Match, truth: &Pose2) -> (f64, f64) {
        let e = truth.between(&m.pose);
        (e.x.hypot(e.y), e.theta.abs())
    }

    /// 0.3 m and 5° off the truth, in a direction that depends on `k`.
    fn perturbed(truth: &Pose2, k: usize) -> Pose2 {
        let a = k as f64 * 2.0 * PI / 5.0;
        let sign = if k.is_multiple_of(2) { 1.0 } else { -1.0 };
        Pose2::new(
            truth.x + 0.3 * a.cos(),
            truth.y + 0.3 * a.sin(),
            truth.theta + sign * 5f64.to_radians(),
        )
    }

    fn check_recovers(bearings_ref: &[f32], bearings_cur: &[f32]) {
        let scene = Scene::park();
        let params = IdcParams::default();
        let from = Pose2::new(0.0, 0.0, 0.1);
        let reference = scan_at(&scene, &from, bearings_ref, 1);
        for (k, to) in [
            Pose2::new(1.0, 0.4, 0.25),
            Pose2::new(-0.8, 1.5, -0.2),
            Pose2::new(1.5, -0.5, 0.0),
        ]
        .iter()
        .enumerate()
        {
            let truth = from.between(to);
            let current = scan_at(&scene, to, bearings_cur, 2 + k as u64);
            let m = idc(&reference, &current, perturbed(&truth, k), &params)
                .expect("overlapping scans");
            let (dt, dr) = error(&m, &truth);
            eprintln!(
                "pair {k}: error {:.2} mm, {:.4}°, {} iterations, quality {:.2}",
                dt * 1e3,
                dr.to_degrees(),
                m.iterations,
                m.quality
            );
            assert!(
                m.converged,
                "pair {k}: not converged in {} iterations",
                m.iterations
            );
            assert!(
                dt < 0.01 && dr < 0.1f64.to_radians(),
                "pair {k}: error {dt:.4} m, {:.3}°",
                dr.to_degrees()
            );
            assert!(
                accept(&m, &QualityGate::default()),
                "pair {k}: rejected {m:?}"
            );
        }
    }

    #[test]
    fn recovers_known_motion_from_a_guess_0_3_m_and_5_deg_off() {
        let bearings = uniform_bearings(361, -PI / 2.0, PI / 360.0);
        check_recovers(&bearings, &bearings);
    }

    #[test]
    fn recovers_known_motion_with_uneven_bearings() {
        // Different uneven bearings in both scans: nothing lines up beam by beam.
        let reference = uneven_bearings(360, 1.5 * PI, 0.4, 7, 11);
        let current = uneven_bearings(360, 1.5 * PI, 0.4, 5, 12);
        check_recovers(&reference, &current);
    }

    #[test]
    fn full_circle_scans_match_across_the_bearing_seam() {
        // 360° scans; the motion turns the scan by 179°, so points cross ±π.
        let scene = Scene::park();
        let bearings = uniform_bearings(360, -PI, PI / 180.0);
        let from = Pose2::new(0.0, 0.0, 0.0);
        let to = Pose2::new(0.5, -0.3, 179f64.to_radians());
        let truth = from.between(&to);
        let reference = scan_at(&scene, &from, &bearings, 3);
        let current = scan_at(&scene, &to, &bearings, 4);
        let m = idc(
            &reference,
            &current,
            perturbed(&truth, 1),
            &IdcParams::default(),
        )
        .expect("overlap");
        let (dt, dr) = error(&m, &truth);
        eprintln!(
            "full circle: error {:.2} mm, {:.4}°",
            dt * 1e3,
            dr.to_degrees()
        );
        assert!(
            dt < 0.01 && dr < 0.1f64.to_radians(),
            "error {dt:.4} m, {:.3}°",
            dr.to_degrees()
        );
    }

    #[test]
    fn corridor_covariance_is_stretched_along_the_corridor() {
        let scene = Scene::corridor(4.0, 200.0);
        let bearings = uniform_bearings(361, -PI / 2.0, PI / 360.0);
        let from = Pose2::IDENTITY;
        let to = Pose2::new(0.6, 0.2, 0.05);
        let truth = from.between(&to);
        let ranges_ref = scene.scan(&from, &bearings, 12.0, 0.01, 5);
        let ranges_cur = scene.scan(&to, &bearings, 12.0, 0.01, 6);
        let reference = Scan2::from_polar(&bearings, &ranges_ref, 12.0).expect("same lengths");
        let current = Scan2::from_polar(&bearings, &ranges_cur, 12.0).expect("same lengths");
        let m = idc(
            &reference,
            &current,
            perturbed(&truth, 0),
            &IdcParams::default(),
        )
        .expect("overlap");
        let c = m.covariance;
        // Across the corridor (y of the reference frame) and in heading the match is sharp ...
        let (across, turn) = (m.pose.y - truth.y, m.pose.theta - truth.theta);
        assert!(
            across.abs() < 0.01 && turn.abs() < 0.1f64.to_radians(),
            "across {across:.4} m, {turn:.5} rad"
        );
        // ... along it (x of the reference frame) the covariance is stretched: its major axis
        // is the corridor's, and much longer than the minor one. (It is not infinite: the
        // surface normals, estimated from noisy returns, tilt a little.)
        let (xx, xy, yy) = (c[0][0], c[0][1], c[1][1]);
        let axis = 0.5 * (2.0 * xy).atan2(xx - yy);
        let root = ((xx - yy).powi(2) / 4.0 + xy * xy).sqrt();
        let (major, minor) = ((xx + yy) / 2.0 + root, (xx + yy) / 2.0 - root);
        eprintln!(
            "corridor: std {:.4} m along, {:.4} m across, axis at {:.2}°, conditioning {:.1e}",
            major.sqrt(),
            minor.sqrt(),
            axis.to_degrees(),
            m.conditioning
        );
        assert!(
            axis.abs() < 2f64.to_radians(),
            "major axis at {:.2}°",
            axis.to_degrees()
        );
        assert!(
            major > 400.0 * minor,
            "std {:.4} m along, {:.4} m across",
            major.sqrt(),
            minor.sqrt()
        );
        assert!(m.conditioning < 1e-3, "conditioning {}", m.conditioning);
    }

    #[test]
    fn scans_of_different_places_are_rejected() {
        let park = Scene::park();
        // The same kind of scene, turned half a circle and shifted: another place.
        let other = Scene {
            walls: park
                .walls
                .iter()
                .map(|[a, b]| [[-a[0] + 3.0, -a[1]], [-b[0] + 3.0, -b[1]]])
                .collect(),
            trunks: park
                .trunks
                .iter()
                .map(|&(c, r)| ([c[1] - 2.0, c[0]], r))
                .collect(),
        };
        let bearings = uniform_bearings(361, -PI / 2.0, PI / 360.0);
        let reference = scan_at(&park, &Pose2::IDENTITY, &bearings, 1);
        let current = scan_at(&other, &Pose2::IDENTITY, &bearings, 2);
        let gate = QualityGate::default();
        for k in 0..5 {
            let guess = perturbed(&Pose2::new(0.5, 0.0, 0.0), k);
            match idc(&reference, &current, guess, &IdcParams::default()) {
                Ok(m) => {
                    eprintln!(
                        "wrong pairing, guess {k}: quality {:.2}, conflicts {:.2}, residual {:.3} m",
                        m.quality, m.conflict_share, m.mean_residual_m
                    );
                    assert!(!accept(&m, &gate), "guess {k}: accepted {m:?}");
                }
                Err(e) => assert!(matches!(e, MatchError::TooFewCorrespondences { .. }), "{e}"),
            }
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let scene = Scene::park();
        let bearings = uniform_bearings(181, -PI / 2.0, PI / 180.0);
        let scan = scan_at(&scene, &Pose2::IDENTITY, &bearings, 1);
        let params = IdcParams::default();
        let nan = Pose2::new(f64::NAN, 0.0, 0.0);
        assert_eq!(
            idc(&scan, &scan, nan, &params).unwrap_err(),
            MatchError::NonFiniteInitial
        );
        let few = Scan2::from_polar(&bearings[..5], &[1.0; 5], 10.0).expect("same lengths");
        assert!(matches!(
            idc(&scan, &few, Pose2::IDENTITY, &params),
            Err(MatchError::TooFewPoints { .. })
        ));
        let empty = Scan2::default();
        assert!(matches!(
            idc(&empty, &scan, Pose2::IDENTITY, &params),
            Err(MatchError::TooFewPoints { .. })
        ));
        let bad = IdcParams {
            shrink: f64::NAN,
            ..IdcParams::default()
        };
        assert!(matches!(
            idc(&scan, &scan, Pose2::IDENTITY, &bad),
            Err(MatchError::InvalidParams(_))
        ));
        // Far off: nothing within the outlier distance.
        let far = Pose2::new(500.0, 0.0, 0.0);
        assert!(matches!(
            idc(&scan, &scan, far, &params),
            Err(MatchError::TooFewCorrespondences { .. })
        ));
    }

    #[test]
    fn identical_scans_match_at_identity_with_full_quality() {
        let scene = Scene::park();
        let bearings = uniform_bearings(361, -PI / 2.0, PI / 360.0);
        let scan = scan_at(&scene, &Pose2::IDENTITY, &bearings, 1);
        let m = idc(
            &scan,
            &scan,
            Pose2::new(0.0, 0.0, 0.0),
            &IdcParams::default(),
        )
        .expect("overlap");
        let (dt, dr) = error(&m, &Pose2::IDENTITY);
        assert!(dt < 1e-3 && dr < 1e-4, "error {dt} m {dr} rad");
        assert!(
            m.quality > 0.9 && m.inlier_share > 0.95 && m.conflict_share == 0.0,
            "{m:?}"
        );
    }
}
