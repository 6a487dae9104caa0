//! Correlative scan matching against a submap by branch and bound (Hess, Kohler, Rapp,
//! Andor, "Real-Time Loop Closure in 2D LIDAR SLAM", ICRA 2016, section V): the submap's
//! scans are rasterized into a probability grid, the grid is max-pooled once per level of
//! the search, and a depth-first branch and bound over (x, y, θ) returns the **exact** best
//! score of the discretized window (translations in whole cells, rotations in steps that
//! move the farthest return by one cell), not a sample of it. It needs no good initial
//! guess: the window can be the whole submap and every heading.
//!
//! Reading order: [`ProbabilityGrid`] and [`PrecomputedGrids`] (`grid`), then [`search`]
//! (`search`: the discretized scans and the branch and bound).

mod grid;
mod search;
#[cfg(test)]
mod tests;

pub use grid::{PrecomputedGrids, ProbabilityGrid};
pub use search::thin_points;

use super::Scan2;
use crate::Pose2;
use serde::{Deserialize, Serialize};

/// How submaps are rasterized and scans thinned for the search.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CorrelativeParams {
    /// Cell size (m). The translation is found to within a cell, the rotation to within the
    /// step that moves the farthest return by a cell.
    pub resolution_m: f64,
    /// Each return marks the cells around it with a Gaussian of this σ (m): a point a little
    /// off the surface still scores.
    pub hit_sigma_m: f64,
    /// Returns farther than this (m) are neither rasterized nor matched: they are sparse,
    /// noisy, and make the angular step small.
    pub max_range_m: f64,
    /// Levels of the pooled stack: the coarsest covers 2^depth cells a side. A search starts
    /// from the level whose squares are the first to reach half its window (a wider start
    /// bounds too loosely, a narrower one scores more roots), this one at most.
    pub max_depth: u32,
    /// A submap grid larger than this many cells is not built.
    pub max_cells: usize,
}

impl Default for CorrelativeParams {
    fn default() -> Self {
        CorrelativeParams {
            resolution_m: 0.05,
            hit_sigma_m: 0.05,
            max_range_m: 30.0,
            max_depth: 9,
            max_cells: 1 << 24,
        }
    }
}

/// The poses searched around an initial one: translations within ±`linear_m` in x and in
/// y, rotations within ±`angular_rad` (π or more: every heading).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchWindow {
    /// Half the side of the square of translations (m).
    pub linear_m: f64,
    /// Half the range of rotations (rad).
    pub angular_rad: f64,
}

/// The best pose of a window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrelativeMatch {
    /// The scan's frame in the grid's frame (m, rad).
    pub pose: Pose2,
    /// The mean cell value under the scan's (thinned) returns at `pose`, 0 to 1.
    pub score: f64,
    /// Candidates scored by the search (every level counted): its cost.
    pub nodes: usize,
}

/// Rasterizes scans at their poses in the submap's frame and pools the grid for the search;
/// `None` when there is no return or the grid would be too large.
pub fn precompute<'a>(
    scans: impl IntoIterator<Item = (Pose2, &'a Scan2)>,
    params: &CorrelativeParams,
) -> Option<PrecomputedGrids> {
    let grid = ProbabilityGrid::from_scans(
        scans.into_iter().map(|(pose, scan)| (pose, scan.points())),
        params,
    )?;
    Some(PrecomputedGrids::new(grid, params.max_depth))
}

/// The best pose of `scan` (a [`Scan2`], or any points in one frame: several scans gathered)
/// in `grids`' frame within `window` around `initial`, by branch and bound; `None` when no
/// pose scores at least `min_score` (or no return is within range).
pub fn search(
    grids: &PrecomputedGrids,
    scan: &(impl AsRef<[[f64; 2]]> + ?Sized),
    initial: Pose2,
    window: &SearchWindow,
    min_score: f64,
    params: &CorrelativeParams,
) -> Option<CorrelativeMatch> {
    let r = grids.grid().resolution_m();
    let points = search::thin_points(scan.as_ref(), r, params.max_range_m);
    search::Problem::new(grids, &points, initial, window, min_score)?.branch_and_bound()
}

/// Poses left out of a search: those within `radius_m` of translation of `pose`, whatever
/// their angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exclusion {
    /// The centre (m; its angle is ignored).
    pub pose: Pose2,
    /// The radius (m).
    pub radius_m: f64,
}

/// The best pose of the same search outside `excluded` (around the result of [`search`]):
/// a runner-up that scores nearly as well means the match is
/// ambiguous (a corridor, repeated doors), whatever its score. `None` when nothing there
/// scores at least `min_score`.
pub fn runner_up(
    grids: &PrecomputedGrids,
    scan: &(impl AsRef<[[f64; 2]]> + ?Sized),
    initial: Pose2,
    window: &SearchWindow,
    excluded: &Exclusion,
    min_score: f64,
    params: &CorrelativeParams,
) -> Option<CorrelativeMatch> {
    let r = grids.grid().resolution_m();
    let points = search::thin_points(scan.as_ref(), r, params.max_range_m);
    search::Problem::new(grids, &points, initial, window, min_score)?
        .excluding(&excluded.pose, excluded.radius_m)
        .branch_and_bound()
}

/// The best pose of [`search`], unless a pose farther than `ambiguity_radius_m` from it
/// scores at least `max_runner_up_ratio` of its score ([`runner_up`]): a corridor or a row of
/// like doors fits shifted poses nearly as well, and such a best pose is as likely wrong as
/// right.
#[allow(clippy::too_many_arguments)]
pub fn unambiguous_search(
    grids: &PrecomputedGrids,
    scan: &(impl AsRef<[[f64; 2]]> + ?Sized),
    initial: Pose2,
    window: &SearchWindow,
    min_score: f64,
    max_runner_up_ratio: f64,
    ambiguity_radius_m: f64,
    params: &CorrelativeParams,
) -> Option<CorrelativeMatch> {
    let found = search(grids, scan, initial, window, min_score, params)?;
    let excluded = Exclusion {
        pose: found.pose,
        radius_m: ambiguity_radius_m,
    };
    let floor = found.score * max_runner_up_ratio;
    runner_up(grids, scan, initial, window, &excluded, floor, params)
        .is_none()
        .then_some(found)
}

/// The same as [`search`] by scoring every pose of the window: the reference for tests and
/// benches (it is far slower).
pub fn exhaustive_search(
    grids: &PrecomputedGrids,
    scan: &(impl AsRef<[[f64; 2]]> + ?Sized),
    initial: Pose2,
    window: &SearchWindow,
    min_score: f64,
    params: &CorrelativeParams,
) -> Option<CorrelativeMatch> {
    let r = grids.grid().resolution_m();
    let points = search::thin_points(scan.as_ref(), r, params.max_range_m);
    search::Problem::new(grids, &points, initial, window, min_score)?.exhaustive()
}
