//! A lidar's unorganized cloud (a ROS `PointCloud2`, most drivers) organized as KITTI's
//! scans are ([`crate::kitti::organize`]: azimuth sectors sorted bottom-up by elevation),
//! each column stamped from its points' own times where the cloud has them.

use crate::kitti::organize;
use leveling::Scan3d;

/// `xyz` (sensor frame, m; NaN for no return) in `columns` azimuth columns. With
/// `offsets_ns` (per point, after `stamp_ns`), a column's stamp is its points' mean time
/// and the columns are put in time order; without, every column is at `stamp_ns` (the scan
/// is taken as measured at once: no motion compensation).
pub fn organize_timed(
    xyz: &[[f32; 3]],
    offsets_ns: Option<&[i64]>,
    stamp_ns: u64,
    columns: usize,
) -> Scan3d {
    let (mut scan, index) = organize(xyz, columns);
    for column in &mut scan.columns {
        column.stamp_ns = stamp_ns;
        let Some(offsets) = offsets_ns else {
            continue;
        };
        let range = column.start as usize..(column.start + column.len) as usize;
        let times: Vec<i64> = range
            .filter(|&i| scan.points[i].is_valid())
            .filter_map(|i| offsets.get(index[i] as usize).copied())
            .collect();
        if !times.is_empty() {
            let mean = times.iter().map(|&t| t as i128).sum::<i128>() / times.len() as i128;
            column.stamp_ns = (stamp_ns as i128 + mean).max(0) as u64;
        }
    }
    // A spinning lidar's sweep starts anywhere and may turn either way: time order, not
    // azimuth order, is the measurement order the leveling expects.
    scan.columns.sort_by_key(|c| c.stamp_ns);
    scan
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_take_their_points_time_and_come_in_time_order() {
        // Two points ahead (+x) measured late, one behind (−x) early.
        let xyz = [[5.0, 0.0, 0.0], [5.0, 0.0, 1.0], [-5.0, -0.01, 0.0]];
        let offsets = [90_000, 110_000, 10_000];
        let scan = organize_timed(&xyz, Some(&offsets), 1_000_000, 2);
        let stamps: Vec<u64> = scan.columns.iter().map(|c| c.stamp_ns).collect();
        assert_eq!(stamps, vec![1_010_000, 1_100_000]);
        let without = organize_timed(&xyz, None, 7, 2);
        assert!(without.columns.iter().all(|c| c.stamp_ns == 7));
        assert_eq!(without.points.len(), 3);
    }
}
