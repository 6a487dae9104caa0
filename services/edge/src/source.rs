//! Where an edge service's measurements come from: events in time order, each stamped in ns
//! since the Unix epoch.

use crate::node::{GpsReading, SensorScan};
use leveling::{PoseTrack, TimedPose};
use serde::{Deserialize, Serialize};
use sim::{FleetRobot, PARK_DATUM, World};
use std::sync::OnceLock;

/// One measurement of a source.
#[derive(Clone, Debug)]
pub enum SourceEvent {
    /// Live dead reckoning.
    Odometry(TimedPose),
    /// A complete 3D scan (available at its last column's time).
    Scan(Box<SensorScan>),
}

impl SourceEvent {
    /// When the event is available.
    pub fn stamp_ns(&self) -> u64 {
        match self {
            SourceEvent::Odometry(p) => p.stamp_ns,
            SourceEvent::Scan(s) => s.raw.columns.last().map_or(0, |c| c.stamp_ns),
        }
    }
}

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

/// Yields measurements in time order; `None` at the end.
pub trait Source: Send {
    fn next_event(&mut self) -> Option<SourceEvent>;
}

/// The simulated robot of the park (see `sim::FleetRobot`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimSourceConfig {
    /// Which of the park's loops the robot drives (0, 1 or 2).
    pub loop_index: usize,
    /// Seed of the sensors' noise.
    pub seed: u64,
    /// How long the robot drives (s).
    pub duration_s: f64,
}

impl Default for SimSourceConfig {
    fn default() -> Self {
        SimSourceConfig {
            loop_index: 0,
            seed: 7,
            duration_s: 120.0,
        }
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
}

impl SimSource {
    pub fn new(config: &SimSourceConfig, epoch_ns: u64, odometry_rate_hz: f64) -> Option<Self> {
        let duration_ns = (config.duration_s.max(0.0) * 1e9) as u64;
        Some(SimSource {
            robot: FleetRobot::new(park(), config.loop_index, duration_ns, config.seed)?,
            epoch_ns,
            odometry_period_ns: (1e9 / odometry_rate_hz.max(0.1)) as u64,
            queue: Vec::new(),
            next_odometry_ns: 0,
        })
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

/// Scan files in a folder, in name order: KITTI `.bin`, 3DTK `.3d` (with its `.pose`, the
/// odometry), levelmap simulator `.json`. Files carry no time: scans are stamped `period_s`
/// apart. A file that cannot be read is skipped with a warning, never ends the run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilesSourceConfig {
    pub folder: std::path::PathBuf,
    /// Time between scans (s).
    pub period_s: f64,
}

impl Default for FilesSourceConfig {
    fn default() -> Self {
        FilesSourceConfig {
            folder: "scans".into(),
            period_s: 1.0,
        }
    }
}

/// See [`FilesSourceConfig`].
pub struct FilesSource {
    files: std::vec::IntoIter<(std::path::PathBuf, scanio::ScanFormat)>,
    epoch_ns: u64,
    period_ns: u64,
    index: u64,
    pending_scan: Option<SensorScan>,
}

impl FilesSource {
    /// The scan files of `config.folder`; an error if it cannot be listed or has none.
    pub fn new(config: &FilesSourceConfig, epoch_ns: u64) -> anyhow::Result<FilesSource> {
        let mut files: Vec<_> = std::fs::read_dir(&config.folder)
            .map_err(|e| anyhow::anyhow!("{}: {e}", config.folder.display()))?
            .filter_map(|entry| {
                let path = entry.ok()?.path();
                let format = scanio::ScanFormat::from_extension(&path)?;
                Some((path, format))
            })
            .collect();
        files.sort_by(|a, b| a.0.cmp(&b.0));
        anyhow::ensure!(
            !files.is_empty(),
            "{}: no scan files (.bin, .3d, .json)",
            config.folder.display()
        );
        Ok(FilesSource {
            files: files.into_iter(),
            epoch_ns,
            period_ns: (config.period_s.max(1e-3) * 1e9) as u64,
            index: 0,
            pending_scan: None,
        })
    }
}

impl Source for FilesSource {
    fn next_event(&mut self) -> Option<SourceEvent> {
        if let Some(scan) = self.pending_scan.take() {
            return Some(SourceEvent::Scan(Box::new(scan)));
        }
        for (path, format) in self.files.by_ref() {
            let loaded = match scanio::load(&path, format) {
                Ok(l) => l,
                Err(e) => {
                    tracing::warn!("scan skipped: {e}");
                    continue;
                }
            };
            let stamp_ns = self.epoch_ns + self.index * self.period_ns;
            self.index += 1;
            let mut raw = loaded.raw;
            for column in &mut raw.columns {
                column.stamp_ns = stamp_ns;
            }
            // The file's pose (3DTK) or the origin: one pose, standing still during the scan.
            let pose = loaded.track.samples()[0].pose;
            self.pending_scan = Some(SensorScan {
                raw,
                track: PoseTrack::stationary(pose),
                sensor_in_robot: loaded.sensor_in_robot,
                gps: Vec::new(),
            });
            return Some(SourceEvent::Odometry(TimedPose { stamp_ns, pose }));
        }
        None
    }
}
