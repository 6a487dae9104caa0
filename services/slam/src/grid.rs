//! The occupancy grid of a scan-based map (DESIGN §3 "Map"): the leveled scans at their
//! optimized node poses, ray cast into a grid of log-odds. Every beam clears the cells it
//! crosses (a supercover traversal, see `traverse`) and marks the cell of its return
//! occupied. The result is served as
//! occupancy per cent in the layout of ROS `nav_msgs/OccupancyGrid` (−1 unknown, 0–100;
//! row-major, row 0 the southernmost), so the PNG/PGM encoders and any ROS client read it
//! the same way.
//!
//! Within one scan a cell is updated at most once, and a return wins over a beam crossing
//! it: rays grazing a wall would otherwise erase the wall their neighbours just hit.

use crate::matching::Scan2;
use crate::se2::Pose2;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Tunables of the grid, each with its unit. The defaults suit leveled outdoor scans.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GridParams {
    /// Cell edge (m).
    pub resolution_m: f64,
    /// Beams are used up to this range (m); a longer return clears free space up to it and
    /// marks nothing occupied (far returns are sparse and their bearing error is large).
    pub max_range_m: f64,
    /// Log-odds added to a cell that holds a return: 0.85 is p ≈ 0.70, so one return
    /// already reads as occupied.
    pub log_odds_hit: f32,
    /// Log-odds added to a cell a beam crosses: −0.7 is p ≈ 0.33, so one pass reads as
    /// free, and a cell with two returns survives one grazing pass.
    pub log_odds_miss: f32,
    /// Clamp of the log-odds (keeps a cell able to change its mind after many scans).
    pub log_odds_min: f32,
    pub log_odds_max: f32,
    /// Occupied at or above this probability…
    pub occupied_threshold: f64,
    /// …free at or below this one; in between (and never seen) unknown.
    pub free_threshold: f64,
    /// Refuse grids with more cells than this (8 bytes a cell while building): a stray
    /// pose kilometres away gives a clear error instead of a huge allocation. The default
    /// 2²⁴ cells is 410 m × 410 m at 0.1 m.
    pub max_cells: usize,
    /// Instead of refusing a grid over `max_cells`, make the cells as much coarser as it
    /// takes (an overview of a map too big for `resolution_m`).
    pub coarsen_to_fit: bool,
    /// Only this part of the map, `[min x, min y, max x, max y]` (m): the beams of every scan
    /// that reach it still count.
    pub window_m: Option<[f64; 4]>,
}

impl Default for GridParams {
    fn default() -> Self {
        GridParams {
            resolution_m: 0.1,
            max_range_m: 40.0,
            log_odds_hit: 0.85,
            log_odds_miss: -0.7,
            log_odds_min: -2.0,
            log_odds_max: 3.5,
            occupied_threshold: 0.65,
            free_threshold: 0.35,
            max_cells: 1 << 24,
            coarsen_to_fit: false,
            window_m: None,
        }
    }
}

/// What a cell is known to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum CellState {
    Unknown,
    Free,
    Occupied,
}

/// Why a grid could not be built.
#[derive(Clone, Debug, PartialEq)]
pub enum GridError {
    /// A parameter is out of its range.
    InvalidParams(String),
    /// No scan was given.
    NoScans,
    /// The pose of scan `index` (in input order) has a NaN or infinite component.
    NonFinitePose { index: usize },
    /// The scans span more cells than [`GridParams::max_cells`].
    TooLarge {
        width: u64,
        height: u64,
        max_cells: usize,
    },
}

impl fmt::Display for GridError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GridError::InvalidParams(why) => write!(f, "invalid grid parameters: {why}"),
            GridError::NoScans => write!(f, "no scans to build a grid from"),
            GridError::NonFinitePose { index } => write!(f, "scan {index} has a non-finite pose"),
            GridError::TooLarge {
                width,
                height,
                max_cells,
            } => write!(
                f,
                "grid of {width} × {height} cells exceeds the limit of {max_cells} cells \
                 (coarser resolution, or a pose far off the map?)"
            ),
        }
    }
}

impl std::error::Error for GridError {}

/// An occupancy grid: cell (ix, iy) covers `origin_m + resolution_m·[ix, iy]` to one cell
/// further in x (east) and y (north).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Cell edge (m).
    pub resolution_m: f64,
    /// World position of cell (0, 0)'s lower-left corner (m). A multiple of the resolution,
    /// so grids of the same map at different times line up cell for cell.
    pub origin_m: [f64; 2],
    pub width: usize,
    pub height: usize,
    /// Occupancy per cent of each cell, row-major from row 0 (lowest y): −1 never seen,
    /// else 0–100 (`nav_msgs/OccupancyGrid.data`).
    pub cells: Vec<i8>,
    /// Per-cent thresholds of [`Self::state`]: occupied at or above, free at or below.
    pub occupied_percent: i8,
    pub free_percent: i8,
}

/// Cells `(x, y)` the segment from `a` to `b` crosses, in order, the cell of `b` excluded;
/// points in cell units (cell (x, y) is [x, x+1) × [y, y+1)). Amanatides–Woo traversal
/// rather than Bresenham: Bresenham's diagonal steps skip cells the beam crosses, and where
/// beams are about a cell apart those skips line up into never-seen holes in free space.
fn traverse(a: [f64; 2], b: [f64; 2], mut visit: impl FnMut(i64, i64)) {
    let end = (b[0].floor() as i64, b[1].floor() as i64);
    let (mut x, mut y) = (a[0].floor() as i64, a[1].floor() as i64);
    let d = [b[0] - a[0], b[1] - a[1]];
    let step = |d: f64| if d > 0.0 { 1 } else { -1 };
    let (sx, sy) = (step(d[0]), step(d[1]));
    // Parameter t ∈ [0, 1] along the segment at the next x (y) cell boundary, and per cell.
    let first = |a: f64, cell: i64, d: f64| {
        if d > 0.0 {
            (cell as f64 + 1.0 - a) / d
        } else if d < 0.0 {
            (a - cell as f64) / -d
        } else {
            f64::INFINITY
        }
    };
    let (mut tx, mut ty) = (first(a[0], x, d[0]), first(a[1], y, d[1]));
    let (dtx, dty) = (1.0 / d[0].abs(), 1.0 / d[1].abs());
    // Exactly this many steps; the guards keep rounding from leaving the cells' box.
    let steps = (end.0 - x).abs() + (end.1 - y).abs();
    for _ in 0..steps {
        visit(x, y);
        if y == end.1 || (tx < ty && x != end.0) {
            x += sx;
            tx += dtx;
        } else {
            y += sy;
            ty += dty;
        }
    }
}

fn check(params: &GridParams) -> Result<(), GridError> {
    let bad = |why: &str| Err(GridError::InvalidParams(why.to_string()));
    let p = params;
    if !(p.resolution_m.is_finite() && p.resolution_m > 0.0) {
        return bad("resolution_m must be positive");
    }
    if !(p.max_range_m.is_finite() && p.max_range_m > 0.0) {
        return bad("max_range_m must be positive");
    }
    if !(p.log_odds_hit > 0.0 && p.log_odds_miss < 0.0) {
        return bad("log_odds_hit must be positive and log_odds_miss negative");
    }
    if !(p.log_odds_min < 0.0 && p.log_odds_max > 0.0) {
        return bad("log_odds_min must be negative and log_odds_max positive");
    }
    if !(0.0 < p.free_threshold
        && p.free_threshold < p.occupied_threshold
        && p.occupied_threshold < 1.0)
    {
        return bad("thresholds must satisfy 0 < free_threshold < occupied_threshold < 1");
    }
    Ok(())
}

impl OccupancyGrid {
    /// Ray casts scans at their poses (the scanner's pose in the map frame). The grid covers
    /// every scan origin and every beam (up to `max_range_m`), with one cell of margin.
    pub fn from_scans<'a>(
        scans: impl IntoIterator<Item = (Pose2, &'a Scan2)>,
        params: &GridParams,
    ) -> Result<OccupancyGrid, GridError> {
        check(params)?;
        let scans: Vec<(Pose2, &Scan2)> = scans.into_iter().collect();
        if scans.is_empty() {
            return Err(GridError::NoScans);
        }
        if let Some(index) = scans.iter().position(|(p, _)| !p.is_finite()) {
            return Err(GridError::NonFinitePose { index });
        }
        // Each beam in world coordinates: its end (clipped to max range) and whether it is
        // a return.
        let max_r = params.max_range_m;
        let beams = |pose: Pose2, scan: &'a Scan2| {
            scan.points()
                .iter()
                .zip(scan.ranges_m())
                .map(move |(p, &r)| {
                    let hit = r <= max_r;
                    let s = if hit { 1.0 } else { max_r / r };
                    (pose.transform_point([p[0] * s, p[1] * s]), hit)
                })
        };
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let window = params.window_m;
        // With a window, only the scans whose beams reach into it.
        let mut scans_used = Vec::with_capacity(scans.len());
        for &(pose, scan) in &scans {
            let (mut slo, mut shi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for (q, _) in beams(pose, scan).chain([([pose.x, pose.y], false)]) {
                for d in 0..2 {
                    slo[d] = slo[d].min(q[d]);
                    shi[d] = shi[d].max(q[d]);
                }
            }
            if window
                .is_some_and(|w| shi[0] < w[0] || slo[0] > w[2] || shi[1] < w[1] || slo[1] > w[3])
            {
                continue;
            }
            for d in 0..2 {
                lo[d] = lo[d].min(slo[d]);
                hi[d] = hi[d].max(shi[d]);
            }
            scans_used.push((pose, scan));
        }
        let scans = scans_used;
        if let Some(w) = window {
            (lo[0], lo[1]) = (lo[0].max(w[0]), lo[1].max(w[1]));
            (hi[0], hi[1]) = (hi[0].min(w[2]), hi[1].min(w[3]));
            // No scan reaches it: the window, all unknown.
            if scans.is_empty() || lo[0] >= hi[0] || lo[1] >= hi[1] {
                (lo, hi) = ([w[0], w[1]], [w[2], w[3]]);
            }
        }
        let mut res = params.resolution_m;
        let (origin_m, w, h) = loop {
            let origin_m = [
                ((lo[0] / res).floor() - 1.0) * res,
                ((lo[1] / res).floor() - 1.0) * res,
            ];
            // Sizes as f64 first: a pose far off can make them overflow any integer.
            let size = |d: usize| ((hi[d] - origin_m[d]) / res).floor() + 2.0;
            let (w, h) = (size(0), size(1));
            if w * h <= params.max_cells as f64 {
                break (origin_m, w, h);
            }
            if !params.coarsen_to_fit || !(w * h).is_finite() {
                return Err(GridError::TooLarge {
                    width: w.min(u64::MAX as f64) as u64,
                    height: h.min(u64::MAX as f64) as u64,
                    max_cells: params.max_cells,
                });
            }
            // The margin cells make one step sometimes fall short: step again.
            res *= (w * h / params.max_cells as f64).sqrt() * 1.001;
        };
        let (width, height) = (w as usize, h as usize);
        // Cell units: cell (x, y) is [x, x+1) × [y, y+1).
        let units = |q: [f64; 2]| [(q[0] - origin_m[0]) / res, (q[1] - origin_m[1]) / res];
        let cell = |q: [f64; 2]| {
            let u = units(q);
            (u[0].floor() as i64, u[1].floor() as i64)
        };
        // Cells outside the grid (beams leaving a window) are not kept.
        let index = |(x, y): (i64, i64)| {
            (x >= 0 && y >= 0 && (x as usize) < width && (y as usize) < height)
                .then(|| y as usize * width + x as usize)
        };
        let mut log_odds = vec![0f32; width * height];
        // The scan (counted from 1) that last updated a cell, 2k+1 for a pass and 2k+2 for a
        // return; 0: never seen.
        let mut mark = vec![0u32; width * height];
        let clamp = |l: f32| l.clamp(params.log_odds_min, params.log_odds_max);
        for (k, &(pose, scan)) in scans.iter().enumerate() {
            let (pass, ret) = (2 * k as u32 + 1, 2 * k as u32 + 2);
            for (q, hit) in beams(pose, scan) {
                let Some(c) = index(cell(q)) else { continue };
                if hit && mark[c] != ret {
                    mark[c] = ret;
                    log_odds[c] = clamp(log_odds[c] + params.log_odds_hit);
                }
            }
            let from = units([pose.x, pose.y]);
            for (q, hit) in beams(pose, scan) {
                let to = cell(q);
                let mut clear = |x: i64, y: i64| {
                    let Some(c) = index((x, y)) else { return };
                    if mark[c] != ret && mark[c] != pass {
                        mark[c] = pass;
                        log_odds[c] = clamp(log_odds[c] + params.log_odds_miss);
                    }
                };
                traverse(from, units(q), &mut clear);
                if !hit {
                    clear(to.0, to.1);
                }
            }
        }
        let cells = log_odds
            .iter()
            .zip(&mark)
            .map(|(&l, &m)| {
                if m == 0 {
                    -1
                } else {
                    (100.0 / (1.0 + (-f64::from(l)).exp())).round() as i8
                }
            })
            .collect();
        Ok(OccupancyGrid {
            resolution_m: res,
            origin_m,
            width,
            height,
            cells,
            occupied_percent: (params.occupied_threshold * 100.0).round() as i8,
            free_percent: (params.free_threshold * 100.0).round() as i8,
        })
    }

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
