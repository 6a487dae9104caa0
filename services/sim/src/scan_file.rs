//! levelmap simulator scans: a [`SimScanFile`] as JSON (written by `levelmap simulate`),
//! with the dead-reckoning track over the scan and ground truth per point. Read into
//! scanio's [`LoadedScan`] like the real formats; here rather than in scanio so that the
//! readers of real scans need no simulator.

use crate::{SimScanFile, SurfaceKind};
use scanio::{LoadError, LoadedScan, read_nonempty};
use std::path::Path;

/// Reads and checks a simulator scan; returns it ready to level, with per-point truth.
pub fn load(path: &Path) -> Result<(LoadedScan, Vec<Option<SurfaceKind>>), LoadError> {
    let bytes = read_nonempty(path)?;
    let file: SimScanFile = serde_json::from_slice(&bytes)
        .map_err(|e| LoadError::invalid(path, format!("not a levelmap simulator scan: {e}")))?;
    into_loaded(file).map_err(|message| LoadError::invalid(path, message))
}

/// A simulator scan, checked, as a scan ready to level, with its per-point truth.
pub fn into_loaded(file: SimScanFile) -> Result<(LoadedScan, Vec<Option<SurfaceKind>>), String> {
    file.raw.check_columns()?;
    file.validate().map_err(|e| e.to_string())?;
    let track = file.track().map_err(|e| e.to_string())?;
    let file_index = (0..file.raw.points.len() as u32).collect();
    let loaded = LoadedScan {
        raw: file.raw,
        track,
        sensor_in_robot: file.sensor_in_robot,
        file_index,
    };
    Ok((loaded, file.truth))
}

/// Writes a simulator scan as JSON.
pub fn save(path: &Path, file: &SimScanFile) -> Result<(), LoadError> {
    let json = serde_json::to_vec(file).map_err(|e| LoadError::invalid(path, e.to_string()))?;
    std::fs::write(path, json).map_err(|source| LoadError::Io {
        path: path.to_owned(),
        error: source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_scan_track_and_truth() {
        let file = crate::scenario::wall_drive_scan(3, 1.4);
        let path =
            std::env::temp_dir().join(format!("levelmap-simfile-{}.json", std::process::id()));
        save(&path, &file).unwrap();
        let (loaded, truth) = load(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(loaded.raw, file.raw);
        assert_eq!(truth, file.truth);
        assert_eq!(loaded.track.samples(), &file.odometry[..]);
        assert_eq!(loaded.sensor_in_robot, file.sensor_in_robot);
    }

    #[test]
    fn foreign_json_is_refused_with_the_file_name() {
        let path =
            std::env::temp_dir().join(format!("levelmap-simfile-bad-{}.json", std::process::id()));
        std::fs::write(&path, br#"{"format":"something-else"}"#).unwrap();
        let err = load(&path).unwrap_err().to_string();
        std::fs::remove_file(&path).ok();
        assert!(
            err.contains("levelmap-simfile-bad") && err.contains("simulator scan"),
            "{err}"
        );
    }
}
