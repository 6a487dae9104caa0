//! The segmented 3D cloud a node may carry (pure, no I/O): the leveled cloud with its classes,
//! reduced to a size a radio link carries with every node.
//!
//! The reduction, deterministic: invalid points are dropped; then one point per voxel and
//! class (the first in scan order), so the near ground, sampled far more densely than a tree
//! 30 m away, no longer dominates; then, above `max_points`, every class keeps its share
//! (largest remainder, at least one point for a class that has any), spread evenly over the
//! class's points in scan order.

use leveling::deskew::leveled_xyz;
use leveling::{PointClass, Scan3d};
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use wire::ClassifiedCloud;

/// Whether and how a node carries its segmented cloud (`[cloud]` in the edge config).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CloudParams {
    /// Send each node's segmented 3D cloud (for the dashboard's node inspector).
    pub keep: bool,
    /// Edge of the voxels (m) of which one point per class is kept; 0: no voxel filter.
    pub voxel_m: f32,
    /// At most this many points per node, each class keeping its share; 0: no cap.
    pub max_points: usize,
}

impl Default for CloudParams {
    fn default() -> Self {
        CloudParams {
            keep: true,
            voxel_m: 0.1,
            max_points: 6000,
        }
    }
}

const CLASSES: [PointClass; 3] = [
    PointClass::Ground,
    PointClass::Landmark,
    PointClass::Overhang,
];

fn class_slot(class: PointClass) -> Option<usize> {
    CLASSES.iter().position(|&c| c == class)
}

/// The reduced cloud of a leveled scan (`cloud` in the leveled frame, `classes` in the same
/// order, as [`leveling::Leveled`] holds them). Points farther than the wire carries
/// ([`wire::CLOUD_MAX_COORD_CM`]) are left out; `source_points` counts every valid point.
pub fn reduce(cloud: &Scan3d, classes: &[PointClass], params: &CloudParams) -> ClassifiedCloud {
    let limit_m = wire::CLOUD_MAX_COORD_CM as f32 / 100.0;
    let mut source_points = 0u64;
    let mut voxels = HashSet::new();
    let mut candidates: Vec<([f32; 3], usize)> = Vec::new();
    for column in &cloud.columns {
        let start = column.start as usize;
        let range = start..start + column.len as usize;
        for (point, &class) in cloud.points[range.clone()].iter().zip(&classes[range]) {
            let Some(slot) = class_slot(class) else {
                continue;
            };
            if !point.is_valid() {
                continue;
            }
            source_points += 1;
            let p = leveled_xyz(point, column.origin_xy_m);
            let xyz = [p.x, p.y, p.z];
            if xyz.iter().any(|v| !v.is_finite() || v.abs() > limit_m) {
                continue;
            }
            if params.voxel_m > 0.0 {
                let cell = xyz.map(|v| (v / params.voxel_m).floor() as i64);
                if !voxels.insert((slot, cell)) {
                    continue;
                }
            }
            candidates.push((xyz, slot));
        }
    }
    let mut per_class = [0usize; 3];
    for &(_, slot) in &candidates {
        per_class[slot] += 1;
    }
    let quota = quotas(per_class, params.max_points);
    let mut seen = [0usize; 3];
    let mut points_m = Vec::new();
    let mut kept_classes = Vec::new();
    for (xyz, slot) in candidates {
        let (j, n, q) = (seen[slot], per_class[slot], quota[slot]);
        seen[slot] += 1;
        // The j-th of n points is kept when it starts a new q-th of the class (the 0th
        // always): exactly q kept, evenly spread.
        if (j as u64 * q as u64) % (n as u64) < (q as u64) {
            points_m.push(xyz);
            kept_classes.push(CLASSES[slot]);
        }
    }
    ClassifiedCloud {
        points_m,
        classes: kept_classes,
        source_points,
        voxel_m: params.voxel_m.max(0.0),
        max_points: u32::try_from(params.max_points).unwrap_or(u32::MAX),
    }
}

/// Points to keep per class, at most `max` (0: all) in all: shares of `max` in proportion to
/// `counts` by largest remainder, a class with points keeping at least one while `max` allows.
pub fn quotas(counts: [usize; 3], max: usize) -> [usize; 3] {
    let total: usize = counts.iter().sum();
    if max == 0 || total <= max {
        return counts;
    }
    let share = |c: usize| (c as u128 * max as u128 / total as u128) as usize;
    let remainder = |c: usize| c as u128 * max as u128 % total as u128;
    let mut q = counts.map(share);
    for (q, &c) in q.iter_mut().zip(&counts) {
        if c > 0 && *q == 0 {
            *q = 1;
        }
    }
    // The floors leave at most two points over: they go to the largest remainders.
    let mut order = [0, 1, 2];
    order.sort_by_key(|&k| std::cmp::Reverse(remainder(counts[k])));
    for k in order {
        if q.iter().sum::<usize>() >= max {
            break;
        }
        if q[k] < counts[k] {
            q[k] += 1;
        }
    }
    // Minimums beyond a tiny `max`: taken back from the largest share while it has more than
    // one point, then from the smallest class (the later one of equals).
    while q.iter().sum::<usize>() > max {
        let largest = (0..3).max_by_key(|&k| q[k]).expect("3 classes");
        let k = if q[largest] > 1 {
            largest
        } else {
            (0..3)
                .filter(|&k| q[k] > 0)
                .min_by_key(|&k| (counts[k], std::cmp::Reverse(k)))
                .expect("over max > 0, so some share is positive")
        };
        q[k] -= 1;
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use leveling::CylPoint;

    /// `columns` columns at azimuths 1° apart, each with `classes` bottom-up at 5 m, 0.1 m
    /// apart in height, the column's sensor axis at (0.5, 0) m.
    fn scan(columns: usize, classes: &[PointClass]) -> (Scan3d, Vec<PointClass>) {
        let mut cloud = Scan3d::default();
        let mut all = Vec::new();
        for c in 0..columns {
            cloud.begin_column(c as u64);
            cloud.columns.last_mut().unwrap().origin_xy_m = [0.5, 0.0];
            for (k, &class) in classes.iter().enumerate() {
                if class == PointClass::Invalid {
                    cloud.push(CylPoint::INVALID);
                } else {
                    cloud.push(CylPoint {
                        r_m: 5.0,
                        phi_rad: (c as f32).to_radians(),
                        z_m: k as f32 * 0.1,
                    });
                }
                all.push(class);
            }
        }
        (cloud, all)
    }

    fn count(classes: &[PointClass], class: PointClass) -> usize {
        classes.iter().filter(|&&c| c == class).count()
    }

    use PointClass::{Ground as G, Invalid as I, Landmark as L, Overhang as O};

    #[test]
    fn small_clouds_keep_every_valid_point_in_the_leveled_frame() {
        let (cloud, classes) = scan(3, &[I, G, L, O, I]);
        let params = CloudParams {
            voxel_m: 0.0,
            ..CloudParams::default()
        };
        let r = reduce(&cloud, &classes, &params);
        assert_eq!(r.source_points, 9);
        assert_eq!(r.classes, [G, L, O, G, L, O, G, L, O]);
        // Column 0 at azimuth 0: (5 + 0.5, 0, z).
        assert_eq!(r.points_m[1], [5.5, 0.0, 0.2]);
        assert_eq!(r.max_points, 6000);
        // What the wire carries of it is valid, and as many points.
        let wire = wire::cloud_to_wire(&r);
        assert_eq!(wire::validate_cloud(&wire).unwrap().landmark, 3);
        assert_eq!(wire.classes.len(), 9);
    }

    #[test]
    fn the_cap_keeps_every_class_in_proportion_and_spread_evenly() {
        // 1000 columns of 7 ground, 2 landmark, 1 overhang: 10,000 points.
        let (cloud, classes) = scan(1000, &[G, G, G, G, G, G, G, L, L, O]);
        let params = CloudParams {
            keep: true,
            voxel_m: 0.0,
            max_points: 500,
        };
        let r = reduce(&cloud, &classes, &params);
        assert_eq!(r.source_points, 10_000);
        assert_eq!(r.classes.len(), 500);
        assert_eq!(
            (
                count(&r.classes, G),
                count(&r.classes, L),
                count(&r.classes, O)
            ),
            (350, 100, 50)
        );
        // Spread over the whole scan (azimuths 0°..999°, every 20th column's overhang), not
        // its start.
        let overhang: Vec<f32> = r
            .points_m
            .iter()
            .zip(&r.classes)
            .filter(|(_, c)| **c == O)
            .map(|(p, _)| p[1].atan2(p[0] - 0.5).to_degrees())
            .collect();
        assert!(
            overhang[0].abs() < 0.01 && (overhang[1] - 20.0).abs() < 0.01,
            "{overhang:?}"
        );
        // Deterministic.
        assert_eq!(reduce(&cloud, &classes, &params), r);
        // A class of one point in 10,000 keeps its point.
        let mut classes = vec![G; 10_000];
        classes[5_000] = O;
        let (cloud, _) = scan(1000, &[G; 10]);
        let r = reduce(&cloud, &classes, &params);
        assert_eq!((r.classes.len(), count(&r.classes, O)), (500, 1));
        // No cap: everything.
        let r = reduce(
            &cloud,
            &classes,
            &CloudParams {
                max_points: 0,
                ..params
            },
        );
        assert_eq!(r.classes.len(), 10_000);
    }

    #[test]
    fn the_voxel_filter_keeps_one_point_per_voxel_and_class() {
        // Ten points 0.1 m apart in height: 1 m voxels keep one per class per column.
        let (cloud, classes) = scan(2, &[G, G, G, G, G, L, L, L, L, L]);
        let params = CloudParams {
            keep: true,
            voxel_m: 1.0,
            max_points: 0,
        };
        let r = reduce(&cloud, &classes, &params);
        assert_eq!(r.source_points, 20);
        // Columns 0 and 1 (1° apart at 5 m: 9 cm) share their voxels.
        assert_eq!(r.classes, [G, L]);
        assert_eq!(r.points_m[1], [5.5, 0.0, 0.5]);
        assert_eq!(r.voxel_m, 1.0);
    }

    #[test]
    fn quotas_add_up_to_the_cap() {
        assert_eq!(quotas([10, 20, 30], 100), [10, 20, 30]);
        assert_eq!(quotas([10, 20, 30], 0), [10, 20, 30]);
        assert_eq!(quotas([1, 1, 1], 2), [1, 1, 0]);
        assert_eq!(quotas([9998, 1, 1], 3), [1, 1, 1]);
        assert_eq!(quotas([9998, 1, 1], 2), [1, 1, 0]);
        for (counts, max) in [
            ([20_000, 5_000, 1_900], 6000),
            ([7, 7, 7], 10),
            ([1_000_003, 17, 0], 999),
        ] {
            let q = quotas(counts, max);
            assert_eq!(q.iter().sum::<usize>(), max, "{counts:?} {max}: {q:?}");
            for k in 0..3 {
                let exact = counts[k] as f64 * max as f64 / counts.iter().sum::<usize>() as f64;
                assert!((q[k] as f64 - exact).abs() <= 1.0, "{counts:?}: {q:?}");
                assert!(q[k] <= counts[k] && (counts[k] == 0 || q[k] > 0));
            }
        }
    }
}
