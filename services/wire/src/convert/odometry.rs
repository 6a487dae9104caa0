//! Odometry.

use super::check_header;
use super::pose::{
    check_covariance, check_vec3, pose2d_from_wire, pose2d_to_wire, pose3d_from_wire,
    pose3d_to_wire,
};
use crate::{WireError, v1};
use leveling::TimedPose;

/// Odometry on the wire: `header.stamp_ns` is set to the pose's time, `pose` and `pose2d`
/// are filled; velocities and covariance are left unknown for the caller to set.
pub fn odometry_to_wire(pose: &TimedPose, mut header: v1::Header) -> v1::Odometry {
    header.stamp_ns = pose.stamp_ns;
    v1::Odometry {
        header: Some(header),
        pose: Some(pose3d_to_wire(&pose.pose)),
        pose2d: Some(pose2d_to_wire(&pose.pose)),
        linear_velocity_mps: None,
        angular_velocity_radps: None,
        pose_covariance: Vec::new(),
    }
}

/// The timed pose of an odometry message, checked: header, a valid pose, finite `pose2d`
/// and velocities if present, a covariance of 36 finite values or none.
pub fn odometry_from_wire(msg: &v1::Odometry) -> Result<TimedPose, WireError> {
    let header = check_header(msg.header.as_ref(), "Odometry.header")?;
    let pose = msg.pose.as_ref().ok_or(WireError::Missing {
        field: "Odometry.pose",
    })?;
    let pose = pose3d_from_wire(pose)?;
    if let Some(p) = &msg.pose2d {
        pose2d_from_wire(p)?;
    }
    check_vec3(
        msg.linear_velocity_mps.as_ref(),
        "Odometry.linear_velocity_mps",
    )?;
    check_vec3(
        msg.angular_velocity_radps.as_ref(),
        "Odometry.angular_velocity_radps",
    )?;
    check_covariance(&msg.pose_covariance, 6, "Odometry.pose_covariance")?;
    Ok(TimedPose {
        stamp_ns: header.stamp_ns,
        pose,
    })
}
