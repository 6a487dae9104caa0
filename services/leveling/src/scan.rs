//! The organized 3D scan: vertical base scans (columns) of bottom-up points (paper eq. 2.1).

use serde::{Deserialize, Serialize};

/// One point of a vertical base scan in cylindrical coordinates (paper eq. 2.1).
///
/// `r_m` is the horizontal distance from the vertical axis through the column's sensor origin
/// ([`Column::origin_xy_m`]), `phi_rad` the azimuth in the scan frame, `z_m` the height along
/// the scan frame's z axis. An invalid return (no echo, NaN, out of range) keeps its slot so
/// that the bottom-up order is kept; it is stored as [`CylPoint::INVALID`] (`r_m == 0`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CylPoint {
    /// Horizontal distance from the column's vertical sensor axis (m); 0 for an invalid return.
    pub r_m: f32,
    /// Azimuth in the scan frame (rad, counter-clockwise from x forward).
    pub phi_rad: f32,
    /// Height along the scan frame's z axis (m).
    pub z_m: f32,
}

impl CylPoint {
    /// The placeholder of a return that carries no measurement.
    pub const INVALID: CylPoint = CylPoint {
        r_m: 0.0,
        phi_rad: 0.0,
        z_m: 0.0,
    };

    /// Cylindrical point of a Cartesian one (x forward, y left, z up); invalid if not finite.
    pub fn from_xyz(x: f32, y: f32, z: f32) -> CylPoint {
        let r = (x * x + y * y).sqrt();
        if !(r.is_finite() && z.is_finite()) || r <= 0.0 {
            return CylPoint::INVALID;
        }
        CylPoint {
            r_m: r,
            phi_rad: y.atan2(x),
            z_m: z,
        }
    }

    /// True for a real measurement: finite and off the axis.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.r_m > 0.0 && self.r_m.is_finite() && self.z_m.is_finite() && self.phi_rad.is_finite()
    }

    /// Cartesian coordinates relative to the column's sensor axis.
    pub fn to_xyz(&self) -> [f32; 3] {
        let (s, c) = self.phi_rad.sin_cos();
        [self.r_m * c, self.r_m * s, self.z_m]
    }

    /// Elevation angle seen from the sensor origin (rad), for bottom-up ordering.
    pub fn elevation_rad(&self) -> f32 {
        self.z_m.atan2(self.r_m)
    }
}

/// One vertical base scan: a run of points in [`Scan3d::points`], ordered bottom-up.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Column {
    /// Index of the column's first (lowest) point in [`Scan3d::points`].
    pub start: u32,
    /// Number of points, invalid ones included.
    pub len: u32,
    /// Time the column was measured (ns, same clock as the odometry).
    pub stamp_ns: u64,
    /// Horizontal position of the column's sensor axis in the scan frame (m). Zero for a scan
    /// taken standing still; after motion compensation, where the sensor was when the column
    /// was measured, seen from the robot at scan start.
    pub origin_xy_m: [f32; 2],
}

/// An organized 3D scan: `columns` index contiguous, bottom-up runs of `points`.
///
/// The frame is the sensor frame as loaded (x forward, y left, z up), or the leveled frame
/// after [`crate::deskew()`]: origin at the sensor at scan start, z along gravity.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Scan3d {
    /// Every column's points, column after column, each column bottom-up.
    pub points: Vec<CylPoint>,
    /// The columns (vertical base scans), in measurement order.
    pub columns: Vec<Column>,
}

impl Scan3d {
    /// An empty scan with room for `columns` × `points_per_column` points.
    pub fn with_capacity(columns: usize, points_per_column: usize) -> Scan3d {
        Scan3d {
            points: Vec::with_capacity(columns * points_per_column),
            columns: Vec::with_capacity(columns),
        }
    }

    /// Starts a new column measured at `stamp_ns`; following `push_*` calls fill it bottom-up.
    pub fn begin_column(&mut self, stamp_ns: u64) {
        self.columns.push(Column {
            start: self.points.len() as u32,
            len: 0,
            stamp_ns,
            origin_xy_m: [0.0, 0.0],
        });
    }

    /// Appends a Cartesian point (sensor frame, m) to the current column; non-finite → invalid.
    pub fn push_xyz(&mut self, x: f32, y: f32, z: f32) {
        self.push(CylPoint::from_xyz(x, y, z));
    }

    /// Appends an invalid return (no echo) to the current column, keeping its slot.
    pub fn push_invalid(&mut self) {
        self.push(CylPoint::INVALID);
    }

    /// Appends a point to the current column.
    ///
    /// # Panics
    /// If no column was begun: a programming error, not a data error.
    pub fn push(&mut self, point: CylPoint) {
        let column = self.columns.last_mut().expect("push before begin_column");
        column.len += 1;
        self.points.push(point);
    }

    /// The points of column `index`, bottom-up.
    #[inline]
    pub fn column_points(&self, index: usize) -> &[CylPoint] {
        let c = &self.columns[index];
        &self.points[c.start as usize..(c.start + c.len) as usize]
    }

    /// Number of points with a measurement.
    pub fn valid_points(&self) -> usize {
        self.points.iter().filter(|p| p.is_valid()).count()
    }

    /// Checks that every column lies within `points` (true of every scan built with
    /// [`Scan3d::begin_column`]; a scan read from a file must be checked).
    pub fn check_columns(&self) -> Result<(), String> {
        for (i, c) in self.columns.iter().enumerate() {
            let end = c.start as u64 + c.len as u64;
            if end > self.points.len() as u64 {
                return Err(format!(
                    "column {i} spans points {}..{end} of {}",
                    c.start,
                    self.points.len()
                ));
            }
        }
        Ok(())
    }

    /// Time of the first column (ns), or 0 for an empty scan.
    pub fn start_stamp_ns(&self) -> u64 {
        self.columns.iter().map(|c| c.stamp_ns).min().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_points_keep_their_slot_as_invalid() {
        let mut scan = Scan3d::default();
        scan.begin_column(5);
        scan.push_xyz(1.0, 0.0, -1.0);
        scan.push_xyz(f32::NAN, 0.0, 0.0);
        scan.push_invalid();
        scan.push_xyz(0.0, 2.0, 1.0);
        let column = scan.column_points(0);
        assert_eq!(column.len(), 4);
        assert!(column[0].is_valid() && column[3].is_valid());
        assert!(!column[1].is_valid() && !column[2].is_valid());
        assert!((column[3].phi_rad - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert_eq!(scan.valid_points(), 2);
    }

    #[test]
    fn columns_beyond_the_points_are_reported() {
        let mut scan = Scan3d::default();
        scan.begin_column(0);
        scan.push_xyz(1.0, 0.0, 0.0);
        assert!(scan.check_columns().is_ok());
        scan.columns[0].len = 2;
        assert_eq!(
            scan.check_columns(),
            Err("column 0 spans points 0..2 of 1".to_string())
        );
    }

    #[test]
    fn cartesian_round_trip() {
        let p = CylPoint::from_xyz(3.0, -4.0, 0.5);
        let [x, y, z] = p.to_xyz();
        assert!((x - 3.0).abs() < 1e-5 && (y + 4.0).abs() < 1e-5 && z == 0.5);
        assert!((p.r_m - 5.0).abs() < 1e-6);
    }
}
