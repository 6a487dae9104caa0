//! Where an edge service's measurements come from: events in time order, each stamped in ns
//! since the Unix epoch.

use crate::node::SensorScan;
use leveling::TimedPose;
use serde::{Deserialize, Serialize};

mod files;
mod mcap;
pub mod ros;
mod ros2;
pub use self::files::{FilesSource, FilesSourceConfig};
pub use self::mcap::{McapSource, McapSourceConfig};
pub use self::ros2::{Ros2Source, Ros2SourceConfig};

// The simulated robot: only with the `sim` feature (the lab, not a robot's build).
#[cfg(feature = "sim")]
mod sim;
#[cfg(feature = "sim")]
pub use self::sim::{SimSource, park, sim_gps_reading};

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

/// Yields measurements in time order; `None` at the end.
pub trait Source: Send {
    /// The next measurement in time order; `None` once the source is done.
    fn next_event(&mut self) -> Option<SourceEvent>;
}

/// The simulated robot of the park (see `sim::FleetRobot`). Parsed in every build, so that
/// a build without the `sim` feature can refuse it by name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimSourceConfig {
    /// Which of the park's loops the robot drives (0, 1 or 2).
    pub loop_index: usize,
    /// Seed of the sensors' noise.
    pub seed: u64,
    /// How long the robot drives (s).
    pub duration_s: f64,
    /// Start at a random place along the loop (from `seed`), with odometry from the
    /// identity, so the mapper does not know where the robot is; otherwise at the loop's
    /// start with odometry in the park's frame.
    pub scattered_start: bool,
    /// Send the simulated GPS receiver's fixes.
    pub gps: bool,
}

impl Default for SimSourceConfig {
    fn default() -> Self {
        SimSourceConfig {
            loop_index: 0,
            seed: 7,
            duration_s: 120.0,
            scattered_start: false,
            gps: true,
        }
    }
}
