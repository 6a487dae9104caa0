//! One iteration's correspondences: both pairing rules over the current scan, and the
//! update each rule's least-squares solution gives.

use super::motion;
use crate::Pose2;
use crate::matching::Scan2;
use crate::matching::contour::Contour;
use nalgebra::{Matrix3, Vector3};

/// A closest-point pair (reference frame, m).
pub(super) struct ClosestPair {
    /// The point of the current scan.
    point: [f64; 2],
    /// Its closest point on the reference polyline.
    target: [f64; 2],
    /// The reference surface normal there; `None` at an isolated return.
    normal: Option<[f64; 2]>,
}

/// One iteration's pairs (points in the reference frame).
#[derive(Default)]
pub(super) struct Pairs {
    pub(super) closest: Vec<ClosestPair>,
    /// Number of matching-range pairs, with Σ w·sin δ and Σ w·cos δ over them (δ: bearing
    /// offset from the point to its match, w: the pair's rotation information).
    pub(super) matching: usize,
    cross: f64,
    dot: f64,
}

impl Pairs {
    /// No pairs yet, with room for the closest-point pairs of `points` points.
    pub(super) fn with_capacity(points: usize) -> Pairs {
        Pairs {
            closest: Vec::with_capacity(points),
            ..Pairs::default()
        }
    }

    /// The update, as a motion applied in the reference frame, `q ↦ R(ω)·q + T`: the rotation
    /// ω of the matching-range pairs and the translation T of the closest-point pairs, each
    /// from the least-squares solution of its own pairs (Lu & Milios, section 4: "(ω₂, T₁)").
    pub(super) fn update(&self) -> Pose2 {
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
pub(super) fn correspond(
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
