//! The GPS fix model, one home for the robot and the mapper: a fix as the receiver gives it,
//! carried to a node by dead reckoning (on the robot), then turned into an observation of the
//! node's scan frame with its lever arm leveled by roll and pitch (in the mapper).
//!
//! A fix is usually older than the scan it goes with (a 1 Hz receiver, a node every few
//! seconds). The robot folds its motion between the fix and the scan's start into the
//! antenna offset ([`carry_antenna_to_node`]): the antenna where it was at the fix's time, in
//! the robot frame at the scan's start. The fix itself is unchanged.

use crate::geodesy::{GeoDatum, Geodetic};
use crate::se2::Pose2;
use nalgebra::{Isometry3, Matrix2, Matrix3, Point3, UnitQuaternion, Vector2, Vector3};

/// Quality of a fix, worst to best (as `levelmap.v1.FixStatus`, `sensor_msgs/NavSatStatus`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FixStatus {
    /// Not set by the sender: taken as no fix.
    Unspecified,
    /// The receiver has no position.
    NoFix,
    /// Autonomous single-point fix (metres).
    Fix,
    /// Differential (SBAS or DGPS).
    Dgps,
    /// RTK with float ambiguities (decimetres).
    RtkFloat,
    /// RTK with fixed ambiguities (centimetres).
    RtkFixed,
}

impl FixStatus {
    /// Standard deviation (m) of a fix of this status that carries no covariance; `None`
    /// when the status says there is no position.
    pub fn default_sigma_m(self) -> Option<f64> {
        match self {
            FixStatus::Unspecified | FixStatus::NoFix => None,
            FixStatus::Fix => Some(3.0),
            FixStatus::Dgps => Some(1.0),
            FixStatus::RtkFloat => Some(0.3),
            FixStatus::RtkFixed => Some(0.03),
        }
    }
}

/// One fix of the robot's antenna, as a node carries it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsFix {
    /// When the receiver measured it (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// WGS84 position of the antenna.
    pub position: Geodetic,
    /// Covariance of the position (m²), east-north-up at the fix; `None`: unknown (the
    /// status's default applies).
    pub covariance_m2: Option<Matrix3<f64>>,
    /// The receiver's kind of solution.
    pub status: FixStatus,
    /// The antenna in the robot frame at the node's scan start (m): see the module docs.
    pub antenna_offset_m: Vector3<f64>,
}

/// Where the antenna, mounted at `antenna_in_robot_m`, was at a fix's time, in the robot
/// frame at the scan's start: dead reckoning (`odometry_at_fix`, `odometry_at_scan`, both in
/// the odometry frame) carries the fix to the node.
pub fn carry_antenna_to_node(
    antenna_in_robot_m: &Vector3<f64>,
    odometry_at_fix: &Isometry3<f64>,
    odometry_at_scan: &Isometry3<f64>,
) -> Vector3<f64> {
    let antenna_at_fix = odometry_at_fix * Point3::from(*antenna_in_robot_m);
    (odometry_at_scan.inverse() * antenna_at_fix).coords
}

/// The horizontal lever arm, in the scan frame `scan_origin` (robot planar frame), of an
/// antenna at `offset_m` in the tilted robot frame whose attitude is `attitude` and planar
/// heading `heading_rad`: roll and pitch lean the mast (on a 10° slope a 1 m mast leans
/// 0.17 m).
pub fn leveled_lever_arm(
    offset_m: &Vector3<f64>,
    attitude: &UnitQuaternion<f64>,
    heading_rad: f64,
    scan_origin: &Pose2,
) -> Vector2<f64> {
    let heading = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading_rad);
    let leveled = heading.inverse() * (attitude * offset_m);
    let lever = scan_origin
        .inverse()
        .transform_point([leveled.x, leveled.y]);
    Vector2::new(lever[0], lever[1])
}

/// A fix as an observation of a node's scan frame, in the map's east-north frame around
/// `datum`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsObservation {
    /// Antenna position east and north of the datum (m).
    pub position_m: Vector2<f64>,
    /// Its covariance (m²), from the fix.
    pub covariance_m2: Matrix2<f64>,
    /// The antenna in the scan's frame (m). For a fix older than the scan, where the antenna
    /// was at the fix's time in the scan's frame (dead reckoning carries the fix to the scan).
    pub lever_arm_m: Vector2<f64>,
}

impl GpsFix {
    /// Whether the fix carries a position: a status with one, or a covariance.
    pub fn has_position(&self) -> bool {
        !matches!(self.status, FixStatus::NoFix)
            && (self.covariance_m2.is_some() || self.status.default_sigma_m().is_some())
    }

    /// The horizontal covariance (m²): the fix's own, else the status's default; `None`
    /// without a position.
    pub fn horizontal_covariance_m2(&self) -> Option<Matrix2<f64>> {
        if !self.has_position() {
            return None;
        }
        Some(match &self.covariance_m2 {
            Some(c) => c.fixed_view::<2, 2>(0, 0).into_owned(),
            None => {
                let s = self.status.default_sigma_m()?;
                Matrix2::identity() * (s * s)
            }
        })
    }

    /// The fix as an observation of the scan frame `scan_origin` (in the robot's planar
    /// frame) of a robot whose odometry attitude at the scan's start is `attitude` and planar
    /// heading `heading_rad`. The antenna offset is in the tilted robot frame: roll and pitch
    /// turn it into the horizontal lever arm (on a 10° slope a 1 m mast leans 0.17 m). `None`
    /// for a fix without position.
    pub fn observation(
        &self,
        datum: &GeoDatum,
        attitude: &UnitQuaternion<f64>,
        heading_rad: f64,
        scan_origin: &Pose2,
    ) -> Option<GpsObservation> {
        let covariance_m2 = self.horizontal_covariance_m2()?;
        let enu = datum.geodetic_to_enu(&self.position);
        Some(GpsObservation {
            position_m: Vector2::new(enu.x, enu.y),
            covariance_m2,
            lever_arm_m: leveled_lever_arm(
                &self.antenna_offset_m,
                attitude,
                heading_rad,
                scan_origin,
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Translation3;

    fn fix(status: FixStatus, covariance_m2: Option<Matrix3<f64>>) -> GpsFix {
        GpsFix {
            stamp_ns: 0,
            position: Geodetic {
                latitude_deg: 52.0,
                longitude_deg: 9.0,
                height_m: 60.0,
            },
            covariance_m2,
            status,
            antenna_offset_m: Vector3::new(0.0, 0.0, 1.0),
        }
    }

    #[test]
    fn a_fix_without_covariance_takes_its_status_default_and_no_fix_is_no_observation() {
        let c = |s| fix(s, None).horizontal_covariance_m2().map(|m| m[(0, 0)]);
        assert_eq!(c(FixStatus::Fix), Some(9.0));
        assert_eq!(c(FixStatus::RtkFixed), Some(0.03 * 0.03));
        assert_eq!(c(FixStatus::NoFix), None);
        assert_eq!(c(FixStatus::Unspecified), None);
        // A covariance gives a position even when the status does not say which kind.
        let own = fix(FixStatus::Unspecified, Some(Matrix3::identity() * 4.0));
        assert_eq!(
            own.horizontal_covariance_m2(),
            Some(Matrix2::identity() * 4.0)
        );
        // NO_FIX is no position, whatever the covariance says.
        assert!(!fix(FixStatus::NoFix, Some(Matrix3::identity())).has_position());
    }

    #[test]
    fn the_lever_arm_is_leveled_by_roll_and_pitch() {
        let f = fix(FixStatus::Fix, None);
        let datum = GeoDatum { origin: f.position };
        // Pitched 10° nose down, heading north: a 1 m mast leans forward by sin 10°.
        let attitude = UnitQuaternion::from_euler_angles(0.0, 10f64.to_radians(), 0.0);
        let heading = std::f64::consts::FRAC_PI_2;
        let attitude = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading) * attitude;
        let obs = f
            .observation(&datum, &attitude, heading, &Pose2::IDENTITY)
            .unwrap();
        assert!((obs.lever_arm_m.x - 10f64.to_radians().sin()).abs() < 1e-12);
        assert!(obs.lever_arm_m.y.abs() < 1e-12);
        assert!(obs.position_m.norm() < 1e-9);
        // In a scan frame 0.5 m ahead of the robot, the antenna is 0.5 m further back.
        let origin = Pose2::new(0.5, 0.0, 0.0);
        let obs2 = f.observation(&datum, &attitude, heading, &origin).unwrap();
        assert!((obs2.lever_arm_m.x - (obs.lever_arm_m.x - 0.5)).abs() < 1e-12);
    }

    #[test]
    fn dead_reckoning_carries_the_antenna_to_the_scan_start() {
        // Driving east at 1 m/s, the antenna 0.5 m behind: a fix 3 s before the scan was
        // taken 3.5 m behind the robot at the scan.
        let at = |x: f64| Isometry3::from_parts(Translation3::new(x, 0.0, 0.0), Default::default());
        let offset = carry_antenna_to_node(&Vector3::new(-0.5, 0.0, 1.0), &at(1.0), &at(4.0));
        assert!((offset - Vector3::new(-3.5, 0.0, 1.0)).norm() < 1e-12);
    }
}
