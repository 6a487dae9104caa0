//! Ready-made scans of the park with ground truth, for tests and the CLI.
//!
//! Every scenario is deterministic for a seed. Scans start at [`SCAN_START_NS`]; the robot
//! is already under way then (constant speed, no acceleration).

use crate::rng::Rng;
use crate::robot::{RobotBody, Route};
use crate::sensors::{Beam2d, DeadReckoning, FixedScanner2d, SimScan, YawingScanner};
use crate::world::{SurfaceKind, World};
use leveling::{DeskewError, PoseTrack, Scan3d, TimedPose};
use nalgebra::{Isometry3, Point2};
use serde::{Deserialize, Serialize};

/// Time at which every scenario's scan starts (ns).
pub const SCAN_START_NS: u64 = 1_000_000_000;
/// Fastest speed [`wall_drive_scan`] drives (m/s): its lane is 8 m long.
pub const WALL_DRIVE_MAX_SPEED_MPS: f64 = 2.0;
/// Speed of the robot in [`demo_scan`] (m/s).
pub const DEMO_SPEED_MPS: f64 = 1.0;

/// Random streams of a scenario seed, one per consumer.
const STREAM_SCANNER: u64 = 10;
const STREAM_ODOMETRY: u64 = 11;

/// A simulated 3D scan as the CLI stores it (JSON) and reads it back
/// (`levelmap level --format sim`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimScanFile {
    /// Always [`SimScanFile::FORMAT`].
    pub format: String,
    /// Always [`SimScanFile::VERSION`].
    pub version: u32,
    /// The 3D scanner's frame in the robot frame.
    pub sensor_in_robot: Isometry3<f64>,
    /// The scan in the sensor frame, columns stamped with their measurement time.
    pub raw: Scan3d,
    /// Dead reckoning covering every column's stamp (robot frame in the odometry frame).
    pub odometry: Vec<TimedPose>,
    /// Ground truth per point of `raw`, same order; `None` for no return.
    pub truth: Vec<Option<SurfaceKind>>,
}

/// Why a [`SimScanFile`] is not usable.
#[derive(Clone, Debug, PartialEq)]
pub enum SimFileError {
    /// `format` is not [`SimScanFile::FORMAT`] (the value found).
    Format(String),
    /// `version` is not [`SimScanFile::VERSION`] (the value found).
    Version(u32),
    /// `truth` does not have one entry per point.
    TruthLength {
        /// Points in `raw`.
        points: usize,
        /// Entries in `truth`.
        truth: usize,
    },
    /// The odometry is not a valid track or does not cover the columns.
    Odometry(DeskewError),
}

impl std::fmt::Display for SimFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimFileError::Format(found) => write!(
                f,
                "not a simulated scan: format is {found:?}, expected {:?}",
                SimScanFile::FORMAT
            ),
            SimFileError::Version(v) => write!(
                f,
                "simulated scan version {v} is not supported (expected {})",
                SimScanFile::VERSION
            ),
            SimFileError::TruthLength { points, truth } => {
                write!(f, "{truth} ground-truth entries for {points} points")
            }
            SimFileError::Odometry(e) => write!(f, "odometry: {e}"),
        }
    }
}

impl std::error::Error for SimFileError {}

impl SimScanFile {
    /// The `format` of every file.
    pub const FORMAT: &'static str = "levelmap-sim-scan";
    /// The `version` this code reads and writes.
    pub const VERSION: u32 = 1;

    /// A file of a simulated scan, with the scanner mount and the dead reckoning covering it.
    pub fn new(
        scan: SimScan,
        sensor_in_robot: Isometry3<f64>,
        odometry: Vec<TimedPose>,
    ) -> SimScanFile {
        SimScanFile {
            format: SimScanFile::FORMAT.to_owned(),
            version: SimScanFile::VERSION,
            sensor_in_robot,
            raw: scan.raw,
            odometry,
            truth: scan.truth,
        }
    }

    /// The odometry as a track for [`leveling::Leveler::level`].
    pub fn track(&self) -> Result<PoseTrack, DeskewError> {
        PoseTrack::new(self.odometry.clone())
    }

    /// Checks what a file read from outside must satisfy before leveling.
    pub fn validate(&self) -> Result<(), SimFileError> {
        if self.format != SimScanFile::FORMAT {
            return Err(SimFileError::Format(self.format.clone()));
        }
        if self.version != SimScanFile::VERSION {
            return Err(SimFileError::Version(self.version));
        }
        if self.truth.len() != self.raw.points.len() {
            return Err(SimFileError::TruthLength {
                points: self.raw.points.len(),
                truth: self.truth.len(),
            });
        }
        let track = self.track().map_err(SimFileError::Odometry)?;
        let (first, last) = match (self.odometry.first(), self.odometry.last()) {
            (Some(a), Some(b)) => (a.stamp_ns, b.stamp_ns),
            _ => return Err(SimFileError::Odometry(DeskewError::EmptyTrack)),
        };
        for (column, c) in self.raw.columns.iter().enumerate() {
            if track.at(c.stamp_ns).is_none() {
                return Err(SimFileError::Odometry(DeskewError::OutsideTrack {
                    column,
                    stamp_ns: c.stamp_ns,
                    first_ns: first,
                    last_ns: last,
                }));
            }
        }
        Ok(())
    }
}

/// Scans with the default sensors and packs the scan with its dead reckoning.
fn scan_file(world: &World, truth: &impl Fn(u64) -> Isometry3<f64>, seed: u64) -> SimScanFile {
    let scanner = YawingScanner::default();
    let scan = scanner.scan(
        world,
        truth,
        SCAN_START_NS,
        &mut Rng::stream(seed, STREAM_SCANNER),
    );
    let odometry = DeadReckoning::default().track(
        truth,
        SCAN_START_NS,
        scanner.end_stamp_ns(SCAN_START_NS),
        &mut Rng::stream(seed, STREAM_ODOMETRY),
    );
    SimScanFile::new(scan, scanner.mount, odometry)
}

/// A straight open route along `lane` that reaches the lane's start at [`SCAN_START_NS`].
fn lane_route(lane: [Point2<f64>; 2], speed_mps: f64) -> Route {
    let dir = (lane[1] - lane[0]).normalize();
    let lead_in = lane[0] - dir * (speed_mps * SCAN_START_NS as f64 * 1e-9);
    Route::open(vec![lead_in, lane[1]], speed_mps).expect("scenario lanes are valid routes")
}

/// The robot's pose in [`pavilion_hill_scan`]: standing at the foot of the pavilion hill,
/// about 17 m from the pavilion, facing it.
pub fn pavilion_hill_robot_pose(world: &World) -> Isometry3<f64> {
    let view = world.places().pavilion_view_m;
    let to = world.pavilion_center().xy() - view;
    RobotBody::default().pose_on(world, view.x, view.y, to.y.atan2(to.x))
}

/// The paper's figure 4: the robot standing at the foot of the pavilion hill, facing the
/// pavilion. Returns the 3D scan, and what the fixed 2D scanner sees from the same pose
/// (only the hill's slope in that direction).
pub fn pavilion_hill_scan(seed: u64) -> (SimScanFile, Vec<Beam2d>) {
    let world = World::park();
    let pose = pavilion_hill_robot_pose(&world);
    let file = scan_file(&world, &|_| pose, seed);
    let beams = FixedScanner2d::default().scan(&world, &pose);
    (file, beams)
}

/// The route of [`wall_drive_scan`] at `speed_mps` (clamped to [0, 2] m/s): straight
/// east over flat ground towards the test wall ([`crate::Places::test_wall`]), which
/// crosses the lane ahead at 45°.
pub fn wall_drive_route(world: &World, speed_mps: f64) -> Route {
    let speed = if speed_mps.is_finite() {
        speed_mps.clamp(0.0, WALL_DRIVE_MAX_SPEED_MPS)
    } else {
        0.0
    };
    lane_route(world.places().wall_drive_lane_m, speed)
}

/// A 4 s scan taken while driving at `speed_mps` (clamped to [0, 2] m/s) on flat ground
/// with a long straight wall ahead at 45°: uncompensated, the wall comes out bent.
pub fn wall_drive_scan(seed: u64, speed_mps: f64) -> SimScanFile {
    let world = World::park();
    let route = wall_drive_route(&world, speed_mps);
    scan_file(&world, &route.truth(&world), seed)
}

/// The route of [`demo_scan`]: driving slowly up the pavilion hill's east side.
pub fn demo_route(world: &World) -> Route {
    lane_route(world.places().demo_lane_m, DEMO_SPEED_MPS)
}

/// A representative scan for pictures: on the pavilion hill's side while driving, with
/// trees, the pavilion behind on the left and the bridge ahead on the right in view.
pub fn demo_scan(seed: u64) -> SimScanFile {
    let world = World::park();
    let route = demo_route(&world);
    scan_file(&world, &route.truth(&world), seed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_are_valid_and_deterministic() {
        let a = wall_drive_scan(3, 1.4);
        assert_eq!(a.validate(), Ok(()));
        assert_eq!(a.raw.points.len(), 27_000);
        assert_eq!(a, wall_drive_scan(3, 1.4));
        assert_ne!(a.raw, wall_drive_scan(4, 1.4).raw);
        let mut bad = a.clone();
        bad.truth.pop();
        assert!(matches!(
            bad.validate(),
            Err(SimFileError::TruthLength { .. })
        ));
        let mut bad = a.clone();
        bad.odometry.truncate(10);
        assert!(matches!(
            bad.validate(),
            Err(SimFileError::Odometry(DeskewError::OutsideTrack { .. }))
        ));
        bad.format = "other".into();
        assert!(matches!(bad.validate(), Err(SimFileError::Format(_))));
    }
}
