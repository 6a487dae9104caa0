//! `[source.files]`: scans from files: a folder of scan files, or one Ouster capture; with
//! KITTI-format poses as odometry and KITTI times as stamps when given.

use super::{Source, SourceEvent};
use crate::node::SensorScan;
use leveling::nalgebra::Isometry3;
use leveling::{PoseTrack, TimedPose};
use scanio::odometry;
use scanio::ouster::OusterScans;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Scan files in a folder, in name order: KITTI `.bin`, 3DTK `.3d` (with its `.pose`, the
/// odometry), levelmap simulator `.json` (with the `sim` feature); or, with `pcap`, every
/// complete frame of an Ouster capture. Without `times`, folder scans are stamped `period_s`
/// apart and capture frames by their column headers. A file that cannot be read is skipped
/// with a warning, never ends the run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilesSourceConfig {
    /// The folder of scan files, read in name order.
    pub folder: PathBuf,
    /// Time between scans (s), when neither `times` nor the capture gives it.
    pub period_s: f64,
    /// An Ouster capture (pcap) read instead of the folder.
    pub pcap: Option<PathBuf>,
    /// The capture's sensor metadata JSON (required with `pcap`).
    pub ouster_meta: Option<PathBuf>,
    /// KITTI-format poses (3 × 4 row-major [R|t] a line), the odometry: a scan named
    /// `NNNNNN.bin` takes line NNNNNN, any other scan (and capture frames) its place in order.
    /// Unset: the folder's `poses.txt`, if any.
    pub poses: Option<PathBuf>,
    /// KITTI `times.txt` (s, one a line, numbered as `poses`): the scans' stamps, from the
    /// edge's start. Unset: the folder's `times.txt`, if any.
    pub times: Option<PathBuf>,
    /// KITTI `calib.txt` whose `Tr:` (Velodyne → cam0) turns cam0 poses into the Velodyne's.
    /// Unset: the folder's `calib.txt`, if any; none: the poses are the sensor's own.
    pub calib: Option<PathBuf>,
}

impl Default for FilesSourceConfig {
    fn default() -> Self {
        FilesSourceConfig {
            folder: "scans".into(),
            period_s: 1.0,
            pcap: None,
            ouster_meta: None,
            poses: None,
            times: None,
            calib: None,
        }
    }
}

/// Where the scans come from.
enum Scans {
    Folder(std::vec::IntoIter<(PathBuf, FileFormat)>),
    Ouster(Box<OusterScans>, PathBuf),
}

/// See [`FilesSourceConfig`].
pub struct FilesSource {
    scans: Scans,
    epoch_ns: u64,
    period_ns: u64,
    /// Scans read so far (the place of the next one).
    index: usize,
    poses: Option<Vec<Isometry3<f64>>>,
    times: Option<Vec<f64>>,
    /// The capture's first column time (sensor clock), the origin of its stamps.
    capture_start_ns: Option<u64>,
    pending_scan: Option<SensorScan>,
}

impl FilesSource {
    /// The scans of `config`; an error if the folder cannot be listed or has none, or a
    /// capture, metadata, poses, times or calibration file cannot be read.
    pub fn new(config: &FilesSourceConfig, epoch_ns: u64) -> anyhow::Result<FilesSource> {
        let in_folder = |given: &Option<PathBuf>, name: &str| -> Option<PathBuf> {
            given.clone().or_else(|| {
                let path = config.folder.join(name);
                (config.pcap.is_none() && path.is_file()).then_some(path)
            })
        };
        let scans = match &config.pcap {
            Some(pcap) => {
                let Some(meta) = &config.ouster_meta else {
                    anyhow::bail!(
                        "{}: [source.files] pcap needs ouster_meta (the sensor's metadata JSON)",
                        pcap.display()
                    );
                };
                Scans::Ouster(Box::new(OusterScans::open(pcap, meta)?), pcap.clone())
            }
            None => Scans::Folder(folder_files(&config.folder)?.into_iter()),
        };
        let mut poses = in_folder(&config.poses, "poses.txt")
            .map(|p| odometry::load(&p, odometry::parse_poses))
            .transpose()?;
        if let (Some(cam), Some(calib)) = (&poses, in_folder(&config.calib, "calib.txt")) {
            let tr = odometry::load(&calib, odometry::parse_calib_tr)?;
            poses = Some(odometry::velodyne_poses(cam, &tr));
        }
        let times = in_folder(&config.times, "times.txt")
            .map(|p| odometry::load(&p, odometry::parse_times))
            .transpose()?;
        Ok(FilesSource {
            scans,
            epoch_ns,
            period_ns: (config.period_s.max(1e-3) * 1e9) as u64,
            index: 0,
            poses,
            times,
            capture_start_ns: None,
            pending_scan: None,
        })
    }

    /// The next readable scan and its number in the poses and times files.
    fn next_loaded(&mut self) -> Option<(scanio::LoadedScan, usize, bool)> {
        match &mut self.scans {
            Scans::Folder(files) => {
                for (path, format) in files.by_ref() {
                    match format.load(&path) {
                        Ok(loaded) => {
                            self.index += 1;
                            let number = kitti_number(&path).unwrap_or(self.index - 1);
                            return Some((loaded, number, false));
                        }
                        Err(e) => tracing::warn!("scan skipped: {e}"),
                    }
                }
                None
            }
            Scans::Ouster(scans, pcap) => match scans.next_scan() {
                Some((_, loaded)) => {
                    self.index += 1;
                    Some((loaded, self.index - 1, true))
                }
                None => {
                    for w in scans.report().warnings(pcap) {
                        tracing::warn!("{w}");
                    }
                    None
                }
            },
        }
    }
}

impl Source for FilesSource {
    fn next_event(&mut self) -> Option<SourceEvent> {
        if let Some(scan) = self.pending_scan.take() {
            return Some(SourceEvent::Scan(Box::new(scan)));
        }
        loop {
            let (loaded, number, timed_columns) = self.next_loaded()?;
            let pose = match &self.poses {
                Some(poses) => match poses.get(number) {
                    Some(p) => *p,
                    None => {
                        tracing::warn!(
                            "scan {number} skipped: the poses file has {} lines",
                            poses.len()
                        );
                        continue;
                    }
                },
                // The file's pose (3DTK) or the origin.
                None => loaded.track.samples()[0].pose,
            };
            let mut raw = loaded.raw;
            let first_column_ns = raw.start_stamp_ns();
            let stamp_ns = match (&self.times, timed_columns) {
                (Some(times), _) => match times.get(number) {
                    Some(t) => self.epoch_ns + (t * 1e9) as u64,
                    None => {
                        tracing::warn!(
                            "scan {number} skipped: the times file has {} lines",
                            times.len()
                        );
                        continue;
                    }
                },
                (None, true) => {
                    let start = *self.capture_start_ns.get_or_insert(first_column_ns);
                    self.epoch_ns + first_column_ns.saturating_sub(start)
                }
                (None, false) => self.epoch_ns + (self.index as u64 - 1) * self.period_ns,
            };
            for column in &mut raw.columns {
                // A capture keeps its columns' times within the frame; files have none.
                let within = if timed_columns {
                    column.stamp_ns - first_column_ns
                } else {
                    0
                };
                column.stamp_ns = stamp_ns + within;
            }
            // One pose, standing still during the scan.
            self.pending_scan = Some(SensorScan {
                raw,
                track: PoseTrack::stationary(pose),
                sensor_in_robot: loaded.sensor_in_robot,
                gps: Vec::new(),
            });
            return Some(SourceEvent::Odometry(TimedPose { stamp_ns, pose }));
        }
    }
}

/// KITTI names a scan by its frame number (`000042.bin`).
fn kitti_number(path: &Path) -> Option<usize> {
    let stem = path.file_stem()?.to_str()?;
    (!stem.is_empty() && stem.bytes().all(|b| b.is_ascii_digit())).then(|| stem.parse().ok())?
}

fn folder_files(folder: &Path) -> anyhow::Result<Vec<(PathBuf, FileFormat)>> {
    let mut files: Vec<_> = std::fs::read_dir(folder)
        .map_err(|e| anyhow::anyhow!("{}: {e}", folder.display()))?
        .filter_map(|entry| {
            let path = entry.ok()?.path();
            let format = FileFormat::of(&path)?;
            Some((path, format))
        })
        .collect();
    files.sort_by(|a, b| a.0.cmp(&b.0));
    anyhow::ensure!(
        !files.is_empty(),
        "{}: no scan files ({}; an Ouster capture is read with `pcap =`)",
        folder.display(),
        FileFormat::EXTENSIONS
    );
    Ok(files)
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

    fn of(path: &Path) -> Option<FileFormat> {
        #[cfg(feature = "sim")]
        if path.extension().is_some_and(|e| e == "json") {
            return Some(FileFormat::Sim);
        }
        scanio::ScanFormat::from_extension(path).map(FileFormat::Scan)
    }

    fn load(self, path: &Path) -> Result<scanio::LoadedScan, scanio::LoadError> {
        match self {
            FileFormat::Scan(format) => scanio::load(path, format),
            #[cfg(feature = "sim")]
            FileFormat::Sim => ::sim::scan_file::load(path).map(|(scan, _truth)| scan),
        }
    }
}

#[cfg(test)]
mod tests;
