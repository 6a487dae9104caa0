//! Building the grid: every scan's beams ray cast at its pose into log-odds.

use super::params::check;
use super::{GridError, GridParams, OccupancyGrid};
use crate::matching::Scan2;
use crate::se2::Pose2;

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
}

/// Cells `(x, y)` the segment from `a` to `b` crosses, in order, the cell of `b` excluded;
/// points in cell units (cell (x, y) is [x, x+1) × [y, y+1)). Amanatides–Woo traversal
/// rather than Bresenham: Bresenham's diagonal steps skip cells the beam crosses, and where
/// beams are about a cell apart those skips line up into never-seen holes in free space.
pub(super) fn traverse(a: [f64; 2], b: [f64; 2], mut visit: impl FnMut(i64, i64)) {
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
