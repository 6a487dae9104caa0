//! Building the grid: every scan's beams ray cast at its pose into log-odds, the wedges
//! between neighbouring beams filled.

use super::fan::{BeamFan, FanBeam};
use super::params::check;
use super::{GridError, GridParams, OccupancyGrid};
use crate::matching::Scan2;
use crate::se2::Pose2;

/// One beam as the grid uses it, in the scan's frame: where it starts, its direction, how
/// far it clears, and whether its end holds a return (within `max_range_m`).
#[derive(Clone, Copy)]
struct Ray {
    from: [f64; 2],
    direction: [f64; 2],
    clear_m: f64,
    hit: bool,
    /// A return's ray clears up to this much short of it (m).
    short_m: f64,
}

impl Ray {
    fn of(beam: &FanBeam, params: &GridParams) -> Ray {
        let (clear_m, hit) = match beam.range_m {
            Some(r) if r <= params.max_range_m => (r, true),
            Some(_) => (params.max_range_m, false),
            None => (
                beam.free_to_m
                    .unwrap_or(params.no_return_free_m)
                    .min(params.max_range_m),
                false,
            ),
        };
        Ray {
            from: beam.from_m,
            direction: [beam.bearing_rad.cos(), beam.bearing_rad.sin()],
            clear_m,
            hit,
            short_m: params.clear_short_of_hit_m,
        }
    }

    /// Where the ray ends, in the scan's frame.
    fn end(&self) -> [f64; 2] {
        [
            self.from[0] + self.direction[0] * self.clear_m,
            self.from[1] + self.direction[1] * self.clear_m,
        ]
    }

    /// The point `at_m` along the ray, in the map frame.
    fn point(&self, pose: Pose2, at_m: f64) -> [f64; 2] {
        pose.transform_point([
            self.from[0] + self.direction[0] * at_m,
            self.from[1] + self.direction[1] * at_m,
        ])
    }
}

/// The sine of the shallowest angle at which a return still places its surface: below about
/// 6°, where a return lands along the surface says little about where the surface is, so a
/// ray stops at most ten times `clear_short_of_hit_m` short.
const MIN_SURFACE_SINE: f64 = 0.1;

/// The scan's rays and the wedges to fill between neighbours: (ray i, ray j, bearing gap).
/// Neighbours share a wedge when they were seen from places at most a cell apart (the wedge
/// has one apex) and see alike.
///
/// A return stops its ray `clear_short_of_hit_m` short of the surface measured across the
/// surface (its direction taken from the chords to the neighbouring returns), not along the
/// ray: a ray grazing a wall would otherwise clear the wall's own cells beyond its hit
/// whenever the pose is a little off. Neighbours across an edge (a trunk before a wall) give a
/// chord nearly along the beams: the ray then stops further short, which costs a little free
/// space and never calls a surface free.
fn rays(fan: &BeamFan, params: &GridParams) -> (Vec<Ray>, Vec<(usize, usize, f64)>) {
    let beams = fan.beams();
    let mut rays: Vec<Ray> = beams.iter().map(|b| Ray::of(b, params)).collect();
    let neighbours: Vec<(usize, usize, f64)> = fan
        .neighbours(params.max_wedge_rad)
        .filter(|&(i, j, _)| {
            let (a, b) = (&beams[i].from_m, &beams[j].from_m);
            (a[0] - b[0]).hypot(a[1] - b[1]) <= params.resolution_m
        })
        .collect();
    // The smallest sine between a return's ray and a chord to a neighbouring return.
    let mut sine = vec![1f64; rays.len()];
    for &(i, j, _) in &neighbours {
        let (a, b) = (rays[i], rays[j]);
        if !(a.hit && b.hit) {
            continue;
        }
        let (ea, eb) = (a.end(), b.end());
        let chord = [eb[0] - ea[0], eb[1] - ea[1]];
        let length = chord[0].hypot(chord[1]);
        if length == 0.0 {
            continue;
        }
        for k in [i, j] {
            let d = rays[k].direction;
            let across = (d[0] * chord[1] - d[1] * chord[0]).abs() / length;
            sine[k] = sine[k].min(across);
        }
    }
    for (ray, sine) in rays.iter_mut().zip(sine) {
        ray.short_m = params.clear_short_of_hit_m / sine.max(MIN_SURFACE_SINE);
    }
    let wedges = neighbours
        .into_iter()
        .filter(|&(i, j, _)| match (beams[i].range_m, beams[j].range_m) {
            (Some(a), Some(b)) => {
                let allowed = params
                    .wedge_max_jump_m
                    .max(params.wedge_max_jump_ratio * a.min(b));
                (a - b).abs() <= allowed
            }
            (None, None) => true,
            // A return beside a beam without one: an edge of what was seen.
            _ => false,
        })
        .collect();
    (rays, wedges)
}

impl OccupancyGrid {
    /// Ray casts matching scans (returns only) at their poses, as [`Self::from_fans`].
    pub fn from_scans<'a>(
        scans: impl IntoIterator<Item = (Pose2, &'a Scan2)>,
        params: &GridParams,
    ) -> Result<OccupancyGrid, GridError> {
        let fans: Vec<(Pose2, BeamFan)> = scans
            .into_iter()
            .map(|(pose, scan)| (pose, BeamFan::of_returns(scan)))
            .collect();
        OccupancyGrid::from_fans(fans.iter().map(|(p, f)| (*p, f)), params)
    }

    /// Ray casts scans at their poses (the scanner's pose in the map frame), the one way a
    /// grid is made. Per scan: a return within `max_range_m` adds hit evidence to its cell;
    /// each beam clears the cells it crosses from where it was seen, past the blind zone (a
    /// return short of the surface, one beyond `max_range_m` up to it, a beam without a
    /// return as far as it saw free space or up to `no_return_free_m`); the wedge between
    /// neighbouring beams that see alike is cleared too, a cell short of the line between
    /// their ends, while they are `wedge_max_width_m` apart. A pass beside a cell holding a
    /// return counts `miss_weight_beside_return`. Within one scan a cell is updated once, and a
    /// return wins over a clearing. The grid covers every scan origin, beam start and cleared
    /// beam, with one cell of margin.
    pub fn from_fans<'a>(
        scans: impl IntoIterator<Item = (Pose2, &'a BeamFan)>,
        params: &GridParams,
    ) -> Result<OccupancyGrid, GridError> {
        let scans: Vec<(Pose2, &BeamFan)> = scans.into_iter().collect();
        OccupancyGrid::from_fans_made_again(|| scans.iter().copied(), params)
    }

    /// [`Self::from_fans`] of scans made again on each of its three passes over them (the
    /// grid's bounds, the cells beside a return, the casting): `scans()` gives them in the
    /// same order every time. The memory it takes is the grid's and one scan's, not every
    /// scan's beams at once: the way to a whole site's map.
    pub fn from_fans_made_again<I, F>(
        scans: impl Fn() -> I,
        params: &GridParams,
    ) -> Result<OccupancyGrid, GridError>
    where
        I: Iterator<Item = (Pose2, F)>,
        F: std::borrow::Borrow<BeamFan>,
    {
        check(params)?;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let window = params.window_m;
        // With a window, only the scans whose beams reach into it.
        let mut used = Vec::new();
        for (index, (pose, fan)) in scans().enumerate() {
            if !pose.is_finite() {
                return Err(GridError::NonFinitePose { index });
            }
            let (rays, _) = rays(fan.borrow(), params);
            let (mut slo, mut shi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            let ends = rays
                .iter()
                .flat_map(|ray| [ray.point(pose, 0.0), ray.point(pose, ray.clear_m)]);
            for q in ends.chain([[pose.x, pose.y]]) {
                for d in 0..2 {
                    slo[d] = slo[d].min(q[d]);
                    shi[d] = shi[d].max(q[d]);
                }
            }
            let outside = window
                .is_some_and(|w| shi[0] < w[0] || slo[0] > w[2] || shi[1] < w[1] || slo[1] > w[3]);
            used.push(!outside);
            if outside {
                continue;
            }
            for d in 0..2 {
                lo[d] = lo[d].min(slo[d]);
                hi[d] = hi[d].max(shi[d]);
            }
        }
        if used.is_empty() {
            return Err(GridError::NoScans);
        }
        // The scans used, made again with their rays and wedges, in the same order.
        let scans_used = || {
            scans()
                .zip(&used)
                .filter(|(_, used)| **used)
                .map(|((pose, fan), _)| {
                    let (rays, wedges) = rays(fan.borrow(), params);
                    (pose, rays, wedges)
                })
        };
        if let Some(w) = window {
            (lo[0], lo[1]) = (lo[0].max(w[0]), lo[1].max(w[1]));
            (hi[0], hi[1]) = (hi[0].min(w[2]), hi[1].min(w[3]));
            // No scan reaches it: the window, all unknown.
            if !used.contains(&true) || lo[0] >= hi[0] || lo[1] >= hi[1] {
                (lo, hi) = ([w[0], w[1]], [w[2], w[3]]);
            }
        }
        let mut res = params.resolution_m;
        // A cell of margin all round: a window's edge cells then see the returns just beyond
        // it (`beside_a_return`), as the whole grid's do, and its tiles are cut without it.
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
        let blind = params.blind_zone_m;
        let returns = scans_used().flat_map(|(pose, rays, _)| {
            rays.into_iter()
                .filter(|ray| ray.hit)
                .map(move |ray| ray.point(pose, ray.clear_m))
        });
        let beside_return = beside_a_return(returns, width, height, |q| index(cell(q)));
        let miss = params.log_odds_miss;
        let miss_beside = miss * params.miss_weight_beside_return;
        for (k, (pose, rays, wedges)) in scans_used().enumerate() {
            let (pass, ret) = (2 * k as u32 + 1, 2 * k as u32 + 2);
            for ray in rays.iter().filter(|ray| ray.hit) {
                let Some(c) = index(cell(ray.point(pose, ray.clear_m))) else {
                    continue;
                };
                if mark[c] != ret {
                    mark[c] = ret;
                    log_odds[c] = clamp(log_odds[c] + params.log_odds_hit);
                }
            }
            let mut clear = |x: i64, y: i64| {
                let Some(c) = index((x, y)) else { return };
                if mark[c] != ret && mark[c] != pass {
                    mark[c] = pass;
                    let miss = if beside_return[c] { miss_beside } else { miss };
                    log_odds[c] = clamp(log_odds[c] + miss);
                }
            };
            // From the blind zone to `to_m` along `direction` from `from`, the end cell
            // cleared when `to_end`.
            let mut clear_line = |from: [f64; 2], direction: [f64; 2], to_m: f64, to_end: bool| {
                if to_m <= blind {
                    return;
                }
                let along = |m: f64| {
                    pose.transform_point([from[0] + direction[0] * m, from[1] + direction[1] * m])
                };
                let end = along(to_m);
                traverse(units(along(blind)), units(end), &mut clear);
                if to_end {
                    let (x, y) = cell(end);
                    clear(x, y);
                }
            };
            for ray in &rays {
                if ray.hit {
                    clear_line(ray.from, ray.direction, ray.clear_m - ray.short_m, true);
                } else {
                    clear_line(ray.from, ray.direction, ray.clear_m, true);
                }
            }
            for &(i, j, gap) in &wedges {
                let (a, b) = (rays[i], rays[j]);
                // The chord between the two ends: a surface both beams saw lies along it.
                let (ea, eb) = (a.end(), b.end());
                let chord = [eb[0] - ea[0], eb[1] - ea[1]];
                let chord_m = chord[0].hypot(chord[1]);
                // Filled only as far as the two beams are `wedge_max_width_m` apart: beyond,
                // something thinner could stand between them unseen.
                let reach = params.wedge_max_width_m / (2.0 * (0.5 * gap).sin());
                // Rays between the two, one a cell apart at the far end.
                let far = a.clear_m.max(b.clear_m).min(reach);
                let between = ((gap * far / res).ceil() as usize).saturating_sub(1);
                let bearing_a = a.direction[1].atan2(a.direction[0]);
                for s in 1..=between {
                    let t = s as f64 / (between + 1) as f64;
                    let from = [
                        a.from[0] + (b.from[0] - a.from[0]) * t,
                        a.from[1] + (b.from[1] - a.from[1]) * t,
                    ];
                    let bearing = bearing_a + gap * t;
                    let direction = [bearing.cos(), bearing.sin()];
                    // Each stops 1.5 cells (measured across the chord) short of it: a beam
                    // grazing a wall would otherwise clear the wall's own cells between the
                    // two hits.
                    let across = if chord_m > 0.0 {
                        (direction[0] * chord[1] - direction[1] * chord[0]).abs() / chord_m
                    } else {
                        1.0
                    };
                    let margin = 1.5 * res / across.max(0.05);
                    let to_m = (a.clear_m + (b.clear_m - a.clear_m) * t - margin).min(reach);
                    clear_line(from, direction, to_m, false);
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

/// Per cell (row-major, `width` × `height`): does one of its eight neighbours hold one of
/// the `returns` (map points)? `cell_of` gives a map point's cell index, if in the grid.
fn beside_a_return(
    returns: impl Iterator<Item = [f64; 2]>,
    width: usize,
    height: usize,
    cell_of: impl Fn([f64; 2]) -> Option<usize>,
) -> Vec<bool> {
    let mut holds = vec![false; width * height];
    for c in returns.filter_map(cell_of) {
        holds[c] = true;
    }
    let mut beside = vec![false; width * height];
    for (c, _) in holds.iter().enumerate().filter(|(_, h)| **h) {
        let (x, y) = (c % width, c / width);
        for ny in y.saturating_sub(1)..(y + 2).min(height) {
            for nx in x.saturating_sub(1)..(x + 2).min(width) {
                if (nx, ny) != (x, y) {
                    beside[ny * width + nx] = true;
                }
            }
        }
    }
    beside
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
