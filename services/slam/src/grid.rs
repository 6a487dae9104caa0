//! The occupancy grid of a scan-based map (docs/slam.md, "Map products"): the leveled scans at
//! their optimized node poses, ray cast into a grid of log-odds. Every beam clears the cells it
//! crosses (a supercover traversal, see `traverse`) and marks the cell of its return occupied.
//! The result is served as occupancy per cent in the layout of ROS `nav_msgs/OccupancyGrid` (−1
//! unknown, 0–100; row-major, row 0 the southernmost), so the PNG/PGM encoders and any ROS
//! client read it the same way.
//!
//! Within one scan a cell is updated at most once, and a return wins over a beam crossing
//! it: rays grazing a wall would otherwise erase the wall their neighbours just hit.

mod params;
mod raycast;

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
mod tests {
    use super::*;
    use crate::matching::synthetic::{Scene, uniform_bearings};

    /// A closed square room of side `side_m`, centred on the origin.
    fn room(side_m: f64) -> Scene {
        let h = side_m / 2.0;
        let c = [[-h, -h], [h, -h], [h, h], [-h, h]];
        Scene {
            walls: (0..4).map(|i| [c[i], c[(i + 1) % 4]]).collect(),
            trunks: Vec::new(),
        }
    }

    fn scan_of(scene: &Scene, pose: Pose2) -> Scan2 {
        let bearings = uniform_bearings(720, -std::f64::consts::PI, std::f64::consts::TAU / 720.0);
        let ranges = scene.scan(&pose, &bearings, 50.0, 0.0, 1);
        Scan2::from_polar(&bearings, &ranges, 50.0).expect("same lengths")
    }

    #[test]
    fn square_room_has_occupied_walls_free_inside_unknown_outside() {
        // A room of 6.05 m, walls at ±3.025 m: mid-cell, so each wall fills one row of
        // cells. Scanned from an off-centre, rotated pose.
        let pose = Pose2::new(0.7, -0.4, 0.5);
        let scan = scan_of(&room(6.05), pose);
        let grid = OccupancyGrid::from_scans([(pose, &scan)], &GridParams::default()).unwrap();
        // The wall cells span −3.1 … 3.1 m, plus one cell of margin on each side.
        assert_eq!((grid.width, grid.height), (64, 64));
        assert!((grid.origin_m[0] + 3.2).abs() < 1e-9 && (grid.origin_m[1] + 3.2).abs() < 1e-9);
        let state = |x: f64, y: f64| {
            let (ix, iy) = grid.cell_at([x, y]).expect("inside");
            grid.state(ix, iy)
        };
        // Every wall cell holds a return: 4 walls × 62 cells, corners shared (a corner
        // cell holds only 2.5 cm of each wall, beams are 3–6 cm apart there: it may be missed).
        for i in 1..61 {
            let t = -3.05 + 0.1 * i as f64;
            for (x, y) in [(t, -3.025), (t, 3.025), (-3.025, t), (3.025, t)] {
                assert_eq!(state(x, y), CellState::Occupied, "wall at ({x}, {y})");
            }
        }
        let (unknown, free, occupied) = grid.counts();
        assert!((240..=244).contains(&occupied), "{occupied}");
        // Everything inside the walls is free: 60 × 60 cells; the rest was never seen.
        assert_eq!(free, 3600);
        assert_eq!(unknown, 64 * 64 - occupied - 3600);
        for i in 0..60 {
            for j in 0..60 {
                let (x, y) = (-2.95 + 0.1 * i as f64, -2.95 + 0.1 * j as f64);
                assert_eq!(state(x, y), CellState::Free, "({x}, {y})");
            }
        }
    }

    #[test]
    fn long_beams_clear_up_to_max_range_only() {
        // One beam along +x with a return at 10 m, and max range 4 m: free to 4 m, nothing
        // occupied, nothing seen beyond.
        let scan = Scan2::from_polar(&[0.0], &[10.0], 50.0).expect("scan");
        let params = GridParams {
            max_range_m: 4.0,
            ..GridParams::default()
        };
        let grid = OccupancyGrid::from_scans([(Pose2::IDENTITY, &scan)], &params).expect("grid");
        let (_, free, occupied) = grid.counts();
        assert_eq!(occupied, 0);
        // Cells 0.0–4.0 m along the beam: 40, or 41 when 4.0 m rounds into the next cell.
        assert!((40..=41).contains(&free), "{free} free");
        assert!(grid.width <= 43 && grid.height == 3);
    }

    #[test]
    fn returns_win_over_passes_and_repeated_passes_clear() {
        let scene = room(4.0);
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let scan = scan_of(&scene, pose);
        let once = OccupancyGrid::from_scans([(pose, &scan)], &GridParams::default()).unwrap();
        let thrice =
            OccupancyGrid::from_scans([(pose, &scan); 3].iter().copied(), &GridParams::default())
                .unwrap();
        let (ix, iy) = once.cell_at([1.0, 0.3]).unwrap();
        // Inside: 33 % after one scan; after three, −2.1 clamps to −2.0: 12 %.
        assert_eq!(once.occupancy(ix, iy), 33);
        assert_eq!(thrice.occupancy(ix, iy), 12);
        let (wx, wy) = once.cell_at([1.99, 0.03]).unwrap();
        assert_eq!(once.occupancy(wx, wy), 70);
        assert_eq!(thrice.occupancy(wx, wy), 93);
    }

    #[test]
    fn bad_input_is_an_error_not_a_huge_allocation() {
        let scan = Scan2::from_polar(&[0.0], &[1.0], 50.0).unwrap();
        let p = GridParams::default();
        let none: [(Pose2, &Scan2); 0] = [];
        assert_eq!(OccupancyGrid::from_scans(none, &p), Err(GridError::NoScans));
        let far = [
            (Pose2::IDENTITY, &scan),
            (Pose2::new(1e6, -1e6, 0.0), &scan),
        ];
        let err = OccupancyGrid::from_scans(far, &p).unwrap_err();
        assert!(matches!(err, GridError::TooLarge { .. }), "{err}");
        assert!(err.to_string().contains("exceeds"), "{err}");
        let nan = [(Pose2::new(f64::NAN, 0.0, 0.0), &scan)];
        assert_eq!(
            OccupancyGrid::from_scans(nan, &p),
            Err(GridError::NonFinitePose { index: 0 })
        );
        let zero = GridParams {
            resolution_m: 0.0,
            ..GridParams::default()
        };
        assert!(matches!(
            OccupancyGrid::from_scans([(Pose2::IDENTITY, &scan)], &zero),
            Err(GridError::InvalidParams(_))
        ));
    }

    #[test]
    fn traversal_visits_every_crossed_cell_without_the_last() {
        let mut cells = Vec::new();
        traverse([0.5, 0.5], [5.5, -1.5], |x, y| cells.push((x, y)));
        // 5 steps in x, 2 in y: 7 cells before the end cell (5, −2), 4-connected.
        assert_eq!(cells.len(), 7, "{cells:?}");
        assert_eq!(cells[0], (0, 0));
        assert!(!cells.contains(&(5, -2)));
        for w in cells.windows(2) {
            assert_eq!((w[1].0 - w[0].0).abs() + (w[1].1 - w[0].1).abs(), 1);
        }
        // The exact crossings of y = 0 (x = 1.75) and y = −1 (x = 4.25).
        assert!(
            cells.contains(&(1, -1)) && cells.contains(&(4, -2)),
            "{cells:?}"
        );
        let mut none = 0;
        traverse([3.2, 3.7], [3.9, 3.1], |_, _| none += 1);
        assert_eq!(none, 0);
    }

    #[test]
    fn a_window_is_the_same_cells_as_the_whole_grid_there() {
        let pose = Pose2::new(0.7, -0.4, 0.5);
        let scan = scan_of(&room(6.05), pose);
        let whole = OccupancyGrid::from_scans([(pose, &scan)], &GridParams::default()).unwrap();
        let params = GridParams {
            window_m: Some([0.0, 0.0, 2.0, 5.0]),
            ..GridParams::default()
        };
        let part = OccupancyGrid::from_scans([(pose, &scan)], &params).unwrap();
        // x: 0–2 m and a cell of margin each side (−0.1–2.2 m); y: 0 m to the wall's cells.
        assert_eq!((part.width, part.height), (23, 33));
        for iy in 0..part.height {
            for ix in 0..part.width {
                let (wx, wy) = whole.cell_at(part.cell_center(ix, iy)).expect("inside");
                assert_eq!(
                    part.occupancy(ix, iy),
                    whole.occupancy(wx, wy),
                    "({ix}, {iy})"
                );
            }
        }
        let away = GridParams {
            window_m: Some([100.0, 100.0, 110.0, 110.0]),
            ..GridParams::default()
        };
        // Beyond the map: the window, all unknown.
        let empty = OccupancyGrid::from_scans([(pose, &scan)], &away).unwrap();
        assert_eq!((empty.width, empty.height), (102, 102));
        assert_eq!(empty.counts(), (102 * 102, 0, 0));
    }

    #[test]
    fn coarsen_to_fit_grows_the_cells_until_the_grid_fits() {
        let pose = Pose2::new(0.7, -0.4, 0.5);
        let scan = scan_of(&room(6.05), pose);
        let small = GridParams {
            max_cells: 1000,
            ..GridParams::default()
        };
        assert!(matches!(
            OccupancyGrid::from_scans([(pose, &scan)], &small),
            Err(GridError::TooLarge { .. })
        ));
        let fit = GridParams {
            coarsen_to_fit: true,
            ..small
        };
        let grid = OccupancyGrid::from_scans([(pose, &scan)], &fit).unwrap();
        assert!(
            grid.width * grid.height <= 1000,
            "{} × {}",
            grid.width,
            grid.height
        );
        // 64 × 64 cells of 0.1 m into 1000: cells about 0.2 m, not much coarser.
        assert!(
            (0.19..0.23).contains(&grid.resolution_m),
            "{}",
            grid.resolution_m
        );
        let (_, free, occupied) = grid.counts();
        assert!(
            free > 600 && occupied > 80,
            "{free} free, {occupied} occupied"
        );
    }
}
