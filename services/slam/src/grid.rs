//! The occupancy grid of a scan-based map (docs/slam.md, "Map products"): the leveled scans at
//! their optimized node poses, ray cast into a grid of log-odds (a probability grid). Every
//! beam clears the cells it crosses from the sensor's blind zone on (a supercover traversal,
//! see `traverse`) and adds hit evidence to the cell of its return; neighbouring beams that
//! see alike clear the wedge between them, and a beam without a return clears only a short
//! way ([`GridParams`] gives each rule and its reason).
//! The result is served as occupancy per cent in the layout of ROS `nav_msgs/OccupancyGrid` (−1
//! unknown, 0–100; row-major, row 0 the southernmost), so the PNG/PGM encoders and any ROS
//! client read it the same way.
//!
//! Within one scan a cell is updated at most once, and a return wins over a beam crossing
//! it: rays grazing a wall would otherwise erase the wall their neighbours just hit.

mod fan;
mod params;
mod raycast;

pub use fan::{BeamFan, FanBeam};
pub use params::{GridError, GridParams};

// The tests reach these through `use super::*`.
#[cfg(test)]
use crate::{matching::Scan2, se2::Pose2};
#[cfg(test)]
use raycast::traverse;

use serde::{Deserialize, Serialize};

/// What a cell is known to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum CellState {
    /// Never seen, or seen as neither free nor occupied.
    Unknown,
    /// Seen as free.
    Free,
    /// Seen as occupied.
    Occupied,
}

/// An occupancy grid: cell (ix, iy) covers `origin_m + resolution_m·[ix, iy]` to one cell
/// further in x (east) and y (north).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Cell edge (m).
    pub resolution_m: f64,
    /// World position of cell (0, 0)'s lower-left corner (m). A multiple of the resolution,
    /// so grids of the same map at different times line up cell for cell.
    pub origin_m: [f64; 2],
    /// Cells along x (east).
    pub width: usize,
    /// Cells along y (north).
    pub height: usize,
    /// Occupancy per cent of each cell, row-major from row 0 (lowest y): −1 never seen,
    /// else 0–100 (`nav_msgs/OccupancyGrid.data`).
    pub cells: Vec<i8>,
    /// Per-cent thresholds of [`Self::state`]: occupied at or above, free at or below.
    pub occupied_percent: i8,
    /// See `occupied_percent`.
    pub free_percent: i8,
}

impl OccupancyGrid {
    /// The cell holding world point `p` (m), if inside the grid.
    pub fn cell_at(&self, p: [f64; 2]) -> Option<(usize, usize)> {
        let x = ((p[0] - self.origin_m[0]) / self.resolution_m).floor();
        let y = ((p[1] - self.origin_m[1]) / self.resolution_m).floor();
        (x >= 0.0 && y >= 0.0 && x < self.width as f64 && y < self.height as f64)
            .then_some((x as usize, y as usize))
    }

    /// World position of the centre of cell (ix, iy) (m).
    pub fn cell_center(&self, ix: usize, iy: usize) -> [f64; 2] {
        [
            self.origin_m[0] + (ix as f64 + 0.5) * self.resolution_m,
            self.origin_m[1] + (iy as f64 + 0.5) * self.resolution_m,
        ]
    }

    /// Occupancy per cent of cell (ix, iy), −1 when never seen. Panics outside the grid.
    pub fn occupancy(&self, ix: usize, iy: usize) -> i8 {
        assert!(ix < self.width && iy < self.height, "cell outside the grid");
        self.cells[iy * self.width + ix]
    }

    /// The tri-state of cell (ix, iy). Panics outside the grid.
    pub fn state(&self, ix: usize, iy: usize) -> CellState {
        self.classify(self.occupancy(ix, iy))
    }

    /// The tri-state of an occupancy value of this grid (−1 or 0–100).
    pub fn classify(&self, occupancy: i8) -> CellState {
        if occupancy < 0 {
            CellState::Unknown
        } else if occupancy >= self.occupied_percent {
            CellState::Occupied
        } else if occupancy <= self.free_percent {
            CellState::Free
        } else {
            CellState::Unknown
        }
    }

    /// How many cells are in each state: (unknown, free, occupied).
    pub fn counts(&self) -> (usize, usize, usize) {
        let mut n = (0, 0, 0);
        for &c in &self.cells {
            match self.classify(c) {
                CellState::Unknown => n.0 += 1,
                CellState::Free => n.1 += 1,
                CellState::Occupied => n.2 += 1,
            }
        }
        n
    }
}

#[cfg(test)]
mod tests;
