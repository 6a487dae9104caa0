//! The Gauss-Newton iteration of the point-to-line refinement.

use super::{Prior, RefineParams};
use crate::matching::contour::Contour;
use crate::matching::idc::motion;
use crate::matching::{MatchError, Scan2};
use crate::{Pose2, wrap_angle};
use nalgebra::{Matrix3, Vector3};

/// The reference contours (each with its frame in the common frame) and the current scan.
pub(super) struct Solver<'c, 'a> {
    references: &'c [(Contour<'a>, Pose2)],
    current: &'c Scan2,
    min_pairs: usize,
    /// |residual| of every pair of the last iteration (m), for the outlier distance.
    residuals: Vec<f64>,
    /// A prior on the pose, weighed against the points by their residual variance.
    pub(super) prior: Option<Prior>,
    /// Floor of the residuals' standard deviation (m) when weighing them against the prior.
    pub(super) min_sigma_m: f64,
    /// The current scan's contour: the references' points are paired with it too.
    pub(super) symmetric: Option<&'c Contour<'a>>,
}

/// The normal equations of one iteration.
#[derive(Default)]
struct Normal {
    h: Matrix3<f64>,
    g: Vector3<f64>,
}

impl Normal {
    /// Adds the residual `e` along unit direction `n` (common frame) of a point at lever arm
    /// `arm` from the current scan's origin.
    fn add(&mut self, n: [f64; 2], arm: [f64; 2], e: f64) {
        // d(t + R(θ)p)/dθ = perp(R(θ)p) = perp(arm).
        let j = Vector3::new(n[0], n[1], n[1] * arm[0] - n[0] * arm[1]);
        self.h += j * j.transpose();
        self.g += j * e;
    }
}

impl<'c, 'a> Solver<'c, 'a> {
    pub(super) fn new(
        references: &'c [(Contour<'a>, Pose2)],
        current: &'c Scan2,
        min_pairs: usize,
    ) -> Solver<'c, 'a> {
        Solver {
            references,
            current,
            min_pairs,
            residuals: Vec::with_capacity(current.len() * references.len()),
            prior: None,
            min_sigma_m: 0.0,
            symmetric: None,
        }
    }

    /// Iterates from `start` (the current scan's frame in the common frame): the refined
    /// pose, the iterations run and whether the last update was negligible (below the
    /// refinement's tolerance, or `settled` after the last iteration).
    pub(super) fn run(
        &mut self,
        start: Pose2,
        params: &RefineParams,
        settled: impl Fn(&Vector3<f64>) -> bool,
    ) -> Result<(Pose2, u32, bool), MatchError> {
        let mut pose = start;
        let mut last_step = Vector3::zeros();
        let (mut robust_sigma_m, mut sigma_m) = (f64::INFINITY, self.min_sigma_m);
        let mut max_distance_m = params.initial_max_distance_m;
        for iteration in 1..=params.max_iterations {
            let mut normal = self.linearize(&pose, max_distance_m);
            if let Some(current) = self.symmetric {
                self.add_reverse(current, &pose, max_distance_m, &mut normal);
            }
            if self.residuals.len() < self.min_pairs {
                return Err(MatchError::TooFewCorrespondences {
                    iteration,
                    rule: "point-to-line",
                    found: self.residuals.len(),
                    needed: self.min_pairs,
                });
            }
            if iteration == 1 {
                robust_sigma_m = self.robust_sigma();
                sigma_m = robust_sigma_m.max(self.min_sigma_m);
            }
            if let Some(prior) = &self.prior {
                // Points in units of their variance, the prior in its own.
                let w = sigma_m.powi(-2);
                let e = Vector3::new(
                    pose.x - prior.pose.x,
                    pose.y - prior.pose.y,
                    wrap_angle(pose.theta - prior.pose.theta),
                );
                normal.h = normal.h * w + prior.information;
                normal.g = normal.g * w + prior.information * e;
            }
            let Some(step) = normal.h.cholesky().map(|c| -c.solve(&normal.g)) else {
                return Ok((pose, iteration, false));
            };
            pose = Pose2::new(
                pose.x + step[0],
                pose.y + step[1],
                wrap_angle(pose.theta + step[2]),
            );
            if step[0].hypot(step[1]) < params.converged_translation_m
                && step[2].abs() < params.converged_rotation_rad
            {
                return Ok((pose, iteration, true));
            }
            if iteration == 1 {
                // Once, from the residuals at the start: an outlier distance that moved with
                // every iteration would keep flipping pairs in and out.
                max_distance_m = (params.outlier_sigmas * robust_sigma_m)
                    .clamp(params.min_max_distance_m, params.initial_max_distance_m);
            }
            last_step = step;
        }
        // Not converged to the refinement's tolerance: still converged as IDC counts it when
        // the last update was below IDC's (the caller's `settled`).
        Ok((pose, params.max_iterations, settled(&last_step)))
    }

    /// The normal equations of the point-to-line residuals at `pose`, pairs at most
    /// `max_distance_m` apart; the residuals' magnitudes go to `self.residuals`.
    fn linearize(&mut self, pose: &Pose2, max_distance_m: f64) -> Normal {
        self.residuals.clear();
        let mut normal = Normal::default();
        let to_common = motion(pose);
        for (contour, frame) in self.references {
            let (s, c) = frame.theta.sin_cos();
            // A vector of the reference frame in the common frame.
            let rotate = |v: [f64; 2]| [c * v[0] - s * v[1], s * v[0] + c * v[1]];
            let to_reference = motion(&frame.inverse());
            for &p in self.current.points() {
                let w = to_common(p);
                let Some(query) = contour.query(to_reference(w)) else {
                    continue;
                };
                let Some(hit) = contour.closest(&query, max_distance_m) else {
                    continue;
                };
                if hit.open_end {
                    continue;
                }
                let arm = [w[0] - pose.x, w[1] - pose.y];
                let d = rotate([query.point[0] - hit.point[0], query.point[1] - hit.point[1]]);
                match hit.normal {
                    Some(n) => {
                        let n = rotate(n);
                        let e = n[0] * d[0] + n[1] * d[1];
                        normal.add(n, arm, e);
                        self.residuals.push(e.abs());
                    }
                    // An isolated return: point-to-point.
                    None => {
                        normal.add([1.0, 0.0], arm, d[0]);
                        normal.add([0.0, 1.0], arm, d[1]);
                        self.residuals.push(d[0].hypot(d[1]));
                    }
                }
            }
        }
        normal
    }

    /// Adds the point-to-line residuals of the references' points against the current
    /// scan's contour. A pair (reference point r, current surface point c with normal m) is
    /// the forward pair turned round: residual `n·(P(c) − r)` with `n = R_P m`, and the
    /// surface point moves with the pose as a current point does.
    fn add_reverse(
        &mut self,
        current: &Contour,
        pose: &Pose2,
        max_distance_m: f64,
        normal: &mut Normal,
    ) {
        let to_common = motion(pose);
        let to_current = motion(&pose.inverse());
        let (s, c) = pose.theta.sin_cos();
        for (contour, frame) in self.references {
            let to_common_from_reference = motion(frame);
            for &r in contour.points() {
                let r = to_common_from_reference(r);
                let Some(query) = current.query(to_current(r)) else {
                    continue;
                };
                let Some(hit) = current.closest(&query, max_distance_m) else {
                    continue;
                };
                let (false, Some(m)) = (hit.open_end, hit.normal) else {
                    continue;
                };
                let n = [c * m[0] - s * m[1], s * m[0] + c * m[1]];
                let w = to_common(hit.point);
                let e = n[0] * (w[0] - r[0]) + n[1] * (w[1] - r[1]);
                normal.add(n, [w[0] - pose.x, w[1] - pose.y], e);
                self.residuals.push(e.abs());
            }
        }
    }

    /// 1.4826 × the median absolute residual of the last iteration: the residuals' standard
    /// deviation, unmoved by outliers.
    fn robust_sigma(&mut self) -> f64 {
        let n = self.residuals.len();
        if n == 0 {
            return f64::INFINITY;
        }
        let (_, median, _) = self.residuals.select_nth_unstable_by(n / 2, f64::total_cmp);
        1.4826 * *median
    }
}
