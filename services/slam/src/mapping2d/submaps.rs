//! Submaps: each robot's consecutive nodes over `submap_path_m` of path, rasterized in the
//! frame of their first node (the anchor) once the robot has moved on, and pooled for the
//! correlative search.

use super::Mapper2d;
use crate::Pose2;
use crate::matching::correlative::{PrecomputedGrids, ProbabilityGrid, SearchWindow, precompute};
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};

/// Pooled grids kept at once: a submap's grid is made when it is first searched and kept
/// while it is among the most recently searched. Made for every submap and kept for good,
/// they took most of the mapper's time on a fleet and grew its memory with the time driven.
const POOLED_GRIDS_KEPT: usize = 32;

/// A finished submap.
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct Submap {
    pub robot: usize,
    /// The first node: the grid is in its frame.
    pub anchor: usize,
    /// Each node and its pose in the anchor's frame when the submap was finished.
    pub nodes: Vec<(usize, Pose2)>,
    /// Place in the robot's chain, and path (m), of the last node.
    pub last_place: usize,
    pub last_path_m: f64,
    /// The grid's extent in the anchor's frame (m).
    bounds: ([f64; 2], [f64; 2]),
}

impl Submap {
    /// Distance (m) from a point of the anchor's frame to the grid's extent (0 inside).
    pub fn distance_to(&self, p: [f64; 2]) -> f64 {
        let (lo, hi) = self.bounds;
        let dx = (lo[0] - p[0]).max(p[0] - hi[0]).max(0.0);
        let dy = (lo[1] - p[1]).max(p[1] - hi[1]).max(0.0);
        dx.hypot(dy)
    }

    /// The grid's centre in the anchor's frame, and half its larger side (m).
    pub fn centre_and_reach(&self) -> ([f64; 2], f64) {
        let (lo, hi) = self.bounds;
        let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        (centre, (hi[0] - lo[0]).max(hi[1] - lo[1]) / 2.0)
    }

    /// The search over the whole grid and `margin_m` beyond, at every heading: its initial
    /// pose (the centre) and window.
    pub fn whole_window(&self, margin_m: f64) -> (Pose2, SearchWindow) {
        let (centre, reach) = self.centre_and_reach();
        let window = SearchWindow {
            linear_m: reach + margin_m,
            angular_rad: std::f64::consts::PI,
        };
        (Pose2::new(centre[0], centre[1], 0.0), window)
    }
}

/// Which of a submap's two pooled grids.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Resolution {
    /// The local search's (`SubmapSearchParams::grid`).
    Fine,
    /// The global search's (`GlobalSearchParams::grid`).
    Coarse,
}

/// The pooled grids made last, by submap and resolution, with when each was last used.
#[derive(Debug, Default)]
struct PooledGrids {
    kept: Vec<((usize, Resolution), Arc<PrecomputedGrids>, u64)>,
    clock: u64,
}

/// Which finished submap holds each node, for the submaps finished so far (`indexed`).
#[derive(Debug, Default)]
struct NodeIndex {
    /// By node: the submap's index, `u32::MAX` for none (yet).
    submap_of: Vec<u32>,
    indexed: usize,
}

/// Every robot's submaps, and how long each robot has gone without a closure.
#[derive(Debug, Default, Serialize, Deserialize)]
pub(super) struct Submaps {
    pub done: Vec<Submap>,
    /// A cache, made again from the scans on use: not saved.
    #[serde(skip)]
    pooled: Mutex<PooledGrids>,
    /// An index, extended on use: not saved.
    #[serde(skip)]
    by_node: Mutex<NodeIndex>,
    /// By robot.
    pub robots: Vec<RobotSubmaps>,
}

/// One robot's growing submap, and its path (m) at its last closure and last search.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct RobotSubmaps {
    open: Vec<usize>,
    pub last_closure_m: Option<f64>,
    pub last_search_m: f64,
}

impl Mapper2d {
    /// Puts `node` in its robot's growing submap; finishes the submap first when it spans
    /// `submap_path_m`.
    pub(super) fn track_submaps(&mut self, node: usize) {
        let robot = self.node_robot[node].0;
        let robots = &mut self.submaps.robots;
        if robots.len() <= robot {
            robots.resize(robot + 1, RobotSubmaps::default());
        }
        let span = self.params.submaps.submap_path_m;
        let path = self.node_path_m[node];
        let state = &mut robots[robot];
        if let Some(&first) = state.open.first()
            && path - self.node_path_m[first] >= span
        {
            let nodes = std::mem::take(&mut state.open);
            self.finish_submap(robot, &nodes);
        }
        let state = &mut self.submaps.robots[robot];
        state.open.push(node);
        state.last_closure_m.get_or_insert(path);
    }

    fn finish_submap(&mut self, robot: usize, nodes: &[usize]) {
        let (Some(&anchor), Some(&last)) = (nodes.first(), nodes.last()) else {
            return;
        };
        let origin = self.graph.poses[anchor];
        let placed: Vec<(usize, Pose2)> = nodes
            .iter()
            .map(|&n| (n, origin.between(&self.graph.poses[n])))
            .collect();
        let scans = placed
            .iter()
            .map(|&(n, pose)| (pose, self.node_scans[n].points()));
        // The extent alone: the grid is made when the submap is first searched.
        let Some(bounds) = ProbabilityGrid::bounds_of(scans, &self.params.submaps.grid) else {
            return;
        };
        self.submaps.done.push(Submap {
            robot,
            anchor,
            nodes: placed,
            last_place: self.node_robot[last].1,
            last_path_m: self.node_path_m[last],
            bounds,
        });
    }

    /// The finished submap that holds `node`, if one does (a look-up: scanning every
    /// submap's nodes took time that grew with the site).
    pub(super) fn submap_of(&self, node: usize) -> Option<usize> {
        let mut index = self.submaps.by_node.lock().expect("submap index lock");
        let NodeIndex { submap_of, indexed } = &mut *index;
        for (k, submap) in self.submaps.done.iter().enumerate().skip(*indexed) {
            for &(n, _) in &submap.nodes {
                if submap_of.len() <= n {
                    submap_of.resize(n + 1, u32::MAX);
                }
                submap_of[n] = u32::try_from(k).expect("fewer than 2³² submaps");
            }
        }
        *indexed = self.submaps.done.len();
        let k = *submap_of.get(node)?;
        (k != u32::MAX).then_some(k as usize)
    }

    /// Submap `k`'s grid pooled for the correlative search: made on first use, kept while it
    /// is among the [`POOLED_GRIDS_KEPT`] used last.
    pub(super) fn pooled_grids(&self, k: usize) -> Arc<PrecomputedGrids> {
        self.pooled(k, Resolution::Fine)
    }

    /// Submap `k`'s grid at the global search's coarse resolution, pooled and kept likewise.
    pub(super) fn pooled_coarse_grids(&self, k: usize) -> Arc<PrecomputedGrids> {
        self.pooled(k, Resolution::Coarse)
    }

    fn pooled(&self, k: usize, resolution: Resolution) -> Arc<PrecomputedGrids> {
        let mut pooled = self.submaps.pooled.lock().expect("pooled grids lock");
        pooled.clock += 1;
        let now = pooled.clock;
        let key = (k, resolution);
        if let Some(entry) = pooled.kept.iter_mut().find(|e| e.0 == key) {
            entry.2 = now;
            return entry.1.clone();
        }
        let submap = &self.submaps.done[k];
        let scans = submap
            .nodes
            .iter()
            .map(|&(n, pose)| (pose, &self.node_scans[n]));
        let params = match resolution {
            Resolution::Fine => &self.params.submaps.grid,
            Resolution::Coarse => &self.params.global_search.grid,
        };
        // A coarser grid of the same returns is never larger than the fine one.
        let grids =
            Arc::new(precompute(scans, params).expect("its extent was laid out when finished"));
        if pooled.kept.len() >= POOLED_GRIDS_KEPT
            && let Some(oldest) = (0..pooled.kept.len()).min_by_key(|&i| pooled.kept[i].2)
        {
            pooled.kept.swap_remove(oldest);
        }
        pooled.kept.push((key, grids.clone(), now));
        grids
    }

    /// Submap `k`'s returns gathered in the frame of its middle node, within the search's
    /// range of that node (`nodes[nodes.len() / 2]`): one query with the submap's structure.
    /// A single scan fits many places along a corridor, a submap with its doors and corners
    /// fits one.
    pub(super) fn submap_returns(&self, k: usize, max_range_m: f64) -> Vec<[f64; 2]> {
        let nodes = &self.submaps.done[k].nodes;
        let middle = nodes[nodes.len() / 2].1;
        let to_middle = middle.inverse();
        nodes
            .iter()
            .flat_map(|&(n, pose)| {
                let into_middle = to_middle.compose(&pose);
                self.node_scans[n]
                    .points()
                    .iter()
                    .map(move |&p| into_middle.transform_point(p))
            })
            .filter(|p| p[0].hypot(p[1]) <= max_range_m)
            .collect()
    }
}
