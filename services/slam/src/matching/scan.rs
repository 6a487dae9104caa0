//! A 2D range scan as scan matching sees it: its returns, ordered by bearing.

use super::MatchError;
use crate::wrap_angle;

/// The returns of one 2D range scan in its scanner frame (x forward, y left; m), sorted by
/// bearing in (−π, π]. Bearings need not be uniform: a leveled scan drops the columns that
/// have no landmark, and its columns need not be evenly spaced. Beams without a return are
/// not kept; a gap in bearing is how matching sees them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scan2 {
    points: Vec<[f64; 2]>,
    bearings_rad: Vec<f64>,
    ranges_m: Vec<f64>,
}

impl Scan2 {
    /// A scan from its beams: `bearings_rad[i]` (counter-clockwise from x) and `ranges_m[i]`.
    /// A beam is a return when both are finite and `0 < range < max_range_m`; every other
    /// beam (no return, NaN, the sensor's max-range code) is dropped. Fails only when the
    /// two slices differ in length.
    pub fn from_polar(
        bearings_rad: &[f32],
        ranges_m: &[f32],
        max_range_m: f32,
    ) -> Result<Scan2, MatchError> {
        if bearings_rad.len() != ranges_m.len() {
            return Err(MatchError::LengthMismatch {
                bearings: bearings_rad.len(),
                ranges: ranges_m.len(),
            });
        }
        let mut beams: Vec<(f64, f64)> = bearings_rad
            .iter()
            .zip(ranges_m)
            .filter(|(b, r)| b.is_finite() && r.is_finite() && **r > 0.0 && **r < max_range_m)
            .map(|(&b, &r)| (wrap_angle(f64::from(b)), f64::from(r)))
            .collect();
        beams.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(Scan2 {
            points: beams
                .iter()
                .map(|&(b, r)| [r * b.cos(), r * b.sin()])
                .collect(),
            bearings_rad: beams.iter().map(|&(b, _)| b).collect(),
            ranges_m: beams.iter().map(|&(_, r)| r).collect(),
        })
    }

    /// Number of returns.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when the scan has no return.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The returns as points in the scanner frame (m), in bearing order.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Bearing of each return (rad, in (−π, π], ascending).
    pub fn bearings_rad(&self) -> &[f64] {
        &self.bearings_rad
    }

    /// Range of each return (m).
    pub fn ranges_m(&self) -> &[f64] {
        &self.ranges_m
    }
}

/// Its returns, for what takes any set of points in a scanner's frame (the correlative
/// search takes one scan or several scans gathered into one frame).
impl AsRef<[[f64; 2]]> for Scan2 {
    fn as_ref(&self) -> &[[f64; 2]] {
        &self.points
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_returns_only_sorted_by_bearing() {
        let bearings = [0.5, -0.5, 3.5, 0.0, 1.0];
        let ranges = [2.0, 1.0, 3.0, f32::NAN, 80.0];
        let scan = Scan2::from_polar(&bearings, &ranges, 50.0).expect("same lengths");
        assert_eq!(scan.len(), 3);
        // 3.5 rad wraps to 3.5 − 2π ≈ −2.78, the smallest bearing.
        assert!((scan.bearings_rad()[0] - (3.5 - std::f64::consts::TAU)).abs() < 1e-6);
        assert_eq!(scan.ranges_m(), &[3.0, 1.0, 2.0]);
        let [x, y] = scan.points()[2];
        assert!((x - 2.0 * 0.5f64.cos()).abs() < 1e-6 && (y - 2.0 * 0.5f64.sin()).abs() < 1e-6);
    }

    #[test]
    fn length_mismatch_is_an_error() {
        let err = Scan2::from_polar(&[0.0, 0.1], &[1.0], 10.0).unwrap_err();
        assert_eq!(
            err,
            MatchError::LengthMismatch {
                bearings: 2,
                ranges: 1
            }
        );
    }
}
