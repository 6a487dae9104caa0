//! Global loop search: every finished submap is searched for in the robot's other finished
//! submaps (and those of robots it already shares a frame with), whole and at every heading,
//! whatever the estimate says, so a loop closes at any drift. The local searches
//! ([`super::edges`], [`super::submap_search`]) look only near the estimate; after a long loop the
//! place is tens of metres from where the estimate puts it (fr-clinic: 64 m).
//!
//! Cartographer's constraint builder does the same with a scan against every submap at a
//! sampling ratio. Here the query is the whole submap's returns gathered in its middle
//! node's frame: a single scan in a corridor fits many places along it, a submap with its
//! doors and corners fits one. The work is bounded per metre travelled (`searches_per_m`): the
//! newest submap searches first, its targets the most plausible first (nearest for the
//! drift of the path between them), so a loop is tried soon after it is driven.
//!
//! Each hypothesis is checked before it is trusted: coarse to fine (a whole-map search on
//! `grid`'s coarse cells, then the local one's fine grid around it), unambiguous (no pose
//! elsewhere scores nearly as well), its returns must not land where the target saw free
//! space (`max_free_share`), IDC must confirm it against the target's nearest node through
//! the quality gate, and it then waits in the consistency check like every closure, whose
//! neighbours' matches ([`super::support`]) must agree with it.

use super::Mapper2d;
use crate::grid::{CellState, GridParams, OccupancyGrid};
use crate::matching::correlative::{
    CorrelativeMatch, CorrelativeParams, SearchWindow, search, thin_points, unambiguous_search,
};
use crate::network::EdgeKind;
use crate::se2::Pose2;
use serde::{Deserialize, Serialize};

/// The global loop search's parameters, each default with its reason.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GlobalSearchParams {
    /// Search at all.
    pub enabled: bool,
    /// Pairs of submaps searched per metre the robot travels, on average (Cartographer's
    /// sampling ratio, as a budget per path rather than per node, so that the node spacing
    /// does not change it). A search took 15.5 ms (median) on fr-clinic at 0.3 m cells,
    /// less at 0.5 m; the rest of a node's work there takes about 9 ms. A submap spans
    /// 10 m, so each new submap tries its 20 most plausible targets before the next one is
    /// finished. Half as many left fr-clinic's last loop open.
    pub searches_per_m: f64,
    /// The coarse grid of the whole-map search. 0.5 m cells: the walls of a 2 m corridor
    /// still stand four cells apart. 0.3 m cells found the same closures on every 2D log and
    /// took longer (fr-clinic 50.3 against 40.3 s, mit-csail 16.8 against 10.9 s). Returns
    /// beyond 20 m are sparse and are not rasterized.
    pub grid: CorrelativeParams,
    /// The query's returns are thinned to one per square of this side (m), two coarse
    /// cells: the search's cost grows with them, and a submap's walls, doors and corners
    /// still show.
    pub query_spacing_m: f64,
    /// The query keeps the returns within this range of its middle node (m): the angular
    /// step that moves the farthest return by one cell, and so the search's cost, shrinks
    /// with it; a 10 m submap's returns within 10 m still hold its surroundings (12 m took
    /// 36.5–40.3 s on fr-clinic against 32.0 s, with 85 closures against 102).
    pub query_range_m: f64,
    /// Translations within the target's extent plus this margin (m): the query's middle
    /// node may stand outside what the target saw.
    pub margin_m: f64,
    /// The coarse best pose must score at least this (mean cell value under the returns):
    /// about half the returns on the target's surfaces. Two submaps of a place seen on
    /// different paths share less than two scans of one path. The matches that passed the
    /// later checks on fr-clinic scored 0.76 to 0.88 (at 0.3 m cells); the bar also prunes
    /// the search (fr-clinic with 0.5: 36.5–40.3 s, with 0.55: 37.0 s, one run each).
    pub coarse_min_score: f64,
    /// The fine pose (the local search's grid, around the coarse one) must score at least
    /// this: the local search's own bar.
    pub min_score: f64,
    /// Ambiguity on the coarse grid: the best pose farther than `ambiguity_radius_m` must
    /// score below this share of the best. A submap of a straight corridor fits shifted
    /// poses nearly as well, and its best is as likely wrong as right.
    pub max_runner_up_ratio: f64,
    /// See `max_runner_up_ratio` (m): beyond the coarse search's error.
    pub ambiguity_radius_m: f64,
    /// Of the returns at the fine pose, at most this share may land in cells the target saw
    /// free. Where two places look alike from afar, the wrong one has returns inside the
    /// other's free space; at the right pose only moved things and a cell's error put any
    /// there.
    pub max_free_share: f64,
    /// Targets are taken in order of their distance from the estimate over the drift the
    /// path between them allows (`loop_search_radius_m` + this share of that path); those
    /// beyond it are not searched. 0.2: the local candidates' growth; more drift than
    /// one metre in five means the odometry is broken, not drifting.
    pub drift_share: f64,
    /// Submaps that still search, the newest first; an older one's remaining targets are
    /// dropped (a newer submap of the same path takes over).
    pub queries_kept: usize,
}

impl Default for GlobalSearchParams {
    fn default() -> Self {
        GlobalSearchParams {
            enabled: true,
            searches_per_m: 2.0,
            grid: CorrelativeParams {
                resolution_m: 0.5,
                hit_sigma_m: 0.5,
                max_range_m: 20.0,
                ..CorrelativeParams::default()
            },
            query_spacing_m: 1.0,
            query_range_m: 10.0,
            margin_m: 2.0,
            coarse_min_score: 0.55,
            min_score: 0.6,
            max_runner_up_ratio: 0.9,
            ambiguity_radius_m: 1.5,
            max_free_share: 0.1,
            drift_share: 0.2,
            queries_kept: 4,
        }
    }
}

/// The fine search's rotations around the coarse pose: a coarse angular step each way (at
/// 0.5 m cells and returns within 10 m, the step that moves the farthest return by a cell
/// is 2.9°). Its translations are two coarse cells each way.
const FINE_WINDOW_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// The submaps that still search, and the targets each has searched.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct GlobalSearch {
    /// Finished submaps seen so far.
    seen: usize,
    /// Searches earned and not yet spent (`searches_per_m` per metre travelled).
    credit: f64,
    queries: Vec<Query>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Query {
    submap: usize,
    searched: Vec<usize>,
}

impl Mapper2d {
    /// Spends the global searches that `node`'s step earned; returns how many edges the
    /// consistency check let through.
    pub(super) fn search_globally(&mut self, node: usize) -> usize {
        let p = self.params.global_search.clone();
        if !p.enabled || !self.params.submaps.enabled {
            return 0;
        }
        let done = self.submaps.done.len();
        let state = &mut self.global;
        state.queries.extend((state.seen..done).map(|submap| Query {
            submap,
            searched: Vec::new(),
        }));
        state.seen = done;
        let excess = state.queries.len().saturating_sub(p.queries_kept);
        state.queries.drain(..excess);
        self.sync_parts();
        let mut added = 0;
        let step_m = self
            .chain_neighbour(node, -1)
            .map_or(0.0, |last| self.node_path_m[node] - self.node_path_m[last]);
        // Credit left unspent while there is nothing to search is not saved up beyond a
        // metre's worth.
        let earned = p.searches_per_m * step_m.max(0.0);
        self.global.credit = (self.global.credit + earned).min(earned.max(p.searches_per_m) + 1.0);
        while self.global.credit >= 1.0 {
            let Some((query, target)) = self.next_pair(&p) else {
                break;
            };
            self.global.credit -= 1.0;
            self.stats.global_searches += 1;
            if let Some((near, node, m)) = self.match_submaps(query, target, &p) {
                self.stats.global_matches += 1;
                let information = self.match_information(&m.covariance);
                added += self.submit_and_verify(near, node, m.pose, information);
            }
        }
        added
    }

    /// The newest query's most plausible target not yet searched (marked searched). A query
    /// already anchored, or with no target left, is dropped.
    fn next_pair(&mut self, p: &GlobalSearchParams) -> Option<(usize, usize)> {
        while let Some(q) = self.global.queries.last().map(|query| query.submap) {
            let held = self.anchored(q);
            let query = self.global.queries.last().expect("looked at");
            let best = (!held)
                .then(|| {
                    (0..q)
                        .filter(|t| !query.searched.contains(t))
                        .filter_map(|t| self.plausibility(q, t, p).map(|r| (r, t)))
                        .min_by(|a, b| a.0.total_cmp(&b.0))
                })
                .flatten();
            let query = self.global.queries.last_mut().expect("looked at");
            match best {
                Some((_, t)) => {
                    query.searched.push(t);
                    return Some((q, t));
                }
                None => {
                    self.global.queries.pop();
                }
            }
        }
        None
    }

    /// Whether submap `q`'s place on the map is already held: a GPS fix on one of its nodes
    /// (the fix bounds the drift, and the local searches reach that far), or a closure from
    /// one of them to a node at least `closure_min_path_m` of path away or another robot's
    /// (the map holds there, and the local searches keep it so). A global search would
    /// only find what is known.
    fn anchored(&mut self, q: usize) -> bool {
        self.background.adjacency.sync(&self.graph);
        let adjacency = &self.background.adjacency;
        let min_path = self.params.submaps.closure_min_path_m;
        let path = &self.node_path_m;
        let far = |a: usize, b: usize| {
            self.node_robot[a].0 != self.node_robot[b].0 || (path[a] - path[b]).abs() >= min_path
        };
        self.submaps.done[q].nodes.iter().any(|&(n, _)| {
            adjacency.fixes_of(n).next().is_some()
                || adjacency.edges_of(n).any(|k| {
                    let e = &self.graph.edges[k];
                    let other = if e.from == n { e.to } else { e.from };
                    matches!(e.kind, EdgeKind::LoopClosure | EdgeKind::InterRobot) && far(n, other)
                })
        })
    }

    /// How far target submap `t` lies from query `q`'s middle node, over the drift allowed
    /// between them (≤ 1); `None` when it is not a target: another part, or the query's own
    /// neighbours on its chain.
    fn plausibility(&self, q: usize, t: usize, p: &GlobalSearchParams) -> Option<f64> {
        let (query, target) = (&self.submaps.done[q], &self.submaps.done[t]);
        if !self.parts.same_part(query.anchor, target.anchor) {
            return None;
        }
        let first = self.node_robot[query.anchor].1;
        let query_path = self.node_path_m[query.anchor];
        let apart_m = if query.robot == target.robot {
            if target.last_place + self.params.loop_min_node_gap > first {
                return None;
            }
            query_path - target.last_path_m
        } else {
            query_path + target.last_path_m
        };
        let middle = query.nodes[query.nodes.len() / 2].0;
        let at = self.graph.poses[target.anchor].between(&self.graph.poses[middle]);
        let allowed = self.params.loop_search_radius_m + p.drift_share * apart_m.max(0.0);
        let ratio = target.distance_to([at.x, at.y]) / allowed;
        (ratio <= 1.0).then_some(ratio)
    }

    /// Query submap `q`'s returns searched in the whole of target `t`, coarse to fine and
    /// checked: the closure's target node, query node and IDC match, if it holds.
    fn match_submaps(
        &self,
        q: usize,
        t: usize,
        p: &GlobalSearchParams,
    ) -> Option<(usize, usize, crate::matching::Match)> {
        let returns = self.submap_returns(q, p.query_range_m);
        let returns = thin_points(&returns, p.query_spacing_m, p.query_range_m);
        let coarse = self.coarse_unambiguous(t, &returns, p)?;
        let fine = {
            let window = SearchWindow {
                linear_m: 2.0 * p.grid.resolution_m,
                angular_rad: FINE_WINDOW_RAD,
            };
            let grids = self.pooled_grids(t);
            let grid = &self.params.submaps.grid;
            search(&grids, &returns, coarse.pose, &window, p.min_score, grid)?
        };
        if self.free_share(t, &fine.pose, &returns) > p.max_free_share {
            return None;
        }
        let query = &self.submaps.done[q];
        let node = query.nodes[query.nodes.len() / 2].0;
        let (near, m) = self.refine_in_submap(t, node, &fine.pose, true)?;
        Some((near, node, m))
    }

    /// The best pose of `returns` in the whole of target `t` on the coarse grid, every
    /// heading, unless a pose elsewhere scores nearly as well.
    fn coarse_unambiguous(
        &self,
        t: usize,
        returns: &[[f64; 2]],
        p: &GlobalSearchParams,
    ) -> Option<CorrelativeMatch> {
        let grids = self.pooled_coarse_grids(t);
        let (initial, window) = self.submaps.done[t].whole_window(p.margin_m);
        let (ratio, radius) = (p.max_runner_up_ratio, p.ambiguity_radius_m);
        let min_score = p.coarse_min_score;
        unambiguous_search(
            &grids, returns, initial, &window, min_score, ratio, radius, &p.grid,
        )
    }

    /// The share of `returns` (at `pose` in target `t`'s frame) that land in cells the
    /// target's scans saw free.
    fn free_share(&self, t: usize, pose: &Pose2, returns: &[[f64; 2]]) -> f64 {
        let target = &self.submaps.done[t];
        let scans = target
            .nodes
            .iter()
            .map(|&(n, at)| (at, &self.node_scans[n]));
        let params = GridParams {
            resolution_m: self.params.global_search.grid.resolution_m,
            max_range_m: self.params.global_search.grid.max_range_m,
            ..GridParams::default()
        };
        let Ok(grid) = OccupancyGrid::from_scans(scans, &params) else {
            return 1.0;
        };
        let free = returns
            .iter()
            .filter_map(|&r| grid.cell_at(pose.transform_point(r)))
            .filter(|&(i, j)| grid.state(i, j) == CellState::Free)
            .count();
        free as f64 / returns.len().max(1) as f64
    }
}
