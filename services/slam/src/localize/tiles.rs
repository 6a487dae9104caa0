//! The map cut into square tiles, each a pooled probability grid of the returns that fall
//! within its square and a margin of the search range around it: a robot standing in the
//! square sees nothing the tile lacks. And an index of the map's scans by place, for the
//! refinement's nearest scans.

use super::LocalizeParams;
use crate::Pose2;
use crate::matching::Scan2;
use crate::matching::correlative::{CorrelativeParams, PrecomputedGrids, ProbabilityGrid};
use std::collections::{BTreeMap, HashMap};

/// One tile: its square (whose scans' returns it holds, with a margin) and its grids.
#[derive(Debug)]
pub(super) struct Tile {
    /// The square's lower-left corner (m).
    lo: [f64; 2],
    side_m: f64,
    pub(super) grids: PrecomputedGrids,
}

impl Tile {
    /// The square's centre, heading 0: where a search over the whole tile starts.
    pub(super) fn centre(&self) -> Pose2 {
        let h = self.side_m / 2.0;
        Pose2::new(self.lo[0] + h, self.lo[1] + h, 0.0)
    }

    /// Distance from `xy` to the square (0 inside).
    fn distance_to(&self, xy: [f64; 2]) -> f64 {
        let d = |v: f64, lo: f64| (lo - v).max(v - lo - self.side_m).max(0.0);
        d(xy[0], self.lo[0]).hypot(d(xy[1], self.lo[1]))
    }
}

fn key_of(xy: [f64; 2], side_m: f64) -> (i64, i64) {
    (
        (xy[0] / side_m).floor() as i64,
        (xy[1] / side_m).floor() as i64,
    )
}

/// One tile per square holding a scan's pose. A tile's grid takes the returns (within the
/// search range of their scan) that fall in its square widened by the search range.
pub(super) fn build(scans: &[(Pose2, Scan2)], params: &LocalizeParams) -> Vec<Tile> {
    let (side, range) = (params.tile_m, params.grid.max_range_m);
    let mut by_key: BTreeMap<(i64, i64), Vec<usize>> = BTreeMap::new();
    for (k, (pose, scan)) in scans.iter().enumerate() {
        if pose.is_finite() && !scan.is_empty() {
            by_key
                .entry(key_of([pose.x, pose.y], side))
                .or_default()
                .push(k);
        }
    }
    // A scan's returns reach `range` from its pose, and the tile takes returns `range`
    // beyond its square: scans of squares this many away may put returns in it.
    let reach = (2.0 * range / side).ceil() as i64;
    // Returns are placed in the map frame here: the grid's own range cut must not apply.
    let unlimited = CorrelativeParams {
        max_range_m: f64::INFINITY,
        ..params.grid.clone()
    };
    let range2 = range * range;
    by_key
        .keys()
        .filter_map(|&(i, j)| {
            let lo = [i as f64 * side, j as f64 * side];
            let inside = |p: &[f64; 2]| {
                (lo[0] - range..lo[0] + side + range).contains(&p[0])
                    && (lo[1] - range..lo[1] + side + range).contains(&p[1])
            };
            let mut points: Vec<[f64; 2]> = Vec::new();
            for di in -reach..=reach {
                for dj in -reach..=reach {
                    for &k in by_key.get(&(i + di, j + dj)).into_iter().flatten() {
                        let (pose, scan) = &scans[k];
                        points.extend(
                            scan.points()
                                .iter()
                                .filter(|q| q[0] * q[0] + q[1] * q[1] <= range2)
                                .map(|&q| pose.transform_point(q))
                                .filter(inside),
                        );
                    }
                }
            }
            let grid = ProbabilityGrid::from_scans([(Pose2::IDENTITY, &points[..])], &unlimited)?;
            let grids = PrecomputedGrids::new(grid, params.grid.max_depth);
            Some(Tile {
                lo,
                side_m: side,
                grids,
            })
        })
        .collect()
}

/// The tile whose square holds `xy`, else the nearest within half a side of it.
pub(super) fn nearest(tiles: &[Tile], xy: [f64; 2], side_m: f64) -> Option<&Tile> {
    tiles
        .iter()
        .map(|t| (t.distance_to(xy), t))
        .filter(|(d, _)| *d <= side_m / 2.0)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, t)| t)
}

/// The map's scans by place: cells of the search radius.
#[derive(Debug)]
pub(super) struct NodeIndex {
    cell_m: f64,
    cells: HashMap<(i64, i64), Vec<usize>>,
}

impl NodeIndex {
    pub(super) fn new(scans: &[(Pose2, Scan2)], radius_m: f64) -> NodeIndex {
        let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (k, (pose, scan)) in scans.iter().enumerate() {
            if pose.is_finite() && !scan.is_empty() {
                cells
                    .entry(key_of([pose.x, pose.y], radius_m))
                    .or_default()
                    .push(k);
            }
        }
        NodeIndex {
            cell_m: radius_m,
            cells,
        }
    }

    /// Up to `count` scans whose poses lie within the radius of `xy`, nearest first.
    pub(super) fn nearest(
        &self,
        scans: &[(Pose2, Scan2)],
        xy: [f64; 2],
        count: usize,
    ) -> Vec<usize> {
        let (i, j) = key_of(xy, self.cell_m);
        let mut near: Vec<(f64, usize)> = (-1..=1)
            .flat_map(|di| (-1..=1).map(move |dj| (i + di, j + dj)))
            .filter_map(|key| self.cells.get(&key))
            .flatten()
            .map(|&k| {
                let p = &scans[k].0;
                ((p.x - xy[0]).hypot(p.y - xy[1]), k)
            })
            .filter(|(d, _)| *d <= self.cell_m)
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        near.into_iter().take(count).map(|(_, k)| k).collect()
    }
}
