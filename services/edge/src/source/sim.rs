//! The simulated robot as a source (feature `sim`): the park's robots with their dead
//! reckoning, GPS and 3D scans, in simulation time shifted to the epoch.

use super::{SimSourceConfig, Source, SourceEvent};
use crate::node::{GpsReading, SensorScan};
use leveling::{PoseTrack, TimedPose};
use sim::{FleetRobot, FleetStart, PARK_DATUM, World};
use std::sync::OnceLock;

/// A simulated fix as a receiver reports it, with the dead reckoning at its time; stamps
/// shifted by `epoch_ns`.
pub fn sim_gps_reading(robot: &FleetRobot<'_>, fix: &sim::GpsFix, epoch_ns: u64) -> GpsReading {
    let geodetic = fix.geodetic(&PARK_DATUM);
    GpsReading {
        stamp_ns: fix.stamp_ns + epoch_ns,
        latitude_deg: geodetic.latitude_deg,
        longitude_deg: geodetic.longitude_deg,
        altitude_m: geodetic.height_m,
        sigma_horizontal_m: fix.sigma_horizontal_m,
        sigma_vertical_m: fix.sigma_vertical_m,
        status: slam::gnss::FixStatus::RtkFloat,
        antenna_in_robot_m: robot.gps().antenna_in_robot_m,
        odometry_at_fix: robot
            .odometry_track(fix.stamp_ns, fix.stamp_ns)
            .at(fix.stamp_ns)
            .expect("the track covers the fix"),
    }
}

/// The park, built once per process and shared by every simulated robot.
pub fn park() -> &'static World {
    static PARK: OnceLock<World> = OnceLock::new();
    PARK.get_or_init(World::park)
}

/// A simulated robot as a source: odometry at `odometry_rate_hz` and a 3D scan every 4 s,
/// simulation time 0 mapped to `epoch_ns`.
pub struct SimSource {
    robot: FleetRobot<'static>,
    epoch_ns: u64,
    odometry_period_ns: u64,
    /// Events of the current scan period, in time order, popped from the back.
    queue: Vec<SourceEvent>,
    next_odometry_ns: u64,
    gps: bool,
}

impl SimSource {
    /// The simulated robot of `config`, its clock shifted by `epoch_ns`, odometry at
    /// `odometry_rate_hz`; `None` when the park has no loop for it.
    pub fn new(config: &SimSourceConfig, epoch_ns: u64, odometry_rate_hz: f64) -> Option<Self> {
        let duration_ns = (config.duration_s.max(0.0) * 1e9) as u64;
        let start = if config.scattered_start {
            FleetStart::Scattered
        } else {
            FleetStart::Dock
        };
        Some(SimSource {
            robot: FleetRobot::starting(
                park(),
                config.loop_index,
                duration_ns,
                config.seed,
                start,
            )?,
            epoch_ns,
            odometry_period_ns: (1e9 / odometry_rate_hz.max(0.1)) as u64,
            queue: Vec::new(),
            next_odometry_ns: 0,
            gps: config.gps,
        })
    }

    /// The robot's true pose at `stamp_ns` (the source's clock): what the simulator's benches
    /// and tests check against; a real source has none.
    pub fn truth_at(&self, stamp_ns: u64) -> leveling::nalgebra::Isometry3<f64> {
        self.robot.truth_at(stamp_ns.saturating_sub(self.epoch_ns))
    }

    fn shift(&self, pose: TimedPose) -> TimedPose {
        TimedPose {
            stamp_ns: pose.stamp_ns + self.epoch_ns,
            pose: pose.pose,
        }
    }
}

impl Source for SimSource {
    fn next_event(&mut self) -> Option<SourceEvent> {
        if let Some(event) = self.queue.pop() {
            return Some(event);
        }
        let fleet_scan = self.robot.next_scan()?;
        let mut raw = fleet_scan.scan.raw;
        for column in &mut raw.columns {
            column.stamp_ns += self.epoch_ns;
        }
        let end_ns = raw.columns.last().map_or(0, |c| c.stamp_ns) - self.epoch_ns;
        let track = PoseTrack::new(
            fleet_scan
                .track
                .samples()
                .iter()
                .map(|p| self.shift(*p))
                .collect(),
        )
        .expect("the simulator's track is ordered");
        let gps = fleet_scan
            .gps_since_previous
            .iter()
            .filter(|_| self.gps)
            .map(|fix| sim_gps_reading(&self.robot, fix, self.epoch_ns))
            .collect();
        let scan = SensorScan {
            raw,
            track,
            sensor_in_robot: self.robot.scanner().mount,
            gps,
        };
        // Odometry up to the scan's end, then the scan; stored reversed for popping.
        let mut events = Vec::new();
        let from = self.next_odometry_ns;
        if end_ns >= from {
            let odometry = self.robot.odometry_track(from, end_ns);
            let mut t = from;
            while t <= end_ns {
                if let Some(pose) = odometry.at(t) {
                    events.push(SourceEvent::Odometry(
                        self.shift(TimedPose { stamp_ns: t, pose }),
                    ));
                }
                t += self.odometry_period_ns;
            }
            self.next_odometry_ns = t;
        }
        events.push(SourceEvent::Scan(Box::new(scan)));
        events.reverse();
        self.queue = events;
        self.queue.pop()
    }
}
