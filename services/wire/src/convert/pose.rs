//! Poses, vectors and covariances.

use crate::error::{coordinate, finite};
use crate::{WireError, v1};
use leveling::nalgebra::{Isometry2, Isometry3, Quaternion, Translation3, UnitQuaternion};
use slam::Pose2;

/// A 3D pose on the wire (position in m, unit quaternion w, x, y, z).
pub fn pose3d_to_wire(pose: &Isometry3<f64>) -> v1::Pose3D {
    let t = &pose.translation.vector;
    let q = pose.rotation.quaternion();
    v1::Pose3D {
        x_m: t.x,
        y_m: t.y,
        z_m: t.z,
        qw: q.w,
        qx: q.i,
        qy: q.j,
        qz: q.k,
    }
}

/// A 3D pose from the wire: every component finite, the quaternion non-zero (normalized
/// here; an unset orientation is all zeros and therefore rejected).
pub fn pose3d_from_wire(pose: &v1::Pose3D) -> Result<Isometry3<f64>, WireError> {
    let x = coordinate("Pose3D.x_m", None, pose.x_m)?;
    let y = coordinate("Pose3D.y_m", None, pose.y_m)?;
    let z = coordinate("Pose3D.z_m", None, pose.z_m)?;
    let q = Quaternion::new(
        finite("Pose3D.qw", None, pose.qw)?,
        finite("Pose3D.qx", None, pose.qx)?,
        finite("Pose3D.qy", None, pose.qy)?,
        finite("Pose3D.qz", None, pose.qz)?,
    );
    let norm = q.norm();
    // Finite components can still square past f64 (1e200): such a norm is infinite, and
    // normalizing by it would give the zero quaternion, no rotation at all.
    if !(norm > 1e-6 && norm.is_finite()) {
        return Err(WireError::InvalidValue {
            field: "Pose3D.qw",
            index: None,
            value: norm,
            problem: "the norm of a quaternion that cannot be normalized",
        });
    }
    Ok(Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// A planar pose on the wire: the one way a `Pose2D` is written.
pub fn pose2_to_wire(pose: &Pose2) -> v1::Pose2D {
    v1::Pose2D {
        x_m: pose.x,
        y_m: pose.y,
        yaw_rad: pose.theta,
    }
}

/// A planar pose from the wire, every component finite: the one way a `Pose2D` is read.
pub fn pose2_from_wire(pose: &v1::Pose2D) -> Result<Pose2, WireError> {
    Ok(Pose2::new(
        coordinate("Pose2D.x_m", None, pose.x_m)?,
        coordinate("Pose2D.y_m", None, pose.y_m)?,
        finite("Pose2D.yaw_rad", None, pose.yaw_rad)?,
    ))
}

/// The planar pose of a 3D pose: x, y and the heading of its x axis
/// ([`Pose2::from_isometry3`], as the 2D mapping uses it).
pub fn pose2d_to_wire(pose: &Isometry3<f64>) -> v1::Pose2D {
    pose2_to_wire(&Pose2::from_isometry3(pose))
}

/// A planar pose from the wire as an isometry ([`pose2_from_wire`]).
pub fn pose2d_from_wire(pose: &v1::Pose2D) -> Result<Isometry2<f64>, WireError> {
    let p = pose2_from_wire(pose)?;
    Ok(Isometry2::new([p.x, p.y].into(), p.theta))
}

pub(crate) fn check_vec3(v: Option<&v1::Vec3>, field: &'static str) -> Result<(), WireError> {
    if let Some(v) = v {
        for (i, c) in [v.x, v.y, v.z].into_iter().enumerate() {
            coordinate(field, Some(i), c)?;
        }
    }
    Ok(())
}

/// A covariance: either empty (unknown) or `dim`² finite values with a non-negative diagonal.
pub(crate) fn check_covariance(
    values: &[f64],
    dim: usize,
    field: &'static str,
) -> Result<(), WireError> {
    if !values.is_empty() && values.len() != dim * dim {
        return Err(WireError::Invalid {
            field,
            detail: format!("{} values, expected {} or none", values.len(), dim * dim),
        });
    }
    for (i, &v) in values.iter().enumerate() {
        finite(field, Some(i), v)?;
        if i % (dim + 1) == 0 && v < 0.0 {
            return Err(WireError::InvalidValue {
                field,
                index: Some(i),
                value: v,
                problem: "a negative variance",
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::fixtures::*;
    use crate::*;
    use leveling::heading_rad;
    use leveling::*;

    #[test]
    fn a_quaternion_whose_norm_overflows_is_no_rotation() {
        // Found by the `node` fuzz target: finite components whose squares overflow gave an
        // infinite norm, and normalizing by it the zero quaternion, which was taken.
        let mut huge = pose3d_to_wire(&robot_pose());
        (huge.qw, huge.qx, huge.qy, huge.qz) = (1e200, 0.0, 0.0, 1e200);
        assert!(matches!(
            pose3d_from_wire(&huge),
            Err(WireError::InvalidValue {
                field: "Pose3D.qw",
                ..
            })
        ));
        // Large but representable components still normalize.
        (huge.qw, huge.qz) = (1e150, 1e150);
        let rotation = pose3d_from_wire(&huge).unwrap().rotation;
        assert!((rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn poses_round_trip() {
        let pose = robot_pose();
        let back = pose3d_from_wire(&pose3d_to_wire(&pose)).unwrap();
        assert!((back.to_homogeneous() - pose.to_homogeneous()).abs().max() < 1e-12);

        let odometry = odometry_from_wire(
            &decode_odometry(
                &odometry_to_wire(&TimedPose { stamp_ns: 42, pose }, header(1)).encode_to_vec(),
            )
            .unwrap(),
        )
        .unwrap();
        assert_eq!(odometry.stamp_ns, 42);
        assert!(
            (odometry.pose.to_homogeneous() - pose.to_homogeneous())
                .abs()
                .max()
                < 1e-12
        );

        let planar = pose2d_to_wire(&pose);
        assert_eq!((planar.x_m, planar.y_m), (12.5, -3.25));
        assert!((planar.yaw_rad - heading_rad(&pose.rotation)).abs() < 1e-15);
        let p2 = pose2d_from_wire(&planar).unwrap();
        assert!((p2.rotation.angle() - planar.yaw_rad).abs() < 1e-12);
    }
}
