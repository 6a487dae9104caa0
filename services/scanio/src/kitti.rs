//! KITTI Velodyne HDL-64E `.bin` scans: organized into azimuth columns, each sorted bottom-up
//! by elevation, since the file holds an unorganized list of points.

use crate::{LoadError, LoadedScan, read_nonempty};
use leveling::nalgebra::Isometry3;
use leveling::{CylPoint, PoseTrack, Scan3d};
use std::f32::consts::PI;
use std::path::Path;

/// Bytes per point record: x, y, z, reflectance as little-endian float32.
pub const POINT_BYTES: usize = 16;

/// Azimuth columns per revolution. The HDL-64E fires about 2,000 times per revolution at
/// 10 Hz; 2,048 bins of 0.18° keep one firing per column while leaving few columns empty.
pub const DEFAULT_COLUMNS: usize = 2048;

/// Reads a KITTI `.bin` file and organizes it into `columns` azimuth columns.
pub fn load(path: &Path, columns: usize) -> Result<LoadedScan, LoadError> {
    parse(&read_nonempty(path)?, path, columns)
}

/// Parses the bytes of a KITTI `.bin` file (`path` names it in errors) and organizes them
/// into `columns` azimuth columns. Empty bytes or a partial point record are errors.
pub fn parse(bytes: &[u8], path: &Path, columns: usize) -> Result<LoadedScan, LoadError> {
    if bytes.is_empty() {
        return Err(LoadError::Empty {
            path: path.to_owned(),
        });
    }
    if !bytes.len().is_multiple_of(POINT_BYTES) {
        return Err(LoadError::Truncated {
            path: path.to_owned(),
            len: bytes.len(),
            point_bytes: POINT_BYTES,
        });
    }
    let xyz: Vec<[f32; 3]> = bytes
        .chunks_exact(POINT_BYTES)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
            [f(0), f(4), f(8)]
        })
        .collect();
    let (raw, file_index) = organize(&xyz, columns);
    Ok(LoadedScan {
        raw,
        track: PoseTrack::stationary(Isometry3::identity()),
        sensor_in_robot: Isometry3::identity(),
        file_index,
    })
}

/// Bins points (sensor frame, m) into `columns` equal azimuth sectors, counter-clockwise from
/// −π, and sorts each bottom-up by elevation. Points that are not finite have no azimuth; they
/// are kept as invalid returns at the top of column 0 so every file point stays accounted for.
/// Returns the scan and, per scan point, its index in `xyz`.
pub fn organize(xyz: &[[f32; 3]], columns: usize) -> (Scan3d, Vec<u32>) {
    let columns = columns.max(1);
    let sector =
        |p: &CylPoint| (((p.phi_rad + PI) / (2.0 * PI) * columns as f32) as usize).min(columns - 1);
    let points: Vec<CylPoint> = xyz
        .iter()
        .map(|&[x, y, z]| CylPoint::from_xyz(x, y, z))
        .collect();

    // Counting sort by sector, then by elevation within each sector.
    let mut counts = vec![0usize; columns + 1];
    for p in points.iter().filter(|p| p.is_valid()) {
        counts[sector(p) + 1] += 1;
    }
    for i in 0..columns {
        counts[i + 1] += counts[i];
    }
    let starts = counts.clone();
    let mut order = vec![0u32; counts[columns]];
    for (i, p) in points.iter().enumerate().filter(|(_, p)| p.is_valid()) {
        let s = sector(p);
        order[counts[s]] = i as u32;
        counts[s] += 1;
    }
    let invalid: Vec<u32> = (0..points.len() as u32)
        .filter(|&i| !points[i as usize].is_valid())
        .collect();

    let mut scan = Scan3d::with_capacity(columns, points.len() / columns + 1);
    let mut file_index = Vec::with_capacity(points.len());
    for s in 0..columns {
        let column = &mut order[starts[s]..starts[s + 1]];
        column.sort_unstable_by(|&a, &b| {
            points[a as usize]
                .elevation_rad()
                .total_cmp(&points[b as usize].elevation_rad())
        });
        scan.begin_column(0);
        for &i in column.iter() {
            scan.push(points[i as usize]);
            file_index.push(i);
        }
        if s == 0 {
            for &i in &invalid {
                scan.push_invalid();
                file_index.push(i);
            }
        }
    }
    (scan, file_index)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_takes_whole_point_records() {
        let path = Path::new("t.bin");
        let bytes: Vec<u8> = [[5.0f32, 0.1, 1.0, 0.3], [f32::NAN, 0.0, 0.0, 0.0]]
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let scan = parse(&bytes, path, 4).unwrap();
        assert_eq!((scan.raw.points.len(), scan.raw.columns.len()), (2, 4));
        assert!(matches!(
            parse(&bytes[..20], path, 4),
            Err(LoadError::Truncated { len: 20, .. })
        ));
        assert!(matches!(parse(&[], path, 4), Err(LoadError::Empty { .. })));
    }

    #[test]
    fn columns_are_sorted_bottom_up_and_keep_every_point() {
        let xyz = [
            [5.0, 0.1, 1.0],
            [5.0, 0.1, -1.0],
            [-3.0, 0.0, 0.0],
            [f32::NAN, 0.0, 0.0],
            [5.0, 0.12, 0.0],
        ];
        let (scan, index) = organize(&xyz, 4);
        assert_eq!(scan.points.len(), 5);
        assert_eq!(scan.columns.len(), 4);
        let mut seen = index.clone();
        seen.sort();
        assert_eq!(seen, vec![0, 1, 2, 3, 4]);
        // Points ahead (φ ≈ 0) fall in sector 2 of 4, bottom-up: z = −1, 0, 1.
        let ahead: Vec<f32> = scan.column_points(2).iter().map(|p| p.z_m).collect();
        assert_eq!(ahead, vec![-1.0, 0.0, 1.0]);
        assert_eq!(&index[scan.columns[2].start as usize..][..3], &[1, 4, 0]);
    }
}
