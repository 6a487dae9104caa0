//! Projection of the segmented cloud into the leveled range scan (paper 3.2, eq. 3.4).

use crate::deskew::leveled_xyz;
use crate::scan::Scan3d;
use serde::{Deserialize, Serialize};

/// One beam of a leveled range scan: the first landmark point of a column, bottom-up,
/// projected parallel onto the horizontal plane (eq. 3.4).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Beam {
    /// Bearing in the leveled frame at scan start (rad, counter-clockwise from x forward).
    pub bearing_rad: f32,
    /// Horizontal range from the sensor at scan start (m); `None`: the column has no landmark.
    pub range_m: Option<f32>,
}

/// The paper's leveled range scan L_i = (r_i, φ_i), one beam per column, in column order.
/// Bearings need not be uniform.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LeveledScan {
    /// Time of the scan's first column (ns); the scan's frame is the robot's at that time.
    pub stamp_ns: u64,
    /// One beam per column of the scan, in column order.
    pub beams: Vec<Beam>,
}

impl LeveledScan {
    /// Beams that carry a return.
    pub fn returns(&self) -> impl Iterator<Item = (f32, f32)> + '_ {
        self.beams
            .iter()
            .filter_map(|b| b.range_m.map(|r| (b.bearing_rad, r)))
    }

    /// Every beam as bearings (rad) and ranges (m, 0 = no return): the array form the wire,
    /// the HTTP API and map version files share.
    pub fn polar(&self) -> (Vec<f32>, Vec<f32>) {
        self.beams
            .iter()
            .map(|b| (b.bearing_rad, b.range_m.unwrap_or(0.0)))
            .unzip()
    }

    /// Number of beams with a return.
    pub fn return_count(&self) -> usize {
        self.beams.iter().filter(|b| b.range_m.is_some()).count()
    }
}

/// Builds the leveled range scan from each column's first landmark point (indices into
/// `scan.points`, as [`crate::Segmenter::segment`] returns them).
pub fn project(scan: &Scan3d, first_landmarks: &[Option<u32>]) -> LeveledScan {
    let beams = scan
        .columns
        .iter()
        .zip(first_landmarks)
        .map(|(column, first)| match first {
            Some(index) => {
                let point = &scan.points[*index as usize];
                if column.origin_xy_m == [0.0, 0.0] {
                    Beam {
                        bearing_rad: point.phi_rad,
                        range_m: Some(point.r_m),
                    }
                } else {
                    // Motion-compensated column: measure from the sensor at scan start.
                    let p = leveled_xyz(point, column.origin_xy_m);
                    Beam {
                        bearing_rad: p.y.atan2(p.x),
                        range_m: Some(p.x.hypot(p.y)),
                    }
                }
            }
            None => {
                let points =
                    &scan.points[column.start as usize..(column.start + column.len) as usize];
                let bearing = points
                    .iter()
                    .find(|p| p.is_valid())
                    .map_or(0.0, |p| p.phi_rad);
                Beam {
                    bearing_rad: bearing,
                    range_m: None,
                }
            }
        })
        .collect();
    LeveledScan {
        stamp_ns: scan.start_stamp_ns(),
        beams,
    }
}

/// What a fixed, horizontal 2D scanner at the sensor would see: per column, the point nearest
/// to zero elevation, if within `max_elevation_rad`, as (bearing rad, range m). For
/// comparing a leveled scan with a plain 2D scan (paper Fig. 4); uses the raw sensor frame,
/// so it tilts with the robot as a fixed scanner does.
pub fn horizontal_cut(raw: &Scan3d, max_elevation_rad: f32) -> Vec<(f32, f32)> {
    (0..raw.columns.len())
        .filter_map(|i| {
            raw.column_points(i)
                .iter()
                .filter(|p| p.is_valid())
                .map(|p| (p.elevation_rad().abs(), p))
                .filter(|(e, _)| *e <= max_elevation_rad)
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, p)| (p.phi_rad, p.r_m))
        })
        .collect()
}
