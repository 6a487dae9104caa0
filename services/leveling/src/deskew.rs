//! Scanning while driving (paper 2.1): motion compensation and leveling of a 3D scan.
//!
//! Every column is moved by the 3D dead-reckoning pose at its timestamp into the frame of the
//! robot at scan start, then roll and pitch are removed so that z is along gravity: the
//! *leveled* frame. Only the relative motion during one scan matters, so dead-reckoning drift
//! does no harm; its attitude must be gravity-referenced (gyro + inclination), which is what
//! lets the leveled frame be independent of the slope the robot stands on.

use crate::scan::{CylPoint, Scan3d};
use nalgebra::{Isometry3, Matrix3, Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// A robot pose from 3D dead reckoning at one instant: robot frame (x forward, y left, z up) in
/// the odometry frame, whose z axis is along gravity.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimedPose {
    /// Time of the pose (ns, the clock of the scan's column stamps).
    pub stamp_ns: u64,
    /// The robot frame in the odometry frame (m, rad).
    pub pose: Isometry3<f64>,
}

/// Why a scan could not be motion-compensated.
#[derive(Clone, Debug, PartialEq)]
pub enum DeskewError {
    /// The track has no samples.
    EmptyTrack,
    /// Samples are not in strictly increasing time order (index of the first bad one).
    UnorderedTrack {
        /// Index of the sample.
        index: usize,
    },
    /// A column was measured outside the time span the track covers.
    OutsideTrack {
        /// Index of the column.
        column: usize,
        /// Its time stamp (ns).
        stamp_ns: u64,
        /// Time of the track's first sample (ns).
        first_ns: u64,
        /// Time of the track's last sample (ns).
        last_ns: u64,
    },
}

impl std::fmt::Display for DeskewError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DeskewError::EmptyTrack => write!(f, "dead-reckoning track is empty"),
            DeskewError::UnorderedTrack { index } => {
                write!(
                    f,
                    "dead-reckoning sample {index} is not later than the one before"
                )
            }
            DeskewError::OutsideTrack {
                column,
                stamp_ns,
                first_ns,
                last_ns,
            } => write!(
                f,
                "column {column} at {stamp_ns} ns lies outside the dead-reckoning track \
                 [{first_ns}, {last_ns}] ns"
            ),
        }
    }
}

impl std::error::Error for DeskewError {}

/// Dead-reckoning poses over time, interpolated between samples.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseTrack {
    samples: Vec<TimedPose>,
}

impl PoseTrack {
    /// A track from samples in strictly increasing time order.
    pub fn new(samples: Vec<TimedPose>) -> Result<PoseTrack, DeskewError> {
        if samples.is_empty() {
            return Err(DeskewError::EmptyTrack);
        }
        if let Some(i) = samples
            .windows(2)
            .position(|w| w[1].stamp_ns <= w[0].stamp_ns)
        {
            return Err(DeskewError::UnorderedTrack { index: i + 1 });
        }
        Ok(PoseTrack { samples })
    }

    /// A robot standing still at `pose` (attitude from an inclinometer or the scan's pose
    /// file): leveling without motion compensation. Valid at every time.
    pub fn stationary(pose: Isometry3<f64>) -> PoseTrack {
        PoseTrack {
            samples: vec![TimedPose { stamp_ns: 0, pose }],
        }
    }

    /// The samples, in strictly increasing time order.
    pub fn samples(&self) -> &[TimedPose] {
        &self.samples
    }

    /// The pose at `stamp_ns`: linear in position, spherical-linear in attitude; `None`
    /// outside the sampled span (a stationary track covers all time).
    pub fn at(&self, stamp_ns: u64) -> Option<Isometry3<f64>> {
        let s = &self.samples;
        if s.len() == 1 {
            return Some(s[0].pose);
        }
        if stamp_ns < s[0].stamp_ns || stamp_ns > s[s.len() - 1].stamp_ns {
            return None;
        }
        let i = s
            .partition_point(|p| p.stamp_ns <= stamp_ns)
            .clamp(1, s.len() - 1);
        let (a, b) = (&s[i - 1], &s[i]);
        let t = (stamp_ns - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns) as f64;
        Some(a.pose.lerp_slerp(&b.pose, t))
    }
}

/// Heading of a pose: yaw of its x axis projected on the horizontal plane (rad).
pub fn heading_rad(rotation: &UnitQuaternion<f64>) -> f64 {
    let x_axis = rotation * Vector3::x();
    x_axis.y.atan2(x_axis.x)
}

/// The leveled frame of a scan: at the sensor's position at scan start, heading of the robot
/// at scan start, z along gravity. Returns the transform from odometry frame to leveled frame.
pub fn leveled_frame(
    robot_at_start: &Isometry3<f64>,
    sensor_in_robot: &Isometry3<f64>,
) -> Isometry3<f64> {
    let sensor = robot_at_start * sensor_in_robot;
    let heading = heading_rad(&robot_at_start.rotation);
    Isometry3::from_parts(
        sensor.translation,
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading),
    )
    .inverse()
}

/// Moves every column of `raw` (sensor frame) into the leveled frame of the scan's start.
///
/// Each column keeps its order and invalid slots; its sensor axis position at the column's
/// time is stored in [`crate::Column::origin_xy_m`] and its points are re-expressed around
/// that axis, so segmentation measures distances from where the sensor really was.
pub fn deskew(
    raw: &Scan3d,
    track: &PoseTrack,
    sensor_in_robot: &Isometry3<f64>,
) -> Result<Scan3d, DeskewError> {
    let start_ns = raw.start_stamp_ns();
    let outside = |column: usize, stamp_ns: u64| DeskewError::OutsideTrack {
        column,
        stamp_ns,
        first_ns: track.samples[0].stamp_ns,
        last_ns: track.samples[track.samples.len() - 1].stamp_ns,
    };
    let start = track.at(start_ns).ok_or_else(|| outside(0, start_ns))?;
    let world_to_leveled = leveled_frame(&start, sensor_in_robot);

    let mut out = Scan3d {
        points: Vec::with_capacity(raw.points.len()),
        columns: raw.columns.clone(),
    };
    for (index, column) in out.columns.iter_mut().enumerate() {
        let robot = track
            .at(column.stamp_ns)
            .ok_or_else(|| outside(index, column.stamp_ns))?;
        let sensor_to_leveled = world_to_leveled * robot * sensor_in_robot;
        let rotation: Matrix3<f32> = sensor_to_leveled
            .rotation
            .to_rotation_matrix()
            .matrix()
            .cast();
        let origin: Vector3<f32> = sensor_to_leveled.translation.vector.cast();
        column.origin_xy_m = [origin.x, origin.y];
        let begin = column.start as usize;
        for p in &raw.points[begin..begin + column.len as usize] {
            if !p.is_valid() {
                out.points.push(CylPoint::INVALID);
                continue;
            }
            let v = rotation * Vector3::from(p.to_xyz());
            // Relative to the column's own (vertical) sensor axis; z in the leveled frame.
            out.points
                .push(CylPoint::from_xyz(v.x, v.y, v.z + origin.z));
        }
    }
    Ok(out)
}

/// A point of the leveled frame given relative to a column's sensor axis, as (x, y, z).
pub fn leveled_xyz(point: &CylPoint, origin_xy_m: [f32; 2]) -> Point3<f32> {
    let [x, y, z] = point.to_xyz();
    Point3::new(x + origin_xy_m[0], y + origin_xy_m[1], z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Translation3;

    fn pose(x: f64, y: f64, z: f64, roll: f64, pitch: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(roll, pitch, yaw),
        )
    }

    #[test]
    fn track_interpolates_and_refuses_outside() {
        let track = PoseTrack::new(vec![
            TimedPose {
                stamp_ns: 100,
                pose: pose(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            },
            TimedPose {
                stamp_ns: 300,
                pose: pose(2.0, 0.0, 0.0, 0.0, 0.0, 1.0),
            },
        ])
        .unwrap();
        let mid = track.at(200).unwrap();
        assert!((mid.translation.x - 1.0).abs() < 1e-12);
        assert!((heading_rad(&mid.rotation) - 0.5).abs() < 1e-12);
        assert!(track.at(99).is_none() && track.at(301).is_none());
        assert_eq!(
            PoseTrack::new(vec![
                TimedPose {
                    stamp_ns: 5,
                    pose: Isometry3::identity()
                },
                TimedPose {
                    stamp_ns: 5,
                    pose: Isometry3::identity()
                },
            ]),
            Err(DeskewError::UnorderedTrack { index: 1 })
        );
    }

    #[test]
    fn tilted_standing_robot_sees_a_level_world() {
        // The robot stands pitched nose-down 10° and rolled 5°; a point 10 m ahead on level
        // ground 1 m below the sensor must come out at z = -1 in the leveled frame.
        let robot = pose(5.0, -3.0, 2.0, 0.087, 0.17, 0.4);
        let world_point = robot * Point3::new(0.0, 0.0, 0.0)
            + Vector3::new(10.0 * 0.4f64.cos(), 10.0 * 0.4f64.sin(), -1.0);
        let in_sensor = robot.inverse() * world_point;
        let mut raw = Scan3d::default();
        raw.begin_column(0);
        raw.push_xyz(in_sensor.x as f32, in_sensor.y as f32, in_sensor.z as f32);
        let leveled = deskew(&raw, &PoseTrack::stationary(robot), &Isometry3::identity()).unwrap();
        let p = leveled.points[0];
        assert!((p.z_m + 1.0).abs() < 1e-4, "z {}", p.z_m);
        assert!((p.r_m - 10.0).abs() < 1e-4 && p.phi_rad.abs() < 1e-4);
    }

    #[test]
    fn moving_sensor_origin_is_recorded_per_column() {
        let track = PoseTrack::new(vec![
            TimedPose {
                stamp_ns: 0,
                pose: pose(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            },
            TimedPose {
                stamp_ns: 1_000_000_000,
                pose: pose(1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            },
        ])
        .unwrap();
        let mut raw = Scan3d::default();
        for stamp in [0, 1_000_000_000] {
            raw.begin_column(stamp);
            raw.push_xyz(4.0, 0.0, 0.0);
        }
        let leveled = deskew(&raw, &track, &Isometry3::identity()).unwrap();
        assert_eq!(leveled.columns[1].origin_xy_m, [1.0, 0.0]);
        let end = leveled_xyz(&leveled.points[1], leveled.columns[1].origin_xy_m);
        assert!((end.x - 5.0).abs() < 1e-5);
    }
}
