//! What a match is worth: every match yields a relative pose, a covariance and a quality; a
//! match below the quality gate is rejected (docs/slam.md, "Scan matching").
//!
//! **Covariance.** At the final pose, a closest-point pair on a reference surface (normal n)
//! is a point-to-line residual `e = nᵀ(q − c)` with Jacobian `nᵀ [I | perp(q − t)]` with
//! respect to (x, y, θ) of the pose (t: its translation, perp(v) = (−v_y, v_x)); a pair at
//! an isolated return is point-to-point with Jacobian `[I | perp(q − t)]`. Then
//! `H = Σ JᵀJ`, the residual variance `σ² = max(Σ e² / (m − 3), range_noise²)` over m scalar
//! residuals, and the covariance is `(H / σ² + P)⁻¹`, with
//! `P = diag(1/s_m², 1/s_m², 1/s_rad²)` from the `unobservable_std_*` parameters: along a
//! direction the scene does not constrain (a corridor's axis) H is singular and the reported
//! standard deviation becomes s instead of infinite. Pairs count as independent; residuals
//! along one surface are correlated, so the covariance is optimistic, as ICP covariances are.
//!
//! **Quality** is a product of three factors in [0, 1], each scan checked against the other
//! (current in the reference frame, and reference in the current frame):
//! - *inlier share*: of the points the other scan could have seen (it has a return within
//!   `visibility_window_rad` of their bearing), the share within `inlier_distance_m` of its
//!   polyline, both ways pooled: overlap and fit at once;
//! - *1 − conflict share*: a point well in front of every return of the other scan around
//!   its bearing lies in space that scan saw free. A wrong pose produces such points both
//!   ways; an artefact of one scan (a person walking by, the ground hit by a pitched
//!   scanner, common outdoors) only one way, so the smaller share counts. This is the
//!   outdoor check that residuals alone miss: sparse trunks and walls fit wrong poses loosely;
//! - *conditioning*: 0.5 + 0.5·min(1, κ / conditioning_ok), κ = λ_min / λ_max of H with the
//!   rotation scaled by the RMS point range. A corridor is still a useful constraint (its
//!   covariance says where it is weak), so it halves the quality instead of zeroing it.

use super::contour::{Closest, Contour, Query};
use super::idc::motion;
use super::{IdcParams, Match, Scan2};
use crate::Pose2;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

/// The match of `current` at `pose` (its frame in `reference`'s frame) against `reference`,
/// evaluated as IDC evaluates its own result: covariance and quality at that pose, with no
/// iteration (`iterations` 0, `converged` false). How a pose found some other way is checked.
/// (The 2D mapper's use, so only with the `solver` feature.)
#[cfg(feature = "solver")]
pub(crate) fn evaluate(
    reference: &Scan2,
    current: &Scan2,
    pose: &Pose2,
    params: &IdcParams,
) -> Match {
    let contour = Contour::new(
        reference,
        params.join_distance_m,
        params.join_distance_per_m,
    );
    validate(&contour, current, pose, params)
}

/// Evaluates the current scan at `pose` against the reference contour: the match at `pose`
/// with its covariance and quality (the caller fills in how the iteration went).
pub(super) fn validate(
    reference: &Contour,
    current: &Scan2,
    pose: &Pose2,
    params: &IdcParams,
) -> Match {
    // Forward: the current scan in the reference frame gives both the covariance pairs and
    // the agreement with the reference.
    let mut fit = Fit::default();
    let mut forward = Agreement::default();
    let search_m = params.final_max_distance_m.max(params.inlier_distance_m);
    let to_reference = motion(pose);
    for &p in current.points() {
        let Some(query) = reference.query(to_reference(p)) else {
            continue;
        };
        let closest = reference.closest(&query, search_m);
        if let Some(c) =
            closest.filter(|c| c.distance_m <= params.final_max_distance_m && !c.open_end)
        {
            fit.add(&c, query.point, pose);
        }
        let inlier = closest
            .map(|c| c.distance_m)
            .filter(|&d| d <= params.inlier_distance_m);
        forward.add(reference, &query, inlier, params);
    }
    // Backward: the reference seen from the current scan. An artefact of one scan alone (a
    // person, the ground hit by a pitched scanner) contradicts the other scan's free space
    // in one direction only; a wrong pose contradicts it both ways.
    let outline = Contour::outline(current, params.join_distance_m, params.join_distance_per_m);
    let mut backward = Agreement::default();
    let to_current = motion(&pose.inverse());
    for &p in reference.points() {
        let Some(query) = outline.query(to_current(p)) else {
            continue;
        };
        let inlier = outline.distance_within(&query, params.inlier_distance_m);
        backward.add(&outline, &query, inlier, params);
    }
    let (covariance, conditioning) = fit.finish(params);
    let inliers = forward.inliers + backward.inliers;
    let inlier_share = ratio(inliers, forward.visible + backward.visible);
    let conflict_share = forward.conflict_share().min(backward.conflict_share());
    let quality = inlier_share
        * (1.0 - conflict_share)
        * (0.5 + 0.5 * (conditioning / params.conditioning_ok).min(1.0));
    Match {
        pose: *pose,
        covariance,
        quality,
        inlier_share,
        conflict_share,
        mean_residual_m: if inliers > 0 {
            (forward.residual_sum_m + backward.residual_sum_m) / inliers as f64
        } else {
            f64::INFINITY
        },
        conditioning,
        correspondences: fit.pairs,
        iterations: 0,
        converged: false,
    }
}

/// Gauss-Newton information of the pose from the closest-point pairs at the final pose.
#[derive(Default)]
struct Fit {
    info: Matrix3<f64>,
    /// Σ squared residuals over `rows` scalar residuals.
    sse: f64,
    rows: usize,
    pairs: usize,
    /// Σ squared lever arms (m²).
    lever2: f64,
}

impl Fit {
    /// Adds the pair (q, c.point), q in the reference frame.
    fn add(&mut self, c: &Closest, q: [f64; 2], pose: &Pose2) {
        // d(q)/dθ = perp(q − t): the lever arm of the point about the current scan origin.
        let arm = [q[0] - pose.x, q[1] - pose.y];
        let perp = [-arm[1], arm[0]];
        let e = [q[0] - c.point[0], q[1] - c.point[1]];
        match c.normal {
            Some(n) => {
                let j = Vector3::new(n[0], n[1], n[0] * perp[0] + n[1] * perp[1]);
                self.info += j * j.transpose();
                self.sse += (n[0] * e[0] + n[1] * e[1]).powi(2);
                self.rows += 1;
            }
            None => {
                let jx = Vector3::new(1.0, 0.0, perp[0]);
                let jy = Vector3::new(0.0, 1.0, perp[1]);
                self.info += jx * jx.transpose() + jy * jy.transpose();
                self.sse += e[0] * e[0] + e[1] * e[1];
                self.rows += 2;
            }
        }
        self.pairs += 1;
        self.lever2 += arm[0] * arm[0] + arm[1] * arm[1];
    }

    /// The covariance and the conditioning.
    fn finish(&self, params: &IdcParams) -> ([[f64; 3]; 3], f64) {
        let dof = self.rows.saturating_sub(3).max(1) as f64;
        let sigma2 = (self.sse / dof).max(params.range_noise_m.powi(2));
        let prior = Matrix3::from_diagonal(&Vector3::new(
            params.unobservable_std_m.powi(-2),
            params.unobservable_std_m.powi(-2),
            params.unobservable_std_rad.powi(-2),
        ));
        // The prior is positive definite, so the sum always is; keep the prior alone otherwise.
        let covariance = (self.info / sigma2 + prior)
            .try_inverse()
            .or_else(|| prior.try_inverse())
            .unwrap_or_else(Matrix3::identity);
        let lever_m = (self.lever2 / self.pairs.max(1) as f64).sqrt();
        (covariance.into(), conditioning(&self.info, lever_m))
    }
}

/// How the points of one scan, moved into the frame of another, agree with it.
#[derive(Default)]
struct Agreement {
    /// Points the other scan could have seen: it has a return within the visibility window.
    visible: usize,
    /// Points within `inlier_distance_m` of its polyline (counted as visible too).
    inliers: usize,
    /// Visible points in front of every return around their bearing by the conflict margin.
    conflicts: usize,
    /// Σ distance of the inliers (m).
    residual_sum_m: f64,
}

impl Agreement {
    /// Adds one point; `inlier`: its distance to the other scan's polyline, if within
    /// `inlier_distance_m`.
    fn add(&mut self, other: &Contour, query: &Query, inlier: Option<f64>, params: &IdcParams) {
        if let Some(distance_m) = inlier {
            self.inliers += 1;
            self.visible += 1;
            self.residual_sum_m += distance_m;
        } else if let Some(seen_m) = other.min_range_near(query, params.visibility_window_rad) {
            self.visible += 1;
            if query.range_m < seen_m - params.conflict_margin_m {
                self.conflicts += 1;
            }
        }
    }

    fn conflict_share(&self) -> f64 {
        ratio(self.conflicts, self.inliers + self.conflicts)
    }
}

/// λ_min / λ_max of the information with the rotation row and column scaled by `lever_m`, so
/// all three directions are lengths; 0 when there is no information.
fn conditioning(info: &Matrix3<f64>, lever_m: f64) -> f64 {
    if lever_m <= 0.0 {
        return 0.0;
    }
    let scale = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 1.0 / lever_m));
    let eigen = SymmetricEigen::new(scale * info * scale).eigenvalues;
    let (min, max) = (eigen.min(), eigen.max());
    if max > 0.0 { (min / max).max(0.0) } else { 0.0 }
}

fn ratio(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

/// The thresholds a match must pass to become a constraint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QualityGate {
    /// Lowest [`Match::quality`] accepted. Default 0.5.
    pub min_quality: f64,
    /// Highest [`Match::mean_residual_m`] accepted (m). Default 0.05.
    pub max_mean_residual_m: f64,
    /// Highest [`Match::conflict_share`] accepted. Default 0.1.
    pub max_conflict_share: f64,
    /// Reject matches that did not converge. Default true.
    pub require_converged: bool,
}

impl Default for QualityGate {
    fn default() -> QualityGate {
        QualityGate {
            min_quality: 0.5,
            max_mean_residual_m: 0.05,
            max_conflict_share: 0.1,
            require_converged: true,
        }
    }
}

/// True when the match passes the gate; a match with a non-finite pose or covariance never
/// does.
pub fn accept(m: &Match, gate: &QualityGate) -> bool {
    let finite = m.pose.is_finite() && m.covariance.iter().flatten().all(|v| v.is_finite());
    finite
        && m.quality >= gate.min_quality
        && m.mean_residual_m <= gate.max_mean_residual_m
        && m.conflict_share <= gate.max_conflict_share
        && (m.converged || !gate.require_converged)
}
