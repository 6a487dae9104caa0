//! Depth-first branch and bound over (x, y, θ) (Hess et al. 2016, section V.C, Algorithm 3):
//! the scan is rotated once per angular step and discretized into cells; a candidate is an
//! angle and a square of 2ʰ × 2ʰ cell offsets, bounded from above by the scan scored on
//! pooled level h. Candidates are taken best first, and a branch whose bound cannot beat the
//! best leaf so far is cut, so the result is the exact best of the discretized window.

use super::grid::{Cells, FULL, PrecomputedGrids};
use super::{CorrelativeMatch, SearchWindow};
use crate::Pose2;
use std::collections::HashSet;

/// The scan's returns kept for the search: within `max_range_m`, one per cell of
/// `resolution_m` (in the scan frame; the search thins at the grid's resolution), so dense
/// parts of the scan do not outweigh the rest.
pub fn thin_points(points: &[[f64; 2]], resolution_m: f64, max_range_m: f64) -> Vec<[f64; 2]> {
    let mut seen = HashSet::new();
    points
        .iter()
        .filter(|p| p[0].hypot(p[1]) <= max_range_m)
        .filter(|p| {
            seen.insert((
                (p[0] / resolution_m).floor() as i64,
                (p[1] / resolution_m).floor() as i64,
            ))
        })
        .copied()
        .collect()
}

/// The angles searched around `theta0`: steps small enough that the farthest return moves
/// by at most one cell, `acos(1 − r² / 2d²)` (Hess et al., eq. 7).
fn angles(theta0: f64, window: &SearchWindow, resolution_m: f64, max_range_m: f64) -> Vec<f64> {
    let d = max_range_m.max(resolution_m);
    let step = (1.0 - resolution_m * resolution_m / (2.0 * d * d))
        .clamp(-1.0, 1.0)
        .acos()
        .max(1e-4);
    if window.angular_rad >= std::f64::consts::PI {
        let n = (std::f64::consts::TAU / step).ceil() as i64;
        let step = std::f64::consts::TAU / n as f64;
        return (-(n / 2)..n - n / 2)
            .map(|k| theta0 + k as f64 * step)
            .collect();
    }
    let k = (window.angular_rad / step).ceil() as i64;
    (-k..=k).map(|i| theta0 + i as f64 * step).collect()
}

#[derive(Clone, Copy, Debug)]
struct Candidate {
    angle: usize,
    dx: i64,
    dy: i64,
    /// Sum of cell values (level 0: the score × 255 × points; above: an upper bound).
    sum: u32,
}

/// The scan discretized at each angle, and the window in cells.
pub(super) struct Problem<'a> {
    grids: &'a PrecomputedGrids,
    angles: Vec<f64>,
    /// Per angle, the cell of each return at zero offset.
    cells: Vec<Cells>,
    initial: Pose2,
    /// Offsets searched: −reach..=reach cells in x and in y.
    reach: i64,
    /// Smallest sum accepted.
    min_sum: u32,
    /// Candidates scored.
    nodes: usize,
    /// Leaves whose offset lies within this many cells of this offset are skipped.
    excluded: Option<(i64, i64, i64)>,
}

impl<'a> Problem<'a> {
    /// `None` when no return is left to match.
    pub(super) fn new(
        grids: &'a PrecomputedGrids,
        points: &[[f64; 2]],
        initial: Pose2,
        window: &SearchWindow,
        min_score: f64,
    ) -> Option<Problem<'a>> {
        if points.is_empty() {
            return None;
        }
        let r = grids.grid().resolution_m();
        let max_range = points.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
        let angles = angles(initial.theta, window, r, max_range);
        let cells: Vec<Cells> = angles
            .iter()
            .map(|&theta| {
                let pose = Pose2::new(initial.x, initial.y, theta);
                Cells::new(
                    points
                        .iter()
                        .map(|&p| grids.grid().cell_of(pose.transform_point(p)))
                        .collect(),
                )
            })
            .collect();
        let full = FULL as f64 * points.len() as f64;
        // An offset that puts no return in the grid scores 0, whatever the window: the search
        // need not reach beyond the farthest offset that puts one in. Without this bound a
        // window far larger than the grid (a localize request's prior, σ = 10⁵ m: 10¹⁰ roots
        // per angle) enumerated its roots without end, holding each in memory, and beyond
        // 10¹⁸ m its offsets overflowed (the `localize` fuzz target).
        let (width, height) = grids.grid().size();
        let (width, height) = (width as i64, height as i64);
        let useful = cells
            .iter()
            .flat_map(Cells::iter)
            .map(|&(i, j)| {
                let far = |c: i64, n: i64| {
                    c.saturating_abs()
                        .max((n - 1).saturating_sub(c).saturating_abs())
                };
                far(i, width).max(far(j, height))
            })
            .max()
            .unwrap_or(0);
        Some(Problem {
            grids,
            angles,
            cells,
            initial,
            reach: ((window.linear_m / r).ceil().max(0.0) as i64).min(useful),
            min_sum: (min_score.max(0.0) * full).ceil().min(u32::MAX as f64) as u32,
            nodes: 0,
            excluded: None,
        })
    }

    /// Leaves out every pose within `radius_m` of translation of `pose` (a pose of this
    /// window), whatever its angle: the search then finds the best pose elsewhere.
    pub(super) fn excluding(mut self, pose: &Pose2, radius_m: f64) -> Problem<'a> {
        let r = self.grids.grid().resolution_m();
        self.excluded = Some((
            ((pose.x - self.initial.x) / r).round() as i64,
            ((pose.y - self.initial.y) / r).round() as i64,
            (radius_m / r).ceil() as i64,
        ));
        self
    }

    fn is_excluded(&self, c: &Candidate) -> bool {
        self.excluded
            .is_some_and(|(x, y, radius)| (c.dx - x).pow(2) + (c.dy - y).pow(2) <= radius * radius)
    }

    fn score(&mut self, level: u32, angle: usize, dx: i64, dy: i64) -> Candidate {
        self.nodes += 1;
        let sum = self.grids.sum(level, &self.cells[angle], dx, dy);
        Candidate { angle, dx, dy, sum }
    }

    fn result(&self, best: Option<Candidate>) -> Option<CorrelativeMatch> {
        let c = best?;
        let r = self.grids.grid().resolution_m();
        let points = self.cells[c.angle].len() as f64;
        Some(CorrelativeMatch {
            pose: Pose2::new(
                self.initial.x + c.dx as f64 * r,
                self.initial.y + c.dy as f64 * r,
                crate::wrap_angle(self.angles[c.angle]),
            ),
            score: f64::from(c.sum) / (FULL as f64 * points),
            nodes: self.nodes,
        })
    }

    /// Branch and bound from the level that fits the window.
    pub(super) fn branch_and_bound(mut self) -> Option<CorrelativeMatch> {
        // The level whose squares first reach half the window: 2 × 2 roots per angle.
        let half_window = (self.reach.max(1) as u64)
            .next_power_of_two()
            .trailing_zeros();
        let depth = self.grids.depth().min(half_window);
        let step = 1usize << depth;
        let mut roots = Vec::new();
        for angle in 0..self.angles.len() {
            for dx in (-self.reach..=self.reach).step_by(step) {
                for dy in (-self.reach..=self.reach).step_by(step) {
                    roots.push(self.score(depth, angle, dx, dy));
                }
            }
        }
        let best = self.branch(roots, depth, None);
        self.result(best)
    }

    fn branch(
        &mut self,
        mut candidates: Vec<Candidate>,
        level: u32,
        mut best: Option<Candidate>,
    ) -> Option<Candidate> {
        candidates.sort_by_key(|c| std::cmp::Reverse(c.sum));
        for c in candidates {
            let needed = best.map_or(self.min_sum, |b| b.sum.saturating_add(1));
            if c.sum < needed {
                break; // sorted: no later candidate can do better
            }
            if level == 0 {
                if self.is_excluded(&c) {
                    continue;
                }
                best = Some(c);
                break;
            }
            let half = 1i64 << (level - 1);
            let mut children = Vec::with_capacity(4);
            for (a, b) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (dx, dy) = (c.dx + a * half, c.dy + b * half);
                if dx <= self.reach && dy <= self.reach {
                    children.push(self.score(level - 1, c.angle, dx, dy));
                }
            }
            best = self.branch(children, level - 1, best);
        }
        best
    }

    /// Every pose of the window scored on level 0: the reference the search must equal.
    pub(super) fn exhaustive(mut self) -> Option<CorrelativeMatch> {
        let mut best: Option<Candidate> = None;
        for angle in 0..self.angles.len() {
            for dx in -self.reach..=self.reach {
                for dy in -self.reach..=self.reach {
                    let c = self.score(0, angle, dx, dy);
                    if !self.is_excluded(&c)
                        && c.sum >= best.map_or(self.min_sum, |b| b.sum.saturating_add(1))
                    {
                        best = Some(c);
                    }
                }
            }
        }
        self.result(best)
    }
}
