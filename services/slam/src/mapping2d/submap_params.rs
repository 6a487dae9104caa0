//! [`SubmapSearchParams`]: loop closure by correlative search against submaps.

use crate::matching::correlative::CorrelativeParams;
use serde::{Deserialize, Serialize};

/// Loop closure that needs no good guess: a robot's consecutive nodes are gathered into
/// submaps, rasterized; when the robot has gone a while without a closure, its new node is
/// searched in nearby submaps by branch and bound (`matching::correlative`), and the best
/// pose, if it scores well enough, is refined by IDC against the submap's nearest node and
/// gated like any closure.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SubmapSearchParams {
    /// Search submaps at all.
    pub enabled: bool,
    /// A submap gathers a robot's consecutive nodes over this much path (m).
    pub submap_path_m: f64,
    /// Rasterization and search (cell size, hit blur, range used).
    pub grid: CorrelativeParams,
    /// A closure counts as one (it resets the search's clock) when its two nodes are at least
    /// this much path apart (m): closures to nodes a few metres back, as IDC finds all along
    /// at small node spacings, say nothing about the drift of a loop.
    pub closure_min_path_m: f64,
    /// Search when the robot has travelled this far since its last closure (m)…
    pub search_after_m: f64,
    /// …then again after each further stretch of this much path (m).
    pub search_every_m: f64,
    /// Candidate submaps: within `loop_search_radius_m` + `loop_search_growth` × path of the
    /// new node (as IDC's candidates), the nearest first, at most this many per search.
    pub max_submaps: usize,
    /// The local window: translations within the search radius, at most this (m)…
    pub max_linear_window_m: f64,
    /// …and rotations within this (rad).
    pub angular_window_rad: f64,
    /// The best pose must score at least this (mean cell value under the returns, 0–1).
    pub min_score: f64,
    /// After this much path without a closure (m), the window widens: every heading, and
    /// translations up to `global_linear_window_m`.
    pub global_after_m: f64,
    /// See `global_after_m` (m).
    pub global_linear_window_m: f64,
    /// A wide search scores more wrong poses: it must score at least this.
    pub global_min_score: f64,
    /// Ambiguity: the best pose elsewhere (more than `ambiguity_radius_m` away) must score
    /// below this share of the best. A corridor or a row of like doors fits shifted poses
    /// nearly as well, and its best pose is as likely wrong as right.
    pub max_runner_up_ratio: f64,
    /// See `max_runner_up_ratio` (m).
    pub ambiguity_radius_m: f64,
    /// IDC from the correlative pose may move it by at most this (m)…
    pub refine_max_shift_m: f64,
    /// …and turn it by at most this (rad); farther, the two disagree and nothing is added.
    pub refine_max_turn_rad: f64,
}

impl Default for SubmapSearchParams {
    fn default() -> Self {
        SubmapSearchParams {
            enabled: true,
            submap_path_m: 10.0,
            grid: CorrelativeParams {
                resolution_m: 0.1,
                hit_sigma_m: 0.1,
                max_range_m: 20.0,
                ..CorrelativeParams::default()
            },
            closure_min_path_m: 20.0,
            search_after_m: 5.0,
            search_every_m: 1.0,
            max_submaps: 2,
            max_linear_window_m: 8.0,
            angular_window_rad: 30f64.to_radians(),
            min_score: 0.6,
            global_after_m: 40.0,
            global_linear_window_m: 15.0,
            global_min_score: 0.65,
            max_runner_up_ratio: 0.8,
            ambiguity_radius_m: 1.0,
            refine_max_shift_m: 0.5,
            refine_max_turn_rad: 5f64.to_radians(),
        }
    }
}
