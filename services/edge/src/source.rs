//! Where an edge service's measurements come from: events in time order, each stamped in ns
//! since the Unix epoch.

use crate::node::SensorScan;
use leveling::{PoseTrack, TimedPose};
use serde::{Deserialize, Serialize};

mod mcap;
pub mod ros;
mod ros2;
pub use self::mcap::{McapSource, McapSourceConfig};
pub use self::ros2::{KeyStyle, Ros2Source, Ros2SourceConfig, dds_type_name, topic_key};

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

/// Scan files in a folder, in name order: KITTI `.bin`, 3DTK `.3d` (with its `.pose`, the
/// odometry), levelmap simulator `.json` (with the `sim` feature). Files carry no time:
/// scans are stamped `period_s` apart. A file that cannot be read is skipped with a warning, never ends the run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilesSourceConfig {
    /// The folder of scan files, read in name order.
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
    files: std::vec::IntoIter<(std::path::PathBuf, FileFormat)>,
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
                let format = FileFormat::of(&path)?;
                Some((path, format))
            })
            .collect();
        files.sort_by(|a, b| a.0.cmp(&b.0));
        anyhow::ensure!(
            !files.is_empty(),
            "{}: no scan files ({})",
            config.folder.display(),
            FileFormat::EXTENSIONS
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
            let loaded = match format.load(&path) {
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

/// A scan file's format: scanio's real formats, and the simulator's JSON with `sim`.
#[derive(Clone, Copy, Debug)]
enum FileFormat {
    Scan(scanio::ScanFormat),
    #[cfg(feature = "sim")]
    Sim,
}

impl FileFormat {
    #[cfg(feature = "sim")]
    const EXTENSIONS: &str = ".bin, .3d, .json";
    #[cfg(not(feature = "sim"))]
    const EXTENSIONS: &str = ".bin, .3d";

    fn of(path: &std::path::Path) -> Option<FileFormat> {
        #[cfg(feature = "sim")]
        if path.extension().is_some_and(|e| e == "json") {
            return Some(FileFormat::Sim);
        }
        scanio::ScanFormat::from_extension(path).map(FileFormat::Scan)
    }

    fn load(self, path: &std::path::Path) -> Result<scanio::LoadedScan, scanio::LoadError> {
        match self {
            FileFormat::Scan(format) => scanio::load(path, format),
            #[cfg(feature = "sim")]
            FileFormat::Sim => ::sim::scan_file::load(path).map(|(scan, _truth)| scan),
        }
    }
}
