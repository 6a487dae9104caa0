//! [`IdcParams`]: every tunable of IDC and of the validation of its result, and their
//! ranges.

use crate::matching::MatchError;
use serde::{Deserialize, Serialize};

/// Every tunable of IDC and of the validation of its result, with its unit and default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
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
