//! Trajectories as TUM text (`timestamp x y z qx qy qz qw`, one pose a line), the format evo
//! and the TUM RGB-D tools read. Planar poses: z is 0 and the orientation a yaw quaternion.

use crate::EncodeError;
use slam::Pose2;
use std::fmt::Write as _;

/// The header comment of [`to_tum`] (evo and the TUM tools skip `#` lines).
pub const TUM_HEADER: &str = "# timestamp x y z qx qy qz qw";

/// TUM text of `(timestamp_s, pose)` pairs, in the given order: the header line, then per
/// pose seconds with 9 decimals (nanoseconds, as ROS stamps), metres with 6 (µm), the
/// quaternion with 9.
pub fn to_tum(poses: impl IntoIterator<Item = (f64, Pose2)>) -> Result<String, EncodeError> {
    let poses = poses.into_iter();
    let mut s = String::with_capacity(poses.size_hint().0 * 72 + TUM_HEADER.len() + 1);
    s.push_str(TUM_HEADER);
    s.push('\n');
    for (index, (t, p)) in poses.enumerate() {
        if !(t.is_finite() && p.is_finite()) {
            return Err(EncodeError::NonFinitePose { index });
        }
        let (qz, qw) = (0.5 * p.theta).sin_cos();
        let _ = writeln!(s, "{t:.9} {:.6} {:.6} 0 0 0 {qz:.9} {qw:.9}", p.x, p.y);
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tum_lines_have_eight_fields_and_a_yaw_quaternion() {
        let text = to_tum([
            (12.345_678_901, Pose2::new(1.5, -2.25, 0.0)),
            (
                1_234_567_890.5,
                Pose2::new(0.0, 1e-7, std::f64::consts::FRAC_PI_2),
            ),
        ])
        .unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], TUM_HEADER);
        assert_eq!(
            lines[1],
            "12.345678901 1.500000 -2.250000 0 0 0 0.000000000 1.000000000"
        );
        assert_eq!(
            lines[2],
            "1234567890.500000000 0.000000 0.000000 0 0 0 0.707106781 0.707106781"
        );
        // Every line: 8 numbers, a unit quaternion whose yaw is the pose's heading.
        for line in &lines[1..] {
            let v: Vec<f64> = line.split(' ').map(|f| f.parse().unwrap()).collect();
            assert_eq!(v.len(), 8);
            let norm = v[4..].iter().map(|q| q * q).sum::<f64>();
            assert!((norm - 1.0).abs() < 1e-8);
        }
    }

    #[test]
    fn non_finite_poses_are_errors() {
        let err = to_tum([
            (0.0, Pose2::IDENTITY),
            (1.0, Pose2::new(f64::NAN, 0.0, 0.0)),
        ])
        .unwrap_err();
        assert!(matches!(err, EncodeError::NonFinitePose { index: 1 }));
        assert_eq!(to_tum([]).unwrap(), format!("{TUM_HEADER}\n"));
    }
}
