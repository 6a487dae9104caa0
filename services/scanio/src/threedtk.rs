//! 3DTK `.3d` scans from a nodding SICK 2D scanner (Kurt3D style), the paper's kind of sensor.
//!
//! A file is `lines × 360` points `x y z` in cm in 3DTK's left-handed frame (x right, y up,
//! z forward), one nodding line after the other, bottom line first. Taking index j of every
//! line gives a bottom-up vertical column (360 columns). A `.pose` file beside it (position in
//! cm, then Euler angles θx θy θz in degrees, R = Rx·Ry·Rz as 3DTK's `EulerToMatrix4`) gives
//! the robot's attitude, from which roll and pitch are levelled out.

use crate::{LoadError, LoadedScan, read_nonempty};
use leveling::nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use leveling::{PoseTrack, Scan3d};
use std::path::Path;

/// Points per nodding line (one 180° SICK fan at 0.5°).
pub const POINTS_PER_LINE: usize = 360;

/// The SICK's "no echo" value (cm): returns at or beyond it carry no measurement.
pub const NO_ECHO_CM: f64 = 3276.0;

/// 3DTK frame (x right, y up, z forward) → levelmap frame (x forward, y left, z up).
fn to_robot_frame(v: [f64; 3]) -> Vector3<f64> {
    Vector3::new(v[2], -v[0], v[1])
}

/// Reads `FILE.3d` and, when present, `FILE.pose` beside it (identity otherwise).
pub fn load(path: &Path) -> Result<LoadedScan, LoadError> {
    let mut scan = parse(&read_nonempty(path)?, path)?;
    if let Some(pose) = load_pose(&path.with_extension("pose"))? {
        scan.track = PoseTrack::stationary(pose);
    }
    Ok(scan)
}

/// Parses the bytes of a `.3d` file (`path` names it in errors) into a scan of a standing
/// robot at the identity pose; [`load`] puts it at its `.pose`.
pub fn parse(bytes: &[u8], path: &Path) -> Result<LoadedScan, LoadError> {
    if bytes.is_empty() {
        return Err(LoadError::Empty {
            path: path.to_owned(),
        });
    }
    let text = std::str::from_utf8(bytes)
        .map_err(|e| LoadError::invalid(path, format!("not text: {e}")))?;
    let mut xyz_cm = Vec::with_capacity(text.len() / 24);
    for (n, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        let parsed: Result<Vec<f64>, _> = fields.iter().map(|f| f.parse::<f64>()).collect();
        match parsed {
            Ok(v) if v.len() >= 3 => xyz_cm.push([v[0], v[1], v[2]]),
            // 3DTK allows a resolution header in the first line.
            _ if n == 0 => continue,
            _ => {
                return Err(LoadError::Line {
                    path: path.to_owned(),
                    line: n + 1,
                    message: format!("expected `x y z` in cm, got {line:?}"),
                });
            }
        }
    }
    if xyz_cm.is_empty() || xyz_cm.len() % POINTS_PER_LINE != 0 {
        return Err(LoadError::invalid(
            path,
            format!(
                "{} points is not a whole number of {POINTS_PER_LINE}-point scan lines",
                xyz_cm.len()
            ),
        ));
    }
    let lines = xyz_cm.len() / POINTS_PER_LINE;
    let mut raw = Scan3d::with_capacity(POINTS_PER_LINE, lines);
    let mut file_index = Vec::with_capacity(xyz_cm.len());
    for j in 0..POINTS_PER_LINE {
        raw.begin_column(0);
        for k in 0..lines {
            let i = k * POINTS_PER_LINE + j;
            let p = xyz_cm[i];
            let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            if range >= NO_ECHO_CM || range <= 0.0 {
                raw.push_invalid();
            } else {
                let v = to_robot_frame(p) / 100.0;
                raw.push_xyz(v.x as f32, v.y as f32, v.z as f32);
            }
            file_index.push(i as u32);
        }
    }
    Ok(LoadedScan {
        raw,
        track: PoseTrack::stationary(Isometry3::identity()),
        sensor_in_robot: Isometry3::identity(),
        file_index,
    })
}

/// Reads a 3DTK `.pose` file as the robot pose in levelmap's frame (m); `None` if absent.
pub fn load_pose(path: &Path) -> Result<Option<Isometry3<f64>>, LoadError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => {
            return Err(LoadError::Io {
                path: path.to_owned(),
                error: source,
            });
        }
    };
    parse_pose(&text, path).map(Some)
}

/// Parses the text of a `.pose` file (`path` names it in errors) as [`load_pose`].
pub fn parse_pose(text: &str, path: &Path) -> Result<Isometry3<f64>, LoadError> {
    let numbers: Result<Vec<f64>, _> = text.split_whitespace().map(|f| f.parse::<f64>()).collect();
    let numbers =
        numbers.map_err(|e| LoadError::invalid(path, format!("expected 6 numbers: {e}")))?;
    if numbers.len() != 6 || numbers.iter().any(|v| !v.is_finite()) {
        return Err(LoadError::invalid(
            path,
            format!(
                "expected 6 finite numbers (x y z cm, θx θy θz deg), got {}",
                numbers.len()
            ),
        ));
    }
    let [tx, ty, tz, ax, ay, az] = [
        numbers[0], numbers[1], numbers[2], numbers[3], numbers[4], numbers[5],
    ];
    let r = |axis: Vector3<f64>, deg: f64| {
        Rotation3::from_axis_angle(
            &leveling::nalgebra::Unit::new_normalize(axis),
            deg.to_radians(),
        )
    };
    // R in 3DTK coordinates, then the change of basis C (improper, so C·R·Cᵀ is proper).
    let r_3dtk = r(Vector3::x(), ax) * r(Vector3::y(), ay) * r(Vector3::z(), az);
    let c = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let rotation = Rotation3::from_matrix_unchecked(c * r_3dtk.matrix() * c.transpose());
    let t = to_robot_frame([tx, ty, tz]) / 100.0;
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_takes_whole_scan_lines_and_the_pose_its_six_numbers() {
        let path = Path::new("t.3d");
        // A resolution header, then two lines of 360 points; the first point has no echo.
        let mut text = String::from("W x H\n0 0 0\n");
        for i in 1..2 * POINTS_PER_LINE {
            text.push_str(&format!("{} 10 500\n", i % 90));
        }
        let scan = parse(text.as_bytes(), path).unwrap();
        assert_eq!(scan.raw.columns.len(), POINTS_PER_LINE);
        assert_eq!(scan.raw.column_points(0).len(), 2);
        assert!(!scan.raw.points[0].is_valid());
        // (0, 10, 500) cm: 5 m ahead, 0.1 m up.
        let p = scan.raw.column_points(0)[1].to_xyz();
        assert!(
            (p[0] - 5.0).abs() < 1e-6 && (p[2] - 0.1).abs() < 1e-6,
            "{p:?}"
        );
        assert!(matches!(
            parse(b"1 2 3\n", path),
            Err(LoadError::Invalid { .. })
        ));
        assert!(matches!(
            parse(b"1 2 3\nx\n", path),
            Err(LoadError::Line { line: 2, .. })
        ));

        let pose = parse_pose("100 0 -200 0 90 0", Path::new("t.pose")).unwrap();
        // 3DTK (x right, y up, z forward) cm → x forward, y left, z up m.
        assert!((pose.translation.vector - Vector3::new(-2.0, -1.0, 0.0)).norm() < 1e-12);
        for bad in ["1 2 3 4 5", "1 2 3 4 5 nan", "1 2 3 4 5 x"] {
            assert!(parse_pose(bad, Path::new("t.pose")).is_err(), "{bad}");
        }
    }
}
