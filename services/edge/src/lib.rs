//! The onboard edge service of levelmap: every 3D scan is leveled (paper 2.1–3.2), a node is
//! started every few metres or degrees, committed to an on-disk outbox and published over
//! Zenoh until the mapper acks it; live odometry is published best effort.
//!
//! [`node`], [`cloud`] and [`source`] are pure; [`outbox`] is the disk; [`service`] is the thin
//! async shell; [`ros_out`] gives the map→odom transform back to the robot's ROS 2 stack.

pub mod cloud;
pub mod config;
pub mod node;
pub mod outbox;
pub mod ros_out;
pub mod service;
pub mod source;

pub use cloud::CloudParams;
pub use config::{EdgeConfig, SourceConfig};
pub use node::{GpsReading, NodeBuilder, NodeError, NodeParams, PlanarScan, SensorScan};
pub use outbox::{OUTBOX_FORMAT, Outbox, OutboxError};
pub use service::{EdgeReport, ResendBackoff, run};
pub use source::{
    FilesSource, FilesSourceConfig, McapSource, McapSourceConfig, Ros2Source, Ros2SourceConfig,
    SimSourceConfig, Source, SourceEvent,
};
#[cfg(feature = "sim")]
pub use source::{SimSource, park, sim_gps_reading};

/// The source a config names, with simulation time 0 at `epoch_ns`.
pub fn open_source(config: &EdgeConfig, epoch_ns: u64) -> anyhow::Result<Box<dyn Source>> {
    match &config.source {
        #[cfg(feature = "sim")]
        SourceConfig::Sim(sim) => SimSource::new(sim, epoch_ns, config.odometry_rate_hz)
            .map(|s| Box::new(s) as Box<dyn Source>)
            .ok_or_else(|| anyhow::anyhow!("sim source: the park has no loop {}", sim.loop_index)),
        // A robot's build has no simulator: say so rather than fail on a parse error.
        #[cfg(not(feature = "sim"))]
        SourceConfig::Sim(_) => anyhow::bail!(
            "[source.sim]: this levelmap was built without the simulator (feature `sim` of \
             edge, in levelmap's `lab` feature); use [source.files] or a build with it"
        ),
        SourceConfig::Files(files) => Ok(Box::new(FilesSource::new(files, epoch_ns)?)),
        SourceConfig::Mcap(mcap) => Ok(Box::new(McapSource::new(mcap)?)),
        SourceConfig::Ros2(ros2) => Ok(Box::new(Ros2Source::new(ros2)?)),
    }
}
