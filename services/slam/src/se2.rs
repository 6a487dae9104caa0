//! Rigid motions of the plane, SE(2): poses of the robot in a 2D map.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A pose in the plane: position (m) and heading (rad, counter-clockwise from the x axis).
/// As a motion, it maps a point p of its own frame to `R(theta)·p + (x, y)`.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose2 {
    /// East, or x of the parent frame (m).
    pub x: f64,
    /// North, or y of the parent frame (m).
    pub y: f64,
    /// Heading (rad, counter-clockwise from the x axis).
    pub theta: f64,
}

/// The absolute trajectory error of positions: RMSE of the distances between each estimate
/// and its truth (m), over the pairs given (0 for none).
pub fn position_rmse(pairs: impl IntoIterator<Item = (Pose2, Pose2)>) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (p, t) in pairs {
        sum += (p.x - t.x).powi(2) + (p.y - t.y).powi(2);
        n += 1;
    }
    if n == 0 { 0.0 } else { (sum / n as f64).sqrt() }
}

/// The rigid motion that best maps the points `a` onto the points `b` of each pair (2D
/// Procrustes, least squares); `None` with fewer than two pairs or all `a` at one place.
pub fn rigid_fit(pairs: &[([f64; 2], [f64; 2])]) -> Option<Pose2> {
    if pairs.len() < 2 {
        return None;
    }
    let n = pairs.len() as f64;
    let (mut ma, mut mb) = ([0.0; 2], [0.0; 2]);
    for (a, b) in pairs {
        (ma[0], ma[1], mb[0], mb[1]) = (ma[0] + a[0], ma[1] + a[1], mb[0] + b[0], mb[1] + b[1]);
    }
    let (ma, mb) = ([ma[0] / n, ma[1] / n], [mb[0] / n, mb[1] / n]);
    // Rotation angle maximizing Σ (b − mb)·R(a − ma).
    let (mut sin_sum, mut cos_sum) = (0.0, 0.0);
    for (a, b) in pairs {
        let (ax, ay, bx, by) = (a[0] - ma[0], a[1] - ma[1], b[0] - mb[0], b[1] - mb[1]);
        cos_sum += ax * bx + ay * by;
        sin_sum += ax * by - ay * bx;
    }
    if sin_sum == 0.0 && cos_sum == 0.0 {
        return None;
    }
    let angle = f64::atan2(sin_sum, cos_sum);
    let (s, c) = angle.sin_cos();
    Some(Pose2::new(
        mb[0] - (c * ma[0] - s * ma[1]),
        mb[1] - (s * ma[0] + c * ma[1]),
        angle,
    ))
}

/// [`position_rmse`] after moving the estimates by the rigid motion that fits them best to
/// their truths ([`rigid_fit`]): the error of a map whose frame is its own (no GPS, no
/// common start).
pub fn aligned_position_rmse(pairs: impl IntoIterator<Item = (Pose2, Pose2)>) -> f64 {
    let pairs: Vec<(Pose2, Pose2)> = pairs.into_iter().collect();
    let points: Vec<([f64; 2], [f64; 2])> = pairs
        .iter()
        .map(|(p, t)| ([p.x, p.y], [t.x, t.y]))
        .collect();
    let motion = rigid_fit(&points).unwrap_or(Pose2::IDENTITY);
    position_rmse(pairs.iter().map(|(p, t)| (motion.compose(p), *t)))
}

/// An angle brought into (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let b = (a + PI).rem_euclid(2.0 * PI) - PI;
    if b <= -PI { b + 2.0 * PI } else { b }
}

impl Pose2 {
    /// The identity: the origin, heading 0.
    pub const IDENTITY: Pose2 = Pose2 {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    };

    /// The pose at (x, y) (m) with heading theta (rad).
    pub fn new(x: f64, y: f64, theta: f64) -> Pose2 {
        Pose2 { x, y, theta }
    }

    /// The planar pose of a 3D frame: its x and y, and the heading of its x axis projected
    /// on the horizontal plane (as `leveling::heading_rad`), whatever its roll and pitch.
    pub fn from_isometry3(frame: &nalgebra::Isometry3<f64>) -> Pose2 {
        let x_axis = frame.rotation * nalgebra::Vector3::x();
        let t = frame.translation.vector;
        Pose2::new(t.x, t.y, x_axis.y.atan2(x_axis.x))
    }

    /// `self ⊕ other`: `other` expressed in the frame of `self`, moved to the outer frame.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2 {
            x: self.x + c * other.x - s * other.y,
            y: self.y + s * other.x + c * other.y,
            theta: wrap_angle(self.theta + other.theta),
        }
    }

    /// The inverse motion.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2 {
            x: -c * self.x - s * self.y,
            y: s * self.x - c * self.y,
            theta: wrap_angle(-self.theta),
        }
    }

    /// `self⁻¹ ⊕ other`: `other` seen from `self` (the relative pose an edge i → j measures).
    pub fn between(&self, other: &Pose2) -> Pose2 {
        self.inverse().compose(other)
    }

    /// A point of this pose's frame, in the outer frame.
    pub fn transform_point(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        [self.x + c * p[0] - s * p[1], self.y + s * p[0] + c * p[1]]
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn position_rmse_is_the_rms_distance() {
        let p = |x, y| super::Pose2::new(x, y, 0.3);
        let pairs = [(p(3.0, 4.0), p(0.0, 0.0)), (p(1.0, 1.0), p(1.0, 1.0))];
        assert!((super::position_rmse(pairs) - (25.0f64 / 2.0).sqrt()).abs() < 1e-12);
        assert_eq!(super::position_rmse([]), 0.0);
    }

    #[test]
    fn a_moved_map_aligns_back() {
        let motion = super::Pose2::new(12.0, -7.5, 2.2);
        let truth: Vec<super::Pose2> = (0..20)
            .map(|i| super::Pose2::new(f64::from(i).sin() * 9.0, f64::from(i) * 0.7, 0.1))
            .collect();
        let moved = truth.iter().map(|t| motion.inverse().compose(t));
        let pairs: Vec<_> = moved.zip(truth.iter().copied()).collect();
        assert!(super::position_rmse(pairs.clone()) > 5.0);
        assert!(super::aligned_position_rmse(pairs.clone()) < 1e-9);
        let points: Vec<_> = pairs
            .iter()
            .map(|(a, b)| ([a.x, a.y], [b.x, b.y]))
            .collect();
        let fit = super::rigid_fit(&points).expect("a fit");
        assert!(
            (fit.x - 12.0).abs() < 1e-9 && (fit.theta - 2.2).abs() < 1e-9,
            "{fit:?}"
        );
        assert_eq!(super::rigid_fit(&points[..1]), None);
    }

    use super::*;

    fn close(a: &Pose2, b: &Pose2) -> bool {
        (a.x - b.x).abs() < 1e-12
            && (a.y - b.y).abs() < 1e-12
            && wrap_angle(a.theta - b.theta).abs() < 1e-12
    }

    #[test]
    fn planar_pose_of_a_tilted_frame_keeps_its_heading() {
        use nalgebra::{Isometry3, Translation3, UnitQuaternion};
        // Yawed 0.7 rad, then pitched and rolled: the heading stays 0.7.
        let frame = Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 3.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7)
                * UnitQuaternion::from_euler_angles(0.2, -0.3, 0.0),
        );
        assert!(close(
            &Pose2::from_isometry3(&frame),
            &Pose2::new(1.0, -2.0, 0.7)
        ));
    }

    #[test]
    fn wrap_keeps_angles_in_half_open_interval() {
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert_eq!(wrap_angle(0.25), 0.25);
    }

    #[test]
    fn compose_inverse_between_agree() {
        let a = Pose2::new(1.0, -2.0, 0.7);
        let b = Pose2::new(-3.0, 0.5, -2.9);
        assert!(close(&a.compose(&a.inverse()), &Pose2::IDENTITY));
        assert!(close(&a.compose(&a.between(&b)), &b));
        let p = a.transform_point([2.0, 1.0]);
        let back = a.inverse().transform_point(p);
        assert!((back[0] - 2.0).abs() < 1e-12 && (back[1] - 1.0).abs() < 1e-12);
    }
}
