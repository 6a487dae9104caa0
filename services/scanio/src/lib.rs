//! Readers for 3D scan files, turning each into the organized [`leveling::Scan3d`] the
//! leveling pipeline takes: KITTI Velodyne `.bin`, 3DTK `.3d` + `.pose` (nodding SICK) and
//! Ouster pcap captures with their metadata JSON (many scans a file); KITTI odometry
//! `poses.txt` / `times.txt`; plus SemanticKITTI `.label` files for scoring. The algorithms stay free of I/O. The
//! simulator's own JSON scans are read by `sim::scan_file` (the lab), with this crate's
//! [`LoadedScan`] and [`LoadError`], so that a robot's build needs no simulator.

pub mod cloud;
pub mod kitti;
pub mod labels;
pub mod odometry;
pub mod ouster;
pub mod pcap;
pub mod threedtk;

use leveling::nalgebra::Isometry3;
use leveling::{PoseTrack, Scan3d};
use std::path::{Path, PathBuf};

/// Why a scan file could not be read. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file cannot be read.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause, already in the message (not a chained source, so it prints once).
        error: std::io::Error,
    },
    /// The file holds nothing.
    #[error("{}: empty file", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// A binary file whose length is not a whole number of point records.
    #[error("{}: truncated: {len} bytes is not a multiple of the {point_bytes}-byte point record", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Its length (bytes).
        len: usize,
        /// The size of one point record (bytes).
        point_bytes: usize,
    },
    /// A text file with a line that cannot be read.
    #[error("{}: line {line}: {message}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// The line's number, from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// Contents that are not a scan.
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl LoadError {
    /// An `Invalid` error naming `path`.
    pub fn invalid(path: &Path, message: impl Into<String>) -> LoadError {
        LoadError::Invalid {
            path: path.to_owned(),
            message: message.into(),
        }
    }
}

/// A 3D scan as read from a file, ready for [`leveling::Leveler::level`].
#[derive(Clone, Debug)]
pub struct LoadedScan {
    /// The organized scan in the sensor frame (x forward, y left, z up; m).
    pub raw: Scan3d,
    /// Dead reckoning over the scan; stationary when the file has no motion data.
    pub track: PoseTrack,
    /// Sensor pose in the robot frame.
    pub sensor_in_robot: Isometry3<f64>,
    /// For every point of `raw`, its index in the file (to look up per-point labels).
    pub file_index: Vec<u32>,
}

/// Supported scan file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScanFormat {
    /// KITTI Velodyne `.bin`: little-endian float32 x y z reflectance per point.
    Kitti,
    /// 3DTK `.3d` text (cm, left-handed, y up) with an optional `.pose` beside it.
    ThreeDtk,
}

impl ScanFormat {
    /// The format a file name suggests: `.bin`, `.3d`.
    pub fn from_extension(path: &Path) -> Option<ScanFormat> {
        match path.extension()?.to_str()? {
            "bin" => Some(ScanFormat::Kitti),
            "3d" => Some(ScanFormat::ThreeDtk),
            _ => None,
        }
    }
}

/// Reads a scan file of the given format.
pub fn load(path: &Path, format: ScanFormat) -> Result<LoadedScan, LoadError> {
    match format {
        ScanFormat::Kitti => kitti::load(path, kitti::DEFAULT_COLUMNS),
        ScanFormat::ThreeDtk => threedtk::load(path),
    }
}

/// Reads a whole file, refusing a missing or empty one with an error naming it.
pub fn read_nonempty(path: &Path) -> Result<Vec<u8>, LoadError> {
    let bytes = std::fs::read(path).map_err(|source| LoadError::Io {
        path: path.to_owned(),
        error: source,
    })?;
    if bytes.is_empty() {
        return Err(LoadError::Empty {
            path: path.to_owned(),
        });
    }
    Ok(bytes)
}
