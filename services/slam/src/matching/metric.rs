//! The relation metric of Kümmerle et al., "On measuring the accuracy of SLAM algorithms"
//! (Autonomous Robots 27(4), 2009): for each relation (i, j, δ*ᵢⱼ) — a trusted relative pose
//! from the robot at i to the robot at j — the error is εᵢⱼ = (xᵢ⁻¹ ⊕ xⱼ) ⊖ δ*ᵢⱼ, and a
//! trajectory is scored by the mean and standard deviation of |translational part| (m) and
//! |rotational part| (rad) over all relations.

use crate::{Pose2, wrap_angle};
use std::fmt;

/// The error of one relation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelationError {
    /// |translational part of ε| (m).
    pub translation_m: f64,
    /// |rotational part of ε| (rad, in [0, π]).
    pub rotation_rad: f64,
}

/// ε = (from⁻¹ ⊕ to) ⊖ δ*, with a ⊖ b = b⁻¹ ⊕ a (the error seen from the relation's frame;
/// its norms do not depend on that choice).
pub fn relation_error(from: &Pose2, to: &Pose2, delta: &Pose2) -> RelationError {
    let eps = delta.inverse().compose(&from.between(to));
    RelationError {
        translation_m: eps.x.hypot(eps.y),
        rotation_rad: wrap_angle(eps.theta).abs(),
    }
}

/// How a map closes a run that ends where it started, for a log without relations: the last
/// scan matched against the first by IDC, from where the map puts the one relative to the
/// other. A closed loop needs only a small correction; an open one leaves the scans too far
/// apart for IDC (or its quality gate), and no correction is found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReturnToStart {
    /// The last pose's distance from the first on the map (m).
    pub distance_m: f64,
    /// How far the match moves the last scan from where the map has it (m), if they match.
    pub correction_m: Option<f64>,
    /// …and how far it turns it (rad).
    pub correction_rad: Option<f64>,
}

/// The first and last scans, each at its pose on the map: see [`ReturnToStart`].
pub fn return_to_start(
    first: (&Pose2, &crate::matching::Scan2),
    last: (&Pose2, &crate::matching::Scan2),
    idc: &crate::matching::IdcParams,
    gate: &crate::matching::QualityGate,
) -> ReturnToStart {
    let on_map = first.0.between(last.0);
    let matched = crate::matching::idc(first.1, last.1, on_map, idc)
        .ok()
        .filter(|m| crate::matching::accept(m, gate));
    let correction = matched.map(|m| on_map.between(&m.pose));
    ReturnToStart {
        distance_m: on_map.x.hypot(on_map.y),
        correction_m: correction.map(|c| c.x.hypot(c.y)),
        correction_rad: correction.map(|c| wrap_angle(c.theta).abs()),
    }
}

/// Mean, standard deviation (population: divided by the count) and maximum of both parts
/// of the relation errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelationMetric {
    /// Relations scored.
    pub count: usize,
    /// Mean translation error (m).
    pub translation_mean_m: f64,
    /// Standard deviation of the translation error (m).
    pub translation_std_m: f64,
    /// Largest translation error (m).
    pub translation_max_m: f64,
    /// Mean rotation error (rad).
    pub rotation_mean_rad: f64,
    /// Standard deviation of the rotation error (rad).
    pub rotation_std_rad: f64,
    /// Largest rotation error (rad).
    pub rotation_max_rad: f64,
}

/// Why the metric could not be computed.
#[derive(Clone, Debug, PartialEq)]
pub enum MetricError {
    /// No relation was given.
    Empty,
    /// The pose lookup has no pose for a relation's key.
    MissingPose {
        /// Index of the relation.
        relation: usize,
        /// The key with no pose.
        key: String,
    },
    /// A relation or a looked-up pose is not finite.
    NonFinite {
        /// Index of the relation.
        relation: usize,
    },
}

impl fmt::Display for MetricError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MetricError::Empty => write!(f, "no relations"),
            MetricError::MissingPose { relation, key } => {
                write!(f, "relation {relation}: no pose for {key}")
            }
            MetricError::NonFinite { relation } => {
                write!(f, "relation {relation}: pose or delta not finite")
            }
        }
    }
}

impl std::error::Error for MetricError {}

/// Scores poses against relations `(key_i, key_j, δ*ᵢⱼ)`; `pose_of` looks a key up (a
/// timestamp, a node id). Every relation must resolve: a missing pose is an error, not a
/// silently smaller sample.
pub fn relation_metric<K, I, F>(relations: I, mut pose_of: F) -> Result<RelationMetric, MetricError>
where
    K: fmt::Debug,
    I: IntoIterator<Item = (K, K, Pose2)>,
    F: FnMut(&K) -> Option<Pose2>,
{
    let mut errors = Vec::new();
    for (index, (ki, kj, delta)) in relations.into_iter().enumerate() {
        let mut lookup = |key: &K| {
            pose_of(key).ok_or_else(|| MetricError::MissingPose {
                relation: index,
                key: format!("{key:?}"),
            })
        };
        let (from, to) = (lookup(&ki)?, lookup(&kj)?);
        if !(from.is_finite() && to.is_finite() && delta.is_finite()) {
            return Err(MetricError::NonFinite { relation: index });
        }
        errors.push(relation_error(&from, &to, &delta));
    }
    if errors.is_empty() {
        return Err(MetricError::Empty);
    }
    let (t_mean, t_std, t_max) = stats(errors.iter().map(|e| e.translation_m));
    let (r_mean, r_std, r_max) = stats(errors.iter().map(|e| e.rotation_rad));
    Ok(RelationMetric {
        count: errors.len(),
        translation_mean_m: t_mean,
        translation_std_m: t_std,
        translation_max_m: t_max,
        rotation_mean_rad: r_mean,
        rotation_std_rad: r_std,
        rotation_max_rad: r_max,
    })
}

/// (mean, population standard deviation, maximum) of a non-empty sample.
fn stats(values: impl Iterator<Item = f64> + Clone) -> (f64, f64, f64) {
    let n = values.clone().count() as f64;
    let mean = values.clone().sum::<f64>() / n;
    let var = values.clone().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt(), values.fold(0.0, f64::max))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_poses_score_zero_and_errors_add_up() {
        let poses = [
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(1.0, 0.0, 0.5),
            Pose2::new(1.0, 2.0, -1.0),
        ];
        let truth = |i: usize, j: usize| poses[i].between(&poses[j]);
        let relations = vec![(0usize, 1usize, truth(0, 1)), (1, 2, truth(1, 2))];
        let m = relation_metric(relations.clone(), |k| poses.get(*k).copied()).expect("all found");
        assert_eq!(m.count, 2);
        assert!(m.translation_max_m < 1e-12 && m.rotation_max_rad < 1e-12);

        // Shift pose 2 by 0.1 m and turn it by 0.02 rad: only the (1, 2) relation sees it.
        let mut moved = poses;
        moved[2] = poses[2].compose(&Pose2::new(0.1, 0.0, 0.02));
        let m = relation_metric(relations, |k| moved.get(*k).copied()).expect("all found");
        assert!(
            (m.translation_mean_m - 0.05).abs() < 1e-9 && (m.translation_std_m - 0.05).abs() < 1e-9
        );
        assert!(
            (m.translation_max_m - 0.1).abs() < 1e-9 && (m.rotation_max_rad - 0.02).abs() < 1e-9
        );
    }

    #[test]
    fn missing_pose_and_empty_input_are_errors() {
        let relations = vec![(0usize, 7usize, Pose2::IDENTITY)];
        let err = relation_metric(relations, |k| (*k == 0).then_some(Pose2::IDENTITY)).unwrap_err();
        assert_eq!(
            err,
            MetricError::MissingPose {
                relation: 0,
                key: "7".into()
            }
        );
        let none: Vec<(usize, usize, Pose2)> = Vec::new();
        assert_eq!(
            relation_metric(none, |_| None).unwrap_err(),
            MetricError::Empty
        );
    }

    #[test]
    fn a_closed_return_needs_a_small_correction_an_open_one_finds_none() {
        use crate::matching::synthetic::{Scene, uniform_bearings};
        use crate::matching::{IdcParams, QualityGate, Scan2};
        let bearings = uniform_bearings(
            361,
            -std::f64::consts::PI / 2.0,
            std::f64::consts::PI / 360.0,
        );
        let scan_at = |pose: &Pose2, seed: u64| {
            let ranges = Scene::park().scan(pose, &bearings, 40.0, 0.01, seed);
            Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths")
        };
        let (start, end) = (Pose2::new(0.0, 0.0, 0.0), Pose2::new(1.0, 0.5, 0.1));
        let (first, last) = (scan_at(&start, 1), scan_at(&end, 2));
        let (idc, gate) = (IdcParams::default(), QualityGate::default());
        // The map has the end 0.2 m off where it truly is.
        let on_map = end.compose(&Pose2::new(0.2, 0.0, 0.0));
        let closed = return_to_start((&start, &first), (&on_map, &last), &idc, &gate);
        let correction = closed.correction_m.expect("they match");
        assert!((correction - 0.2).abs() < 0.05, "{closed:?}");
        // The map has it 30 m off: an open loop, no match.
        let far = end.compose(&Pose2::new(30.0, 0.0, 0.0));
        let open = return_to_start((&start, &first), (&far, &last), &idc, &gate);
        assert_eq!(open.correction_m, None, "{open:?}");
        assert!(
            (open.distance_m - start.between(&far).x.hypot(start.between(&far).y)).abs() < 1e-9
        );
    }
}
