//! The grid's tunables and their ranges, and why a grid could not be built.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Tunables of the grid, each with its unit. The defaults suit leveled outdoor scans.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
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
    /// A pass through a cell beside a cell that holds a return (of any scan) counts this
    /// share of `log_odds_miss`: poses are off by about a cell, so a beam passing that close
    /// to a surface may have passed through it. Without it the inside of a trunk or a thick
    /// wall, where no return ever lands, turns free at the first stray pass. 0.25: four such
    /// passes weigh one clean pass, so a cell that only a parked car or a standing person
    /// stood beside still clears over time.
    pub miss_weight_beside_return: f32,
    /// Clamp of the log-odds (keeps a cell able to change its mind after many scans).
    pub log_odds_min: f32,
    /// Upper clamp of the log-odds (see `log_odds_min`).
    pub log_odds_max: f32,
    /// Occupied at or above this probability…
    pub occupied_threshold: f64,
    /// …free at or below this one; in between (and never seen) unknown.
    pub free_threshold: f64,
    /// Refuse grids with more cells than this (10 bytes a cell while building): a stray
    /// pose kilometres away gives a clear error instead of a huge allocation. The default
    /// 2²⁴ cells is 410 m × 410 m at 0.1 m.
    pub max_cells: usize,
    /// Instead of refusing a grid over `max_cells`, make the cells as much coarser as it
    /// takes (an overview of a map too big for `resolution_m`).
    pub coarsen_to_fit: bool,
    /// Only this part of the map, `[min x, min y, max x, max y]` (m): the beams of every scan
    /// that reach it still count.
    pub window_m: Option<[f64; 4]>,
    /// The sensor's blind zone (m): no beam clears a cell nearer than this to the scan's
    /// origin. A spinning lidar reports nothing inside its minimum range, so its silence there
    /// says nothing about the space (0.5 m: about the minimum range of the lidars levelmap
    /// reads; the robot's own body is often in it).
    pub blind_zone_m: f64,
    /// A beam with a return clears up to this much short of it (m), measured across the
    /// surface (its direction from the chords to the neighbouring returns; at a grazing
    /// angle the beam stops that much further back, at most ten times): the cells just in
    /// front of a surface keep it when a scan's pose is a little off (0.1 m: a cell, and
    /// about the error of a solved pose), and a ray crossing the corner of a cell that is
    /// mostly inside the object does not call that cell free.
    pub clear_short_of_hit_m: f64,
    /// A beam without a return whose free length is not known (a planar scanner's; a
    /// leveled column tells how far it saw the ground, `FanBeam::free_to_m`) clears free
    /// space up to this range (m) and no further: open space is likely near the sensor, but
    /// the return may also have been lost (glass, black paint, a reflection), and such a beam
    /// must not clear a wall that other scans saw. 5 m, Cartographer's
    /// `missing_data_ray_length` in 2D.
    pub no_return_free_m: f64,
    /// Neighbouring beams at most this far apart in bearing (rad) clear the wedge between
    /// them, not only their own lines: beams diverge, and beyond a few metres the cells
    /// between two lines would stay unknown. 3° fills scans of 1° beams (the Freiburg logs)
    /// and every finer one, and leaves the gaps where beams were dropped.
    pub max_wedge_rad: f64,
    /// A wedge is filled only as far as its two beams are at most this far apart (m): an
    /// obstacle thinner than the gap between two beams can stand between them unseen. 0.15 m
    /// is the thinnest obstacle the map must keep (a lamp post); with beams 1° apart the
    /// wedges fill up to 8.6 m, and beyond each beam clears its own line.
    pub wedge_max_width_m: f64,
    /// Two returns fill their wedge only when their ranges differ by at most this (m)…
    pub wedge_max_jump_m: f64,
    /// …or this fraction of the nearer range, whichever is more: a larger jump is an edge
    /// (one beam passes an object's side, the other hits it), and the space behind the
    /// nearer object is not seen.
    pub wedge_max_jump_ratio: f64,
}

impl Default for GridParams {
    fn default() -> Self {
        GridParams {
            resolution_m: 0.1,
            max_range_m: 40.0,
            log_odds_hit: 0.85,
            log_odds_miss: -0.7,
            miss_weight_beside_return: 0.25,
            log_odds_min: -2.0,
            log_odds_max: 3.5,
            occupied_threshold: 0.65,
            free_threshold: 0.35,
            max_cells: 1 << 24,
            coarsen_to_fit: false,
            window_m: None,
            blind_zone_m: 0.5,
            clear_short_of_hit_m: 0.1,
            no_return_free_m: 5.0,
            max_wedge_rad: 3f64.to_radians(),
            wedge_max_width_m: 0.15,
            wedge_max_jump_m: 0.5,
            wedge_max_jump_ratio: 0.1,
        }
    }
}

/// Why a grid could not be built.
#[derive(Clone, Debug, PartialEq)]
pub enum GridError {
    /// A parameter is out of its range.
    InvalidParams(String),
    /// No scan was given.
    NoScans,
    /// The pose of scan `index` (in input order) has a NaN or infinite component.
    NonFinitePose {
        /// Index of the scan.
        index: usize,
    },
    /// The scans span more cells than [`GridParams::max_cells`].
    TooLarge {
        /// Cells the grid would have along x.
        width: u64,
        /// Cells the grid would have along y.
        height: u64,
        /// The limit, [`GridParams::max_cells`].
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

/// Checks every parameter against its range.
pub(super) fn check(params: &GridParams) -> Result<(), GridError> {
    let bad = |why: &str| Err(GridError::InvalidParams(why.to_string()));
    let p = params;
    if !(p.resolution_m.is_finite() && p.resolution_m > 0.0) {
        return bad("resolution_m must be positive");
    }
    if !(p.max_range_m.is_finite() && p.max_range_m > 0.0) {
        return bad("max_range_m must be positive");
    }
    let non_negative = |v: f64| v.is_finite() && v >= 0.0;
    if ![
        p.blind_zone_m,
        p.clear_short_of_hit_m,
        p.no_return_free_m,
        p.max_wedge_rad,
        p.wedge_max_width_m,
        p.wedge_max_jump_m,
        p.wedge_max_jump_ratio,
    ]
    .into_iter()
    .all(non_negative)
    {
        return bad(
            "blind_zone_m, clear_short_of_hit_m, no_return_free_m and the wedge limits must be finite and ≥ 0",
        );
    }
    if p.max_wedge_rad >= std::f64::consts::PI {
        return bad("max_wedge_rad must be below π");
    }
    if !(0.0..=1.0).contains(&p.miss_weight_beside_return) {
        return bad("miss_weight_beside_return must be within [0, 1]");
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
