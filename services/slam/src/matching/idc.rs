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

use super::contour::Contour;
use super::validate::validate;
use super::{MatchError, Scan2};
use crate::{Pose2, wrap_angle};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Every tunable of IDC and of the validation of its result, with its unit and default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct IdcParams {
    /// Outlier distance of the first iteration (m): a pair further apart is dropped. Covers
    /// the error of the initial guess. Default 1.0.
    pub initial_max_distance_m: f64,
    /// Floor of the outlier distance (m), reached after a few iterations. Default 0.2.
    pub final_max_distance_m: f64,
    /// Rotation window B_r of the matching-range rule at the first iteration (rad): covers
    /// the rotation error of the initial guess. Default 0.15 (8.6°).
    pub initial_rotation_window_rad: f64,
    /// Floor of the rotation window (rad). Default 0.03 (1.7°).
    pub final_rotation_window_rad: f64,
    /// Factor applied to the outlier distance and the window after every iteration
    /// (0 < shrink ≤ 1). Default 0.7.
    pub shrink: f64,
    /// Until the schedules reach their floors, only every `coarse_stride`-th point of the
    /// current scan is paired, for speed. It narrows the basin of convergence: with 2 or 3,
    /// the 2D mapper on ACES found 45 % fewer loop closures (their initial guesses are
    /// far off). Default 1: every point throughout.
    pub coarse_stride: usize,
    /// Iterations at most. Default 50.
    pub max_iterations: u32,
    /// Converged when, with both schedules at their floors, one update moves the pose by
    /// less than this (m) ... Default 1e-3.
    pub converged_translation_m: f64,
    /// ... and turns it by less than this (rad). Default 1e-4.
    pub converged_rotation_rad: f64,
    /// Fewest returns per scan, and fewest pairs per rule and iteration (divided by the
    /// stride in coarse iterations). Default 20.
    pub min_correspondences: usize,
    /// Neighbouring reference returns lie on one surface (and are interpolated between)
    /// when at most `join_distance_m + join_distance_per_m · range` apart (m). Default 0.3.
    pub join_distance_m: f64,
    /// See `join_distance_m` (m per m of range). Default 0.05.
    pub join_distance_per_m: f64,
    /// Validation: a point within this distance of the reference polyline at the final pose
    /// is an inlier (m). Default 0.1.
    pub inlier_distance_m: f64,
    /// Validation: a point is visible to the reference when the reference has a return
    /// within this bearing of it (rad, seen from the reference origin). Default 0.02 (1.1°).
    pub visibility_window_rad: f64,
    /// Validation: a visible point nearer to the reference origin than every reference
    /// return around its bearing by more than this lies in space the reference saw free:
    /// a conflict (m). Default 0.5.
    pub conflict_margin_m: f64,
    /// Validation: conditioning (smallest / largest eigenvalue of the scaled information)
    /// from which a match counts as fully constrained; below it quality is reduced, to at
    /// most half for a degenerate scene. Default 0.02.
    pub conditioning_ok: f64,
    /// Covariance: the residual standard deviation is taken as at least this (m), so that
    /// noise-free scans do not claim a perfect pose. Default 0.01.
    pub range_noise_m: f64,
    /// Covariance: standard deviation reported along a direction the scans do not
    /// constrain, as in a corridor (m). Default 1.0.
    pub unobservable_std_m: f64,
    /// Covariance: the same for rotation (rad). Default 0.2.
    pub unobservable_std_rad: f64,
}

impl Default for IdcParams {
    fn default() -> IdcParams {
        IdcParams {
            initial_max_distance_m: 1.0,
            final_max_distance_m: 0.2,
            initial_rotation_window_rad: 0.15,
            final_rotation_window_rad: 0.03,
            shrink: 0.7,
            coarse_stride: 1,
            max_iterations: 50,
            converged_translation_m: 1e-3,
            converged_rotation_rad: 1e-4,
            min_correspondences: 20,
            join_distance_m: 0.3,
            join_distance_per_m: 0.05,
            inlier_distance_m: 0.1,
            visibility_window_rad: 0.02,
            conflict_margin_m: 0.5,
            conditioning_ok: 0.02,
            range_noise_m: 0.01,
            unobservable_std_m: 1.0,
            unobservable_std_rad: 0.2,
        }
    }
}

impl IdcParams {
    /// Checks every parameter against its range.
    pub fn check(&self) -> Result<(), MatchError> {
        let positive = [
            ("initial_max_distance_m", self.initial_max_distance_m),
            ("final_max_distance_m", self.final_max_distance_m),
            (
                "initial_rotation_window_rad",
                self.initial_rotation_window_rad,
            ),
            ("final_rotation_window_rad", self.final_rotation_window_rad),
            ("shrink", self.shrink),
            ("converged_translation_m", self.converged_translation_m),
            ("converged_rotation_rad", self.converged_rotation_rad),
            ("inlier_distance_m", self.inlier_distance_m),
            ("visibility_window_rad", self.visibility_window_rad),
            ("conditioning_ok", self.conditioning_ok),
            ("range_noise_m", self.range_noise_m),
            ("unobservable_std_m", self.unobservable_std_m),
            ("unobservable_std_rad", self.unobservable_std_rad),
        ];
        let non_negative = [
            ("join_distance_m", self.join_distance_m),
            ("join_distance_per_m", self.join_distance_per_m),
            ("conflict_margin_m", self.conflict_margin_m),
        ];
        let bad = |name: &str, value: f64| MatchError::InvalidParams(format!("{name} = {value}"));
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(bad(name, value));
            }
        }
        for (name, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(bad(name, value));
            }
        }
        if self.shrink > 1.0 {
            return Err(bad("shrink", self.shrink));
        }
        if self.initial_max_distance_m < self.final_max_distance_m {
            return Err(bad("initial_max_distance_m", self.initial_max_distance_m));
        }
        if self.initial_rotation_window_rad < self.final_rotation_window_rad {
            return Err(bad(
                "initial_rotation_window_rad",
                self.initial_rotation_window_rad,
            ));
        }
        if self.coarse_stride == 0 {
            return Err(MatchError::InvalidParams("coarse_stride = 0".into()));
        }
        if self.max_iterations == 0 {
            return Err(MatchError::InvalidParams("max_iterations = 0".into()));
        }
        if self.min_correspondences < 3 {
            return Err(MatchError::InvalidParams(format!(
                "min_correspondences = {} (3 at least: a pose has 3 unknowns)",
                self.min_correspondences
            )));
        }
        Ok(())
    }
}

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
    let mut pairs = Pairs {
        closest: Vec::with_capacity(current.len()),
        ..Pairs::default()
    };
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

/// A closest-point pair (reference frame, m).
struct ClosestPair {
    /// The point of the current scan.
    point: [f64; 2],
    /// Its closest point on the reference polyline.
    target: [f64; 2],
    /// The reference surface normal there; `None` at an isolated return.
    normal: Option<[f64; 2]>,
}

/// One iteration's pairs (points in the reference frame).
#[derive(Default)]
struct Pairs {
    closest: Vec<ClosestPair>,
    /// Number of matching-range pairs, with Σ w·sin δ and Σ w·cos δ over them (δ: bearing
    /// offset from the point to its match, w: the pair's rotation information).
    matching: usize,
    cross: f64,
    dot: f64,
}

impl Pairs {
    /// The update, as a motion applied in the reference frame, `q ↦ R(ω)·q + T`: the rotation
    /// ω of the matching-range pairs and the translation T of the closest-point pairs, each
    /// from the least-squares solution of its own pairs (Lu & Milios, section 4: "(ω₂, T₁)").
    fn update(&self) -> Pose2 {
        let t = self.closest_point_solution();
        Pose2::new(t.x, t.y, self.matching_range_rotation())
    }

    /// The matching-range pairs have equal ranges, so they differ by a rotation about the
    /// reference origin; this is its weighted least-squares angle (rad).
    fn matching_range_rotation(&self) -> f64 {
        self.cross.atan2(self.dot)
    }

    /// The least-squares motion (T, ω) of the closest-point pairs, linearized in ω.
    ///
    /// A closest point inside the reference polyline is the foot of the perpendicular, so a
    /// pair's residual is counted along the surface normal (point-to-line): its component
    /// along the surface only says where the foot fell. At an isolated return the residual
    /// counts in full (point-to-point).
    fn closest_point_solution(&self) -> Pose2 {
        let mut h = Matrix3::<f64>::zeros();
        let mut g = Vector3::<f64>::zeros();
        let mut add = |n: [f64; 2], lever: f64, e: f64| {
            let j = Vector3::new(n[0], n[1], lever);
            h += j * j.transpose();
            g += j * e;
        };
        for ClosestPair {
            point: q,
            target,
            normal,
        } in &self.closest
        {
            // d(R(ω)q)/dω at ω = 0 is perp(q) = (−q_y, q_x).
            let (perp, d) = ([-q[1], q[0]], [target[0] - q[0], target[1] - q[1]]);
            match normal {
                Some(n) => add(
                    *n,
                    n[0] * perp[0] + n[1] * perp[1],
                    n[0] * d[0] + n[1] * d[1],
                ),
                None => {
                    add([1.0, 0.0], perp[0], d[0]);
                    add([0.0, 1.0], perp[1], d[1]);
                }
            }
        }
        // Damping: along a direction no pair constrains (a corridor's axis) the estimate stays
        // where it is instead of following noise; elsewhere it costs a step 0.1 % short.
        h += Matrix3::identity() * (1e-3 * h.trace() / 3.0);
        let x = h.cholesky().map(|c| c.solve(&g)).unwrap_or_default();
        Pose2::new(x[0], x[1], x[2])
    }
}

/// Both correspondence rules for every `stride`-th point of `current` at `pose`, into `pairs`.
fn correspond(
    contour: &Contour,
    current: &Scan2,
    pose: &Pose2,
    max_distance_m: f64,
    window_rad: f64,
    stride: usize,
    pairs: &mut Pairs,
) {
    pairs.closest.clear();
    (pairs.matching, pairs.cross, pairs.dot) = (0, 0.0, 0.0);
    let max2 = max_distance_m * max_distance_m;
    let to_reference = motion(pose);
    for &p in current.points().iter().step_by(stride) {
        let Some(query) = contour.query(to_reference(p)) else {
            continue;
        };
        let q = query.point;
        // No polyline point within the outlier distance: no pair by either rule (a
        // matching-range point is never nearer than the closest point).
        let Some(c) = contour.closest(&query, max_distance_m) else {
            continue;
        };
        if !c.open_end {
            pairs.closest.push(ClosestPair {
                point: q,
                target: c.point,
                normal: c.normal,
            });
        }
        if let Some(m) = contour.matching_range(&query, window_rad, max_distance_m)
            && (m.point[0] - q[0]).powi(2) + (m.point[1] - q[1]).powi(2) <= max2
        {
            // (sin δ, cos δ) of the pair's bearing offset δ, weighted.
            let scale = m.weight / (query.range_m * m.range_m);
            pairs.matching += 1;
            pairs.cross += scale * (q[0] * m.point[1] - q[1] * m.point[0]);
            pairs.dot += scale * (q[0] * m.point[0] + q[1] * m.point[1]);
        }
    }
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
