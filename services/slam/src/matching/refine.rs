//! Point-to-line refinement of a match (PL-ICP, Censi 2008), run from IDC's result.
//!
//! IDC stops when an update moves the pose by less than a millimetre, takes rotation from the
//! matching-range rule and translation from the closest-point rule separately, and keeps
//! pairs up to 0.2 m apart. Near the optimum a joint Gauss-Newton step on the point-to-line
//! residuals of all three coordinates is sharper: every point of the current scan against
//! the reference surface through its closest polyline point (normal from the chord across
//! about 0.4 m of the surface, where Censi takes the line through the two nearest returns:
//! with centimetre range noise on returns a few centimetres apart that line tilts by
//! degrees), with outliers rejected at a few robust standard deviations of the residuals at
//! the start (set once: a distance that moved every iteration kept flipping pairs).
//!
//! It may refine against several reference scans at once (each with its pose in a common
//! frame): the scan-to-submap variant, the new scan against the last few nodes' scans.
//! The result is validated like an IDC match (covariance, quality) against the first
//! reference.

mod solve;
#[cfg(test)]
mod tests;

use super::contour::Contour;
use super::validate::validate;
use super::{IdcParams, Match, MatchError, Scan2};
use crate::Pose2;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};
use solve::Solver;

/// Tunables of the point-to-line refinement, with units and defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineParams {
    /// Refine matches at all (sequential matches and the offsets of scans that hang off a
    /// node). Default true.
    pub enabled: bool,
    /// In the 2D mapper, the reference scans: the last node and this many nodes before it
    /// on its chain, at their current estimates (0: scan-to-scan). Default 1
    /// (docs/measurements/slam.md has the figures for 0, 1 and 2).
    pub submap_extra_nodes: usize,
    /// Pair the reference scans' points with the current scan's surfaces too (both ways).
    /// Default false.
    pub symmetric: bool,
    /// In the 2D mapper: odometry as a prior on the refined pose (see [`Prior`]). Default
    /// false: on ACES it changed nothing locally.
    pub odometry_prior: bool,
    /// Gauss-Newton iterations at most. Default 10.
    pub max_iterations: u32,
    /// Pairs further apart than this are dropped in the first iteration (m). Default 0.2,
    /// IDC's final outlier distance.
    pub initial_max_distance_m: f64,
    /// Later iterations drop pairs beyond this many robust standard deviations (1.4826 ×
    /// the median absolute residual) of the first iteration's residuals… Default 3.
    pub outlier_sigmas: f64,
    /// …but never closer than this (m). Default 0.03.
    pub min_max_distance_m: f64,
    /// Converged when an update moves the pose by less than this (m)… Default 1e-5.
    pub converged_translation_m: f64,
    /// …and turns it by less than this (rad). Default 1e-6.
    pub converged_rotation_rad: f64,
    /// Do not move the pose further than this from IDC's (m): a refinement that wanders off
    /// is dropped, IDC's match kept. Default 0.1.
    pub max_shift_m: f64,
}

impl Default for RefineParams {
    fn default() -> RefineParams {
        RefineParams {
            enabled: true,
            submap_extra_nodes: 1,
            odometry_prior: false,
            symmetric: false,
            max_iterations: 10,
            initial_max_distance_m: 0.2,
            outlier_sigmas: 3.0,
            min_max_distance_m: 0.03,
            converged_translation_m: 1e-5,
            converged_rotation_rad: 1e-6,
            max_shift_m: 0.1,
        }
    }
}

impl RefineParams {
    /// Checks every parameter against its range.
    pub fn check(&self) -> Result<(), MatchError> {
        let positive = [
            ("initial_max_distance_m", self.initial_max_distance_m),
            ("outlier_sigmas", self.outlier_sigmas),
            ("min_max_distance_m", self.min_max_distance_m),
            ("converged_translation_m", self.converged_translation_m),
            ("converged_rotation_rad", self.converged_rotation_rad),
            ("max_shift_m", self.max_shift_m),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(MatchError::InvalidParams(format!("{name} = {value}")));
            }
        }
        if self.max_iterations == 0 {
            return Err(MatchError::InvalidParams("max_iterations = 0".into()));
        }
        Ok(())
    }
}

/// A reference scan of the refinement and its frame in the common frame.
#[derive(Clone, Copy, Debug)]
pub struct Reference<'a> {
    /// The scan, in its own frame.
    pub scan: &'a Scan2,
    /// Its frame in the common frame (the first reference's frame for a plain match).
    pub pose: Pose2,
}

/// A Gaussian prior on the refined pose (odometry): where the scans leave a direction
/// unconstrained (a corridor's axis) it holds the pose, elsewhere the points outweigh it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    /// The current scan's frame in the common frame (the reference's frame for [`refine`]).
    pub pose: Pose2,
    /// Its information (x, y, θ; 1/m², 1/rad²).
    pub information: Matrix3<f64>,
}

/// Refines `start` (the current scan's frame in the reference frame, e.g. IDC's match) by
/// point-to-line Gauss-Newton, then validates the result as IDC does. The iterations run
/// are added to `start`'s; the match is converged when both are.
pub fn refine(
    reference: &Scan2,
    current: &Scan2,
    start: &Match,
    idc_params: &IdcParams,
    params: &RefineParams,
) -> Result<Match, MatchError> {
    let references = [Reference {
        scan: reference,
        pose: Pose2::IDENTITY,
    }];
    refine_against(&references, current, start, None, idc_params, params)
}

/// [`refine`] against several reference scans at once (scan-to-submap), each with its frame
/// in a common frame; `start` and the result are the current scan's frame in the frame of
/// `references[0]`, which the result is validated against. `prior`, if any, is in the common
/// frame.
pub fn refine_against(
    references: &[Reference],
    current: &Scan2,
    start: &Match,
    prior: Option<&Prior>,
    idc_params: &IdcParams,
    params: &RefineParams,
) -> Result<Match, MatchError> {
    params.check()?;
    idc_params.check()?;
    let Some(first) = references.first() else {
        return Err(MatchError::InvalidParams("no reference scan".into()));
    };
    if !start.pose.is_finite() {
        return Err(MatchError::NonFiniteInitial);
    }
    let contours: Vec<(Contour, Pose2)> = references
        .iter()
        .map(|r| {
            let contour = Contour::new(
                r.scan,
                idc_params.join_distance_m,
                idc_params.join_distance_per_m,
            );
            (contour, r.pose)
        })
        .collect();
    let current_contour = params.symmetric.then(|| {
        Contour::new(
            current,
            idc_params.join_distance_m,
            idc_params.join_distance_per_m,
        )
    });
    let mut solver = Solver::new(&contours, current, idc_params.min_correspondences);
    solver.symmetric = current_contour.as_ref();
    solver.prior = prior.copied();
    solver.min_sigma_m = idc_params.range_noise_m;
    let settled = |step: &nalgebra::Vector3<f64>| {
        step[0].hypot(step[1]) < idc_params.converged_translation_m
            && step[2].abs() < idc_params.converged_rotation_rad
    };
    let (in_common, iterations, converged) =
        solver.run(first.pose.compose(&start.pose), params, settled)?;
    let pose = first.pose.inverse().compose(&in_common);
    if (pose.x - start.pose.x).hypot(pose.y - start.pose.y) > params.max_shift_m {
        return Ok(start.clone());
    }
    Ok(Match {
        iterations: start.iterations + iterations,
        converged: start.converged && converged,
        ..validate(&contours[0].0, current, &pose, idc_params)
    })
}
