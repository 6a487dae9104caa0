//! Projection of the segmented cloud into the leveled range scan (paper 3.2, eq. 3.4).

use crate::deskew::leveled_xyz;
use crate::scan::Scan3d;
use crate::segment::PointClass;
use serde::{Deserialize, Serialize};

/// One beam of a leveled range scan: the first landmark point of a column, bottom-up,
/// projected parallel onto the horizontal plane (eq. 3.4).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Beam {
    /// Bearing in the leveled frame at scan start (rad, counter-clockwise from x forward).
    pub bearing_rad: f32,
    /// Horizontal range from the sensor at scan start (m); `None`: the column has no landmark.
    pub range_m: Option<f32>,
    /// Where the sensor's axis was when the column was measured, in the scan's frame (m):
    /// the beam was seen from there, so free space is cleared from there. `[0, 0]` for a
    /// scan taken from one place. A beam without a return points along `bearing_rad` from
    /// here.
    #[serde(default)]
    pub sensor_xy_m: [f32; 2],
    /// A beam without a return: how far from `sensor_xy_m` its column saw the ground, with
    /// nothing standing on it (m; the farthest ground point's horizontal range short of any
    /// overhang). The beam to that point passed over everything nearer, so the space up to
    /// it is free; 0: the column saw no such ground. `None`: not known (a planar scan).
    #[serde(default)]
    pub ground_to_m: Option<f32>,
}

impl Beam {
    /// The beam as seen from where it was measured (`sensor_xy_m`): its bearing (rad) and, for
    /// a return, its range (m) from there. A beam without a return already points from there.
    pub fn seen_from_sensor(&self) -> (f64, Option<f64>) {
        let bearing = f64::from(self.bearing_rad);
        let Some(r) = self.range_m.map(f64::from) else {
            return (bearing, None);
        };
        let [sx, sy] = self.sensor_xy_m.map(f64::from);
        let d = [r * bearing.cos() - sx, r * bearing.sin() - sy];
        (d[1].atan2(d[0]), Some(d[0].hypot(d[1])))
    }
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
/// `scan.points`, as [`crate::Segmenter::segment`] returns them with `classes`, one per
/// point). A column without a landmark gives a beam without a return, and how far it saw the
/// ground.
pub fn project(
    scan: &Scan3d,
    first_landmarks: &[Option<u32>],
    classes: &[PointClass],
) -> LeveledScan {
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
                        sensor_xy_m: [0.0, 0.0],
                        ground_to_m: None,
                    }
                } else {
                    // Motion-compensated column: measure from the sensor at scan start.
                    let p = leveled_xyz(point, column.origin_xy_m);
                    Beam {
                        bearing_rad: p.y.atan2(p.x),
                        range_m: Some(p.x.hypot(p.y)),
                        sensor_xy_m: column.origin_xy_m,
                        ground_to_m: None,
                    }
                }
            }
            None => {
                let range = column.start as usize..(column.start + column.len) as usize;
                let (points, classes) = (&scan.points[range.clone()], &classes[range]);
                // Ground is taken as seen free only short of the column's first overhang:
                // under a crown, a roof or a bridge deck stand the trunk, the pillars or, on
                // the deck, the rails, which a beam skimming the ground below may just miss.
                let overhang_from = points
                    .iter()
                    .zip(classes)
                    .filter(|(_, class)| **class == PointClass::Overhang)
                    .map(|(p, _)| p.r_m)
                    .fold(f32::INFINITY, f32::min);
                let farthest_ground = points
                    .iter()
                    .zip(classes)
                    .filter(|(p, class)| **class == PointClass::Ground && p.r_m < overhang_from)
                    .map(|(p, _)| p)
                    .max_by(|a, b| a.r_m.total_cmp(&b.r_m));
                // A tilted sensor's column is no vertical plane: the beam points at the
                // farthest ground it saw, not along its first point.
                let bearing = farthest_ground
                    .or_else(|| points.iter().find(|p| p.is_valid()))
                    .map_or(0.0, |p| p.phi_rad);
                let ground_to_m = Some(farthest_ground.map_or(0.0, |p| p.r_m));
                Beam {
                    bearing_rad: bearing,
                    range_m: None,
                    sensor_xy_m: column.origin_xy_m,
                    ground_to_m,
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

#[cfg(test)]
mod tests {
    use crate::scan::Scan3d;
    use crate::{Leveler, SegmentParams};

    /// Ground every metre from 1 m to `to_m` along azimuth `phi(r)`, 1.2 m below the sensor,
    /// then `above`: further points (x, y, z), bottom-up.
    fn column(scan: &mut Scan3d, to_m: u32, phi: impl Fn(f32) -> f32, above: &[[f32; 3]]) {
        scan.begin_column(0);
        for r in 1..=to_m {
            let (r, a) = (r as f32, phi(r as f32));
            scan.push_xyz(r * a.cos(), r * a.sin(), -1.2);
        }
        for &[x, y, z] in above {
            scan.push_xyz(x, y, z);
        }
    }

    #[test]
    fn a_return_is_seen_from_where_its_column_was_measured() {
        // A return at (3, 2) in the scan's frame, its column measured 3 m along x.
        let beam = crate::Beam {
            bearing_rad: 2f32.atan2(3.0),
            range_m: Some(13f32.sqrt()),
            sensor_xy_m: [3.0, 0.0],
            ground_to_m: None,
        };
        let (bearing, range) = beam.seen_from_sensor();
        assert!(
            (bearing - std::f64::consts::FRAC_PI_2).abs() < 1e-6,
            "{bearing}"
        );
        assert!((range.unwrap() - 2.0).abs() < 1e-6);
        let none = crate::Beam {
            range_m: None,
            ..beam
        };
        assert_eq!(none.seen_from_sensor(), (f64::from(beam.bearing_rad), None));
    }

    #[test]
    fn a_column_without_a_landmark_tells_how_far_it_saw_the_ground() {
        let mut scan = Scan3d::default();
        // Open ground to 20 m.
        column(&mut scan, 20, |_| 0.0, &[]);
        // Ground to 10 m under a crown from 6 m on: free only to 5 m.
        column(
            &mut scan,
            10,
            |_| 0.5,
            &[[6.0 * 0.5f32.cos(), 6.0 * 0.5f32.sin(), 2.0]],
        );
        // A tilted sensor's column drifts in azimuth: the beam points at its farthest ground.
        column(&mut scan, 20, |r| 1.0 + 0.01 * r, &[]);
        // A wall at 8 m: a return, no ground reach.
        column(
            &mut scan,
            6,
            |_| -1.0,
            &[
                [8.0 * (-1f32).cos(), 8.0 * (-1f32).sin(), -1.2],
                [8.0 * (-1f32).cos(), 8.0 * (-1f32).sin(), -0.4],
            ],
        );
        // Only sky: no ground seen, so nothing to clear.
        scan.begin_column(0);
        scan.push_invalid();
        scan.columns[3].origin_xy_m = [0.5, -0.25];
        let leveled = Leveler::new(SegmentParams::default()).segment_and_project(scan);
        let beams = &leveled.scan.beams;
        assert_eq!(beams[0].range_m, None);
        assert_eq!(beams[0].ground_to_m, Some(20.0));
        assert_eq!(beams[1].ground_to_m, Some(5.0));
        assert!((beams[1].bearing_rad - 0.5).abs() < 1e-6);
        assert!((beams[2].ground_to_m.unwrap() - 20.0).abs() < 1e-4);
        assert!(
            (beams[2].bearing_rad - 1.2).abs() < 1e-5,
            "{}",
            beams[2].bearing_rad
        );
        assert!(beams[3].range_m.is_some());
        assert_eq!(beams[3].ground_to_m, None);
        assert_eq!(beams[3].sensor_xy_m, [0.5, -0.25]);
        assert_eq!(beams[4].ground_to_m, Some(0.0));
    }
}
