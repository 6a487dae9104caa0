//! Which nodes lie near a point: the nodes filed by their estimates in square cells, so that
//! finding the other robots' nodes near a new node costs the nodes nearby, not the network.
//! Every change of the estimates files the nodes again: a window's nodes one by one, a solve
//! of the whole network (or a part moved) all of them.

use crate::se2::Pose2;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Side of a cell (m).
const CELL_M: f64 = 5.0;

type Cell = (i64, i64);

/// The nodes by cell.
#[derive(Debug, Default, Serialize, Deserialize)]
pub(super) struct NodeGrid {
    cells: HashMap<Cell, Vec<usize>>,
    /// Each node's cell.
    filed: Vec<Cell>,
}

fn cell_of(x: f64, y: f64) -> Cell {
    ((x / CELL_M).floor() as i64, (y / CELL_M).floor() as i64)
}

impl NodeGrid {
    /// Files the nodes of `poses` not filed yet, and files `moved` again where they are now.
    pub fn refile(&mut self, poses: &[Pose2], moved: &[usize]) {
        for &node in moved {
            let cell = cell_of(poses[node].x, poses[node].y);
            let old = std::mem::replace(&mut self.filed[node], cell);
            if old != cell {
                let nodes = self.cells.get_mut(&old).expect("filed");
                nodes.swap_remove(nodes.iter().position(|&n| n == node).expect("filed"));
                self.cells.entry(cell).or_default().push(node);
            }
        }
        for (node, pose) in poses.iter().enumerate().skip(self.filed.len()) {
            let cell = cell_of(pose.x, pose.y);
            self.filed.push(cell);
            self.cells.entry(cell).or_default().push(node);
        }
    }

    /// Files every node again.
    pub fn rebuild(&mut self, poses: &[Pose2]) {
        self.cells.clear();
        self.filed.clear();
        self.refile(poses, &[]);
    }

    /// Every node filed within `radius` of `at` (and some a little farther), in no order.
    pub fn near(&self, at: &Pose2, radius: f64) -> impl Iterator<Item = usize> + '_ {
        let (lo, hi) = (
            cell_of(at.x - radius, at.y - radius),
            cell_of(at.x + radius, at.y + radius),
        );
        (lo.0..=hi.0)
            .flat_map(move |i| (lo.1..=hi.1).map(move |j| (i, j)))
            .filter_map(|cell| self.cells.get(&cell))
            .flatten()
            .copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_every_node_within_the_radius_after_moves() {
        let mut poses: Vec<Pose2> = (0..400)
            .map(|k| {
                Pose2::new(
                    (k % 20) as f64 * 1.7 - 15.0,
                    (k / 20) as f64 * 1.3 - 12.0,
                    0.0,
                )
            })
            .collect();
        let mut grid = NodeGrid::default();
        grid.refile(&poses, &[]);
        // Some move far, one by one; then all of them.
        for k in (0..400).step_by(7) {
            poses[k].x += 11.0;
            poses[k].y -= 4.0;
        }
        let moved: Vec<usize> = (0..400).step_by(7).collect();
        grid.refile(&poses, &moved);
        let check = |grid: &NodeGrid, poses: &[Pose2]| {
            for at in [
                Pose2::new(0.0, 0.0, 0.0),
                Pose2::new(-14.0, 9.5, 1.0),
                Pose2::new(20.0, -3.0, 0.0),
            ] {
                let mut found: Vec<usize> = grid.near(&at, 3.0).collect();
                found.sort_unstable();
                let within = |k: &usize| (poses[*k].x - at.x).hypot(poses[*k].y - at.y) <= 3.0;
                let expected: Vec<usize> = (0..poses.len()).filter(within).collect();
                assert!(
                    expected.iter().all(|k| found.binary_search(k).is_ok()),
                    "{at:?}"
                );
                assert!(!expected.is_empty());
            }
        };
        check(&grid, &poses);
        for p in &mut poses {
            p.y += 2.5;
        }
        grid.rebuild(&poses);
        check(&grid, &poses);
    }
}
