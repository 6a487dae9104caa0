//! A horizontal 2D laser scanner fixed to the chassis: what a classic 2D SLAM robot sees.

use crate::world::{SurfaceKind, World};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

/// A planar scanner bolted to the robot: its plane tilts with the robot on a slope.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedScanner2d {
    /// Number of beams, evenly spread over `fov_deg`.
    pub beams: usize,
    /// Opening angle, centred forward (degrees).
    pub fov_deg: f64,
    /// Farther surfaces give no return (m).
    pub max_range_m: f64,
    /// The scanner frame in the robot frame (scan plane = its x–y plane).
    pub mount: Isometry3<f64>,
}

impl Default for FixedScanner2d {
    /// 541 beams over 270° (0.5° apart), 40 m, 0.3 m forward and 1 m above the ground with
    /// the default body (0.7 m above the robot frame's origin).
    fn default() -> Self {
        FixedScanner2d {
            beams: 541,
            fov_deg: 270.0,
            max_range_m: 40.0,
            mount: Isometry3::from_parts(
                Translation3::new(0.3, 0.0, 0.7),
                UnitQuaternion::identity(),
            ),
        }
    }
}

/// One beam of a 2D scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Beam2d {
    /// Bearing in the scanner frame (rad, counter-clockwise from forward).
    pub bearing_rad: f64,
    /// Measured range (m); `None`: no return within range.
    pub range_m: Option<f64>,
    /// What the beam hit (ground truth).
    pub kind: Option<SurfaceKind>,
}

impl FixedScanner2d {
    /// Bearing of beam `i` (rad).
    pub fn bearing_rad(&self, i: usize) -> f64 {
        let fov = self.fov_deg.to_radians();
        let step = if self.beams > 1 {
            fov / (self.beams - 1) as f64
        } else {
            0.0
        };
        -0.5 * fov + step * i as f64
    }

    /// One noise-free scan from the robot at `robot_pose` (robot frame in the world).
    pub fn scan(&self, world: &World, robot_pose: &Isometry3<f64>) -> Vec<Beam2d> {
        let sensor = robot_pose * self.mount;
        let origin = sensor.translation.vector.into();
        (0..self.beams)
            .map(|i| {
                let bearing = self.bearing_rad(i);
                let local = Vector3::new(bearing.cos(), bearing.sin(), 0.0);
                let dir = Unit::new_unchecked(sensor.rotation * local);
                let hit = world.raycast(&origin, &dir, self.max_range_m);
                Beam2d {
                    bearing_rad: bearing,
                    range_m: hit.map(|h| h.range_m),
                    kind: hit.map(|h| h.kind),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::RobotBody;

    #[test]
    fn sees_the_test_wall_ahead_on_flat_ground() {
        let world = World::park();
        let wall = world.places().test_wall;
        let pose = RobotBody::default().pose_on(&world, -5.0, -50.0, 0.0);
        let scan = FixedScanner2d::default().scan(&world, &pose);
        assert_eq!(scan.len(), 541);
        let ahead = &scan[270];
        assert!(ahead.bearing_rad.abs() < 1e-12);
        assert_eq!(ahead.kind, Some(SurfaceKind::Wall));
        // The wall crosses y = −50 at its centre line; the scanner is 0.3 m ahead of the robot.
        let crossing_x = wall.a_m.x
            + (wall.b_m.x - wall.a_m.x) * (-50.0 - wall.a_m.y) / (wall.b_m.y - wall.a_m.y);
        let face = crossing_x - 0.5 * wall.thickness_m * std::f64::consts::SQRT_2;
        let range = ahead.range_m.expect("wall in range");
        assert!(
            (range - (face - (-5.0 + 0.3))).abs() < 0.01,
            "range {range}"
        );
    }
}
