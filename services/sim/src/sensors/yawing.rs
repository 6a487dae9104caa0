//! The yawing 3D scanner of the paper: a vertical 2D base scan turned about the upright axis.

use crate::rng::Rng;
use crate::world::{SurfaceKind, World};
use leveling::Scan3d;
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

/// A vertical fan of beams (bottom-up) turned step by step about the sensor's z axis.
///
/// Sensor frame: x forward at azimuth 0, y left, z along the turning axis. The sweep runs
/// counter-clockwise (right to left) from −`horizontal_fov_deg`/2 to +`horizontal_fov_deg`/2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YawingScanner {
    /// Vertical base scans per 3D scan.
    pub columns: usize,
    /// Beams per base scan.
    pub points_per_column: usize,
    /// Opening angle of the turn, centred forward (degrees).
    pub horizontal_fov_deg: f64,
    /// Opening angle of the base scan (degrees).
    pub vertical_fov_deg: f64,
    /// Elevation of the lowest beam (degrees; the highest is this + `vertical_fov_deg`).
    pub min_elevation_deg: f64,
    /// Time for one 3D scan (s); the columns are spread evenly over it.
    pub scan_duration_s: f64,
    /// Standard deviation of the range noise (m).
    pub range_noise_m: f64,
    /// Farther surfaces give no return (m).
    pub max_range_m: f64,
    /// The sensor frame in the robot frame.
    pub mount: Isometry3<f64>,
}

impl Default for YawingScanner {
    /// The paper's sensor: 270° × 100° in 4 s, 270 × 100 = 27,000 points; mounted 0.2 m
    /// forward and 0.9 m up on the robot (1.2 m above the ground with the default body).
    fn default() -> Self {
        YawingScanner {
            columns: 270,
            points_per_column: 100,
            horizontal_fov_deg: 270.0,
            vertical_fov_deg: 100.0,
            min_elevation_deg: -60.0,
            scan_duration_s: 4.0,
            range_noise_m: 0.01,
            max_range_m: 40.0,
            mount: Isometry3::from_parts(
                Translation3::new(0.2, 0.0, 0.9),
                UnitQuaternion::identity(),
            ),
        }
    }
}

/// One simulated 3D scan with its ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct SimScan {
    /// The organized scan in the sensor frame: columns in sweep order, stamped with the time
    /// each was measured, points bottom-up; no return → an invalid slot.
    pub raw: Scan3d,
    /// What each point of `raw` hit, same order; `None` for no return.
    pub truth: Vec<Option<SurfaceKind>>,
    /// The robot's true pose (robot frame in the world frame) at the scan's first column.
    pub truth_start_pose: Isometry3<f64>,
}

impl YawingScanner {
    /// Azimuth of column `i` in the sensor frame (rad).
    pub fn column_azimuth_rad(&self, i: usize) -> f64 {
        let fov = self.horizontal_fov_deg.to_radians();
        let step = if self.columns > 1 {
            fov / (self.columns - 1) as f64
        } else {
            0.0
        };
        -0.5 * fov + step * i as f64
    }

    /// Elevation of beam `j` of a column (rad), bottom-up.
    pub fn beam_elevation_rad(&self, j: usize) -> f64 {
        let step = if self.points_per_column > 1 {
            self.vertical_fov_deg / (self.points_per_column - 1) as f64
        } else {
            0.0
        };
        (self.min_elevation_deg + step * j as f64).to_radians()
    }

    /// Time column `i` is measured (ns) in a scan started at `start_ns`.
    pub fn column_stamp_ns(&self, start_ns: u64, i: usize) -> u64 {
        let duration_ns = self.scan_duration_s * 1e9;
        start_ns + (duration_ns * i as f64 / self.columns.max(1) as f64) as u64
    }

    /// Time of the last column (ns) of a scan started at `start_ns`: the dead-reckoning
    /// track must reach at least this far.
    pub fn end_stamp_ns(&self, start_ns: u64) -> u64 {
        self.column_stamp_ns(start_ns, self.columns.saturating_sub(1))
    }

    /// Scans `world` from a robot moving along `truth` (robot pose in the world at a time),
    /// starting at `start_ns`; `rng` draws the range noise.
    pub fn scan(
        &self,
        world: &World,
        truth: &impl Fn(u64) -> Isometry3<f64>,
        start_ns: u64,
        rng: &mut Rng,
    ) -> SimScan {
        let mut raw = Scan3d::with_capacity(self.columns, self.points_per_column);
        let mut kinds = Vec::with_capacity(self.columns * self.points_per_column);
        // Beam directions in the sensor frame do not depend on time: compute them once.
        let elevations: Vec<(f64, f64)> = (0..self.points_per_column)
            .map(|j| self.beam_elevation_rad(j).sin_cos())
            .collect();
        for i in 0..self.columns {
            let stamp = self.column_stamp_ns(start_ns, i);
            // The column is measured from where the robot really is at this instant.
            let sensor = truth(stamp) * self.mount;
            let origin = sensor.translation.vector.into();
            let (sin_az, cos_az) = self.column_azimuth_rad(i).sin_cos();
            raw.begin_column(stamp);
            for &(sin_el, cos_el) in &elevations {
                let local = Vector3::new(cos_el * cos_az, cos_el * sin_az, sin_el);
                let dir = Unit::new_unchecked(sensor.rotation * local);
                let hit = world.raycast(&origin, &dir, self.max_range_m);
                // Noise is drawn for every beam, so a seed's noise does not depend on the scene.
                let noise = rng.gauss(self.range_noise_m);
                match hit.filter(|h| h.range_m + noise > 0.0) {
                    Some(hit) => {
                        let range = hit.range_m + noise;
                        let p = local * range;
                        raw.push_xyz(p.x as f32, p.y as f32, p.z as f32);
                        kinds.push(Some(hit.kind));
                    }
                    None => {
                        raw.push_invalid();
                        kinds.push(None);
                    }
                }
            }
        }
        SimScan {
            raw,
            truth: kinds,
            truth_start_pose: truth(start_ns),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::RobotBody;

    #[test]
    fn geometry_of_the_default_scanner() {
        let s = YawingScanner::default();
        assert_eq!(s.columns * s.points_per_column, 27_000);
        assert!((s.column_azimuth_rad(0).to_degrees() + 135.0).abs() < 1e-9);
        assert!((s.column_azimuth_rad(269).to_degrees() - 135.0).abs() < 1e-9);
        assert!((s.beam_elevation_rad(0).to_degrees() + 60.0).abs() < 1e-9);
        assert!((s.beam_elevation_rad(99).to_degrees() - 40.0).abs() < 1e-9);
        assert_eq!(s.column_stamp_ns(10, 0), 10);
        assert!(s.end_stamp_ns(0) < 4_000_000_000 && s.end_stamp_ns(0) > 3_980_000_000);
    }

    #[test]
    fn a_standing_scan_is_organized_and_true() {
        let world = World::park();
        let pose = RobotBody::default().pose_on(&world, -5.0, -50.0, 0.0);
        let scanner = YawingScanner {
            range_noise_m: 0.0,
            ..Default::default()
        };
        let scan = scanner.scan(&world, &|_| pose, 1_000, &mut Rng::new(1));
        assert_eq!(scan.raw.columns.len(), 270);
        assert_eq!(scan.raw.points.len(), 27_000);
        assert_eq!(scan.truth.len(), 27_000);
        assert!(
            scan.raw
                .columns
                .windows(2)
                .all(|w| w[0].stamp_ns < w[1].stamp_ns)
        );
        for (p, kind) in scan.raw.points.iter().zip(&scan.truth) {
            assert_eq!(p.is_valid(), kind.is_some());
        }
        // Every valid point, moved to the world, lies on what it claims to have hit: for
        // terrain, on the height field.
        let sensor = pose * scanner.mount;
        let mut terrain = 0;
        for (p, kind) in scan.raw.points.iter().zip(&scan.truth) {
            if *kind == Some(SurfaceKind::Terrain) {
                let [x, y, z] = p.to_xyz();
                let w = sensor * nalgebra::Point3::new(x as f64, y as f64, z as f64);
                assert!((w.z - world.ground_height_m(w.x, w.y)).abs() < 0.01);
                terrain += 1;
            }
        }
        assert!(terrain > 5_000, "{terrain} terrain points");
        // Bottom-up: elevation rises within each column.
        for c in 0..scan.raw.columns.len() {
            let valid: Vec<f32> = scan
                .raw
                .column_points(c)
                .iter()
                .filter(|p| p.is_valid())
                .map(|p| p.elevation_rad())
                .collect();
            assert!(valid.windows(2).all(|w| w[0] < w[1]));
        }
    }
}
