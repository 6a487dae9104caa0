//! What a match is worth (DESIGN §3: "every match yields a relative pose, a covariance and a
//! quality; a match below the quality gate is rejected").
//!
//! **Covariance.** At the final pose, a closest-point pair inside a reference segment is a
//! point-to-line residual `e = nᵀ(q − c)` with Jacobian `nᵀ [I | perp(q − t)]` with respect
//! to (x, y, θ) of the pose (t: its translation, perp(v) = (−v_y, v_x)); a pair at a return
//! (corner, isolated return) is point-to-point with Jacobian `[I | perp(q − t)]`. Then
//! `H = Σ JᵀJ`, the residual variance `σ² = max(Σ e² / (m − 3), range_noise²)` over m scalar
//! residuals, and the covariance is `(H / σ² + P)⁻¹`, with
//! `P = diag(1/s_m², 1/s_m², 1/s_rad²)` from the `unobservable_std_*` parameters: along a
//! direction the scene does not constrain (a corridor's axis) H is singular and the reported
//! standard deviation becomes s instead of infinite. Pairs count as independent; residuals
//! along one surface are correlated, so the covariance is optimistic, as ICP covariances are.
//!
//! **Quality** is a product of three factors in [0, 1]:
//! - *inlier share*: of the current points the reference could have seen (it has a return
//!   within `visibility_window_rad` of their bearing), the share within `inlier_distance_m`
//!   of its polyline: overlap and fit at once;
//! - *1 − conflict share*: a current point well in front of every reference return around its
//!   bearing lies in space the reference saw free; a wrong match produces such points, a
//!   right one only through moving objects. This is the outdoor check that residuals alone
//!   miss: sparse trunks and walls fit many wrong poses loosely;
//! - *conditioning*: 0.5 + 0.5·min(1, κ / conditioning_ok), κ = λ_min / λ_max of H with the
//!   rotation scaled by the RMS point range. A corridor is still a useful constraint (its
//!   covariance says where it is weak), so it halves the quality instead of zeroing it.

use super::contour::Contour;
use super::idc::motion;
use super::{IdcParams, Match, Scan2};
use crate::Pose2;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

/// Covariance and quality of a final pose.
pub(super) struct Validation {
    pub covariance: [[f64; 3]; 3],
    pub quality: f64,
    pub inlier_share: f64,
    pub conflict_share: f64,
    pub mean_residual_m: f64,
    pub conditioning: f64,
    pub correspondences: usize,
}

/// Evaluates the current scan at `pose` against the reference contour.
pub(super) fn validate(
    reference: &Contour,
    current: &Scan2,
    pose: &Pose2,
    params: &IdcParams,
) -> Validation {
    let fit = fit(reference, current, pose, params);
    // Agreement both ways: the current scan seen from the reference, and the reference seen
    // from the current scan. An artefact of one scan alone (a person, ground hit by a pitched
    // scanner) contradicts the other scan's free space in one direction only; a wrong pose
    // contradicts it both ways.
    let current_contour = Contour::new(current, params.join_distance_m, params.join_distance_per_m);
    let forward = agreement(reference, current.points(), pose, params);
    let backward = agreement(&current_contour, reference.points(), &pose.inverse(), params);
    let inliers = forward.inliers + backward.inliers;
    let inlier_share = ratio(inliers, forward.visible + backward.visible);
    let conflict_share = forward.conflict_share().min(backward.conflict_share());
    let quality = inlier_share
        * (1.0 - conflict_share)
        * (0.5 + 0.5 * (fit.conditioning / params.conditioning_ok).min(1.0));
    Validation {
        covariance: fit.covariance,
        quality,
        inlier_share,
        conflict_share,
        mean_residual_m: if inliers > 0 {
            (forward.residual_sum_m + backward.residual_sum_m) / inliers as f64
        } else {
            f64::INFINITY
        },
        conditioning: fit.conditioning,
        correspondences: fit.pairs,
    }
}

/// Covariance and conditioning of the pose from the closest-point pairs at the final pose.
struct Fit {
    covariance: [[f64; 3]; 3],
    conditioning: f64,
    pairs: usize,
}

fn fit(reference: &Contour, current: &Scan2, pose: &Pose2, params: &IdcParams) -> Fit {
    let mut info = Matrix3::<f64>::zeros();
    let (mut sse, mut rows, mut pairs, mut lever2) = (0.0, 0usize, 0usize, 0.0);
    let to_reference = motion(pose);
    for &p in current.points() {
        let Some(query) = reference.query(to_reference(p)) else { continue };
        let q = query.point;
        let Some(c) = reference.closest(&query, params.final_max_distance_m).filter(|c| !c.open_end)
        else {
            continue;
        };
        // d(q)/dθ = perp(q − t): the lever arm of the point about the current scan origin.
        let arm = [q[0] - pose.x, q[1] - pose.y];
        let perp = [-arm[1], arm[0]];
        let e = [q[0] - c.point[0], q[1] - c.point[1]];
        match c.normal {
            Some(n) => {
                let j = Vector3::new(n[0], n[1], n[0] * perp[0] + n[1] * perp[1]);
                info += j * j.transpose();
                sse += (n[0] * e[0] + n[1] * e[1]).powi(2);
                rows += 1;
            }
            None => {
                let jx = Vector3::new(1.0, 0.0, perp[0]);
                let jy = Vector3::new(0.0, 1.0, perp[1]);
                info += jx * jx.transpose() + jy * jy.transpose();
                sse += e[0] * e[0] + e[1] * e[1];
                rows += 2;
            }
        }
        pairs += 1;
        lever2 += arm[0] * arm[0] + arm[1] * arm[1];
    }
    let sigma2 = (sse / rows.saturating_sub(3).max(1) as f64).max(params.range_noise_m.powi(2));
    let prior = Matrix3::from_diagonal(&Vector3::new(
        params.unobservable_std_m.powi(-2),
        params.unobservable_std_m.powi(-2),
        params.unobservable_std_rad.powi(-2),
    ));
    // The prior is positive definite, so the sum always is; keep the prior alone otherwise.
    let covariance = (info / sigma2 + prior)
        .try_inverse()
        .or_else(|| prior.try_inverse())
        .unwrap_or_else(Matrix3::identity);
    Fit {
        covariance: covariance.into(),
        conditioning: conditioning(&info, (lever2 / pairs.max(1) as f64).sqrt()),
        pairs,
    }
}

/// How the points of one scan, moved into the frame of another by `pose`, agree with it.
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
    fn conflict_share(&self) -> f64 {
        ratio(self.conflicts, self.inliers + self.conflicts)
    }
}

fn agreement(other: &Contour, points: &[[f64; 2]], pose: &Pose2, params: &IdcParams) -> Agreement {
    let mut a = Agreement::default();
    let to_other = motion(pose);
    for &p in points {
        let Some(query) = other.query(to_other(p)) else { continue };
        if let Some(c) = other.closest(&query, params.inlier_distance_m) {
            a.inliers += 1;
            a.visible += 1;
            a.residual_sum_m += c.distance_m;
        } else if let Some(seen_m) = other.min_range_near(&query, params.visibility_window_rad) {
            a.visible += 1;
            if query.range_m < seen_m - params.conflict_margin_m {
                a.conflicts += 1;
            }
        }
    }
    a
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
#[serde(default)]
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
