//! KITTI odometry files: `poses.txt` (12 numbers a line: a 3 × 4 row-major [R|t], m),
//! `times.txt` (s, one a line) and `calib.txt`'s `Tr:` line (Velodyne → cam0).
//!
//! KITTI's poses are cam0's (x right, y down, z forward) in the frame of cam0 at frame 0.
//! With `Tr` they become the Velodyne's poses in the frame of the Velodyne at frame 0,
//! `Tr⁻¹ · P · Tr`, which is levelmap's frame (x forward, y left, z up). Without it the poses
//! are taken as the sensor's own (as the Ouster SDK's KITTI-format poses are).

use crate::LoadError;
use leveling::nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use std::path::Path;

/// Parses a KITTI pose file (`path` names it in errors).
pub fn parse_poses(text: &str, path: &Path) -> Result<Vec<Isometry3<f64>>, LoadError> {
    let mut poses = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let v = numbers(line, path, n)?;
        if v.len() != 12 {
            return Err(LoadError::Line {
                path: path.to_owned(),
                line: n + 1,
                message: format!(
                    "expected 12 numbers (3 × 4 row-major [R|t]), got {}",
                    v.len()
                ),
            });
        }
        poses.push(isometry(&v));
    }
    if poses.is_empty() {
        return Err(LoadError::Empty {
            path: path.to_owned(),
        });
    }
    Ok(poses)
}

/// Parses a KITTI `times.txt` (s) (`path` names it in errors).
pub fn parse_times(text: &str, path: &Path) -> Result<Vec<f64>, LoadError> {
    let mut times = Vec::new();
    for (n, line) in text.lines().enumerate() {
        match numbers(line, path, n)?.as_slice() {
            [] => {}
            [t] if *t >= 0.0 && times.last().is_none_or(|last| t >= last) => times.push(*t),
            other => {
                return Err(LoadError::Line {
                    path: path.to_owned(),
                    line: n + 1,
                    message: format!("expected one time (s), not before the last: {other:?}"),
                });
            }
        }
    }
    if times.is_empty() {
        return Err(LoadError::Empty {
            path: path.to_owned(),
        });
    }
    Ok(times)
}

/// The `Tr:` line of a KITTI `calib.txt`: the Velodyne's pose in cam0's frame.
pub fn parse_calib_tr(text: &str, path: &Path) -> Result<Isometry3<f64>, LoadError> {
    for (n, line) in text.lines().enumerate() {
        if let Some(rest) = line.trim_start().strip_prefix("Tr:") {
            let v = numbers(rest, path, n)?;
            if v.len() != 12 {
                return Err(LoadError::Line {
                    path: path.to_owned(),
                    line: n + 1,
                    message: format!("Tr: expected 12 numbers, got {}", v.len()),
                });
            }
            return Ok(isometry(&v));
        }
    }
    Err(LoadError::invalid(path, "no `Tr:` line (Velodyne → cam0)"))
}

/// Camera poses to Velodyne poses: `Tr⁻¹ · P · Tr`.
pub fn velodyne_poses(camera: &[Isometry3<f64>], tr: &Isometry3<f64>) -> Vec<Isometry3<f64>> {
    let inverse = tr.inverse();
    camera.iter().map(|p| inverse * p * tr).collect()
}

/// Reads a text file with `parse`.
pub fn load<T>(
    path: &Path,
    parse: impl Fn(&str, &Path) -> Result<T, LoadError>,
) -> Result<T, LoadError> {
    let bytes = crate::read_nonempty(path)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| LoadError::invalid(path, format!("not text: {e}")))?;
    parse(text, path)
}

fn numbers(line: &str, path: &Path, n: usize) -> Result<Vec<f64>, LoadError> {
    line.split_whitespace()
        .map(|f| match f.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(LoadError::Line {
                path: path.to_owned(),
                line: n + 1,
                message: format!("{f:?} is not a finite number"),
            }),
        })
        .collect()
}

/// A 3 × 4 row-major [R|t] as an isometry (R made orthonormal: the files carry 7 digits).
fn isometry(v: &[f64]) -> Isometry3<f64> {
    let m = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
    let rotation = Rotation3::from_matrix(&m);
    Isometry3::from_parts(
        Translation3::from(Vector3::new(v[3], v[7], v[11])),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_poses_become_velodyne_poses() {
        let path = Path::new("poses.txt");
        // cam0 one metre forward (+z) at frame 1.
        let text = "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1\n";
        let poses = parse_poses(text, path).unwrap();
        // KITTI's Tr, rounded: Velodyne x → cam z, y → −x, z → −y.
        let tr = parse_calib_tr("P0: 1\nTr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n", path).unwrap();
        let velo = velodyne_poses(&poses, &tr);
        assert!((velo[1].translation.vector - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        assert!(velo[1].rotation.angle() < 1e-12);
    }

    #[test]
    fn bad_lines_are_errors_naming_file_and_line() {
        let path = Path::new("poses.txt");
        let e = parse_poses("1 0 0 0 0 1 0 0 0 0 1 0\n1 2 3\n", path).unwrap_err();
        assert!(
            e.to_string().starts_with("poses.txt: line 2: expected 12"),
            "{e}"
        );
        assert!(parse_poses("1 0 0 0 0 1 0 0 0 0 1 nan\n", path).is_err());
        assert!(parse_poses("\n", path).is_err());
        let times = Path::new("times.txt");
        assert_eq!(parse_times("0\n0.1\n", times).unwrap(), vec![0.0, 0.1]);
        let e = parse_times("0.2\n0.1\n", times).unwrap_err();
        assert!(e.to_string().starts_with("times.txt: line 2"), "{e}");
        assert!(parse_calib_tr("P0: 1 2\n", path).is_err());
    }
}
