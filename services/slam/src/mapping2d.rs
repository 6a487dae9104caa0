//! Scan-based 2D SLAM (paper section 4) on a stream of scans with odometry: nodes every few
//! decimetres or degrees, odometry and IDC edges between successive nodes, loop closures
//! verified by IDC and the quality gate, and the network re-optimized as closures arrive.
//! Scans between nodes hang off their node by an IDC offset, so every scan gets a pose.
//!
//! Several robots share one network: each has its own chain of nodes, its first node at its
//! odometry pose (robots start with odometry in the map frame, as from a known dock, or GPS
//! pulls them in), and loop-closure candidates include the other robots' nodes, so robots
//! that meet share one map. GPS fixes become GPS edges with a robust kernel. A part of the
//! network that neither GPS nor a link to another part anchors is optimized with its first
//! node held where it is (its own gauge, [`Optimizer::for_parts`]).
//!
//! Loop-closure candidates are earlier nodes whose current estimate lies within a search
//! radius of the new node's, excluding its recent predecessors; a candidate becomes an edge
//! only when IDC matches it, the gate accepts the match and the pairwise consistency check
//! ([`closures`], [`consistency`]) lets it through, and then with a soft robust
//! kernel (Cauchy, c = 10): a closure that slips through wrongly is down-weighted, while a
//! right one that arrives after much drift still pulls the map. (DCS was measured on ACES:
//! it discarded the right closures too, and the relation error tripled.)

mod closures;
pub mod consistency;
mod contact_check;
mod coverage;
mod edges;
mod first_contact;
mod global_search;
mod local;
mod near;
mod params;
mod parts;
mod saved;
mod solve;
mod submap_params;
mod submap_search;
mod submaps;
mod support;
mod wrong_closures;
mod wrong_matches;

pub use contact_check::ContactCheckParams;
pub use coverage::{CoverageParams, Passed};
pub use first_contact::FirstContactParams;
pub use global_search::GlobalSearchParams;
pub use params::{ConsistencyParams, Mapper2dParams};
pub use saved::{RestoreError, SavedMapper};
pub use solve::{BackgroundSolve, SolvedInBackground};
pub use submap_params::SubmapSearchParams;
pub use wrong_closures::WrongClosures;
pub use wrong_matches::WrongMatches;

use crate::matching::Scan2;
use crate::network::{EdgeKind, GraphError, PoseGraph, RelativeEdge};
use crate::optimize::{OptimizeReport, Optimizer};
use crate::robust::Robust;
use crate::se2::{Pose2, wrap_angle};
use serde::{Deserialize, Serialize};

/// Where a scan went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Placed {
    /// It started node `node`.
    Node(usize),
    /// It hangs off node `node` at `offset` (its frame in the node's frame).
    Attached {
        /// The node.
        node: usize,
        /// The scan's frame in the node's frame (m, rad).
        offset: Pose2,
    },
}

/// What the mapper did so far.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapperStats {
    /// Scans added.
    pub scans: usize,
    /// Nodes created (one scan each).
    pub nodes: usize,
    /// Scan matches between successive nodes the gate accepted.
    pub sequential_matches: usize,
    /// Scan matches between successive nodes rejected (odometry used instead).
    pub sequential_rejected: usize,
    /// Of the sequential matches (and of the scans attached to a node), those IDC got
    /// wrong or missed that the correlative search on the local map found.
    #[serde(default)]
    pub sequential_recovered: usize,
    /// Loop-closure candidates matched.
    pub loop_candidates: usize,
    /// Loop-closure matches the quality gate accepted (each then checked for consistency).
    pub loop_matches: usize,
    /// Closure candidates added from outside the matcher (`add_closure_candidate`).
    pub external_closures: usize,
    /// Matches of a waiting closure's neighbouring nodes, tried for its support (also
    /// checked before they become edges).
    pub support_matches: usize,
    /// Loop closures (edges), within a robot's chain and between robots.
    pub loop_closures: usize,
    /// Closure candidates (matches and external ones) the consistency check rejected.
    pub loop_closures_rejected: usize,
    /// Of `loop_closures`, those between two robots.
    pub inter_robot_closures: usize,
    /// Correlative searches of a node in a submap.
    pub submap_searches: usize,
    /// Of `loop_closures`, those found by a submap search.
    pub submap_closures: usize,
    /// Global searches: a finished submap's returns in another submap, whole, every heading.
    #[serde(default)]
    pub global_searches: usize,
    /// Of `global_searches`, the matches that passed every check and went to the
    /// consistency check as closures.
    #[serde(default)]
    pub global_matches: usize,
    /// Searches of a lone robot's node in another robot's submap (whole, every heading).
    pub contact_searches: usize,
    /// Of `inter_robot_closures`, the first contacts those searches found.
    pub first_contacts: usize,
    /// GPS edges added (fixes taken).
    pub gps_edges: usize,
    /// Of `gps_edges`, the fixes of passes over covered ground, carried to the node passed.
    #[serde(default)]
    pub pass_fixes: usize,
    /// Optimizations run.
    pub optimizations: usize,
    /// Optimizations put off because a part of the network was not anchored yet.
    pub deferred_optimizations: usize,
    /// Parts of the network (robots that had not met, without GPS) moved onto the map by
    /// their first closure with it.
    pub parts_joined: usize,
    /// Windows of a chain re-solved at once (with `defer_optimization`).
    pub window_solves: usize,
}

pub use crate::gnss::GpsObservation;

/// One robot's chain of nodes.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
struct Chain {
    last_node: usize,
    last_odometry: Pose2,
    /// Nodes in the chain so far.
    length: usize,
    /// Nodes passed since the last ([`coverage`]).
    passed: coverage::Passed,
}

/// The incremental 2D mapper. Its serde form ([`Self::saved`], [`SavedMapper`]) is all of its
/// state but the node scans, which its owner keeps anyway.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct Mapper2d {
    params: Mapper2dParams,
    graph: PoseGraph,
    #[serde(skip)]
    node_scans: Vec<Scan2>,
    /// The robot of each node, and the node's place in that robot's chain.
    node_robot: Vec<(usize, usize)>,
    /// Path length the node's robot travelled up to the node (m).
    node_path_m: Vec<f64>,

    /// Each robot's chain, by robot index.
    chains: Vec<Option<Chain>>,
    /// Loop-closure candidates and their consistency check.
    book: closures::ClosureBook,
    /// Only a cache (the last symbolic factorization): not saved.
    #[serde(skip, default = "Optimizer::for_parts")]
    optimizer: Optimizer,
    stats: MapperStats,
    last_optimization: Option<OptimizeReport>,
    optimization_pending: bool,
    submaps: submaps::Submaps,
    contact: first_contact::ContactSearch,
    #[serde(default)]
    global: global_search::GlobalSearch,
    /// The network's parts, kept up to date by [`Self::sync_parts`].
    parts: crate::parts::PartTracker,
    /// The solves of a deferred mapper: windows now, the whole network in the background.
    background: solve::Background,
    /// The nodes filed by their estimates.
    near: near::NodeGrid,
    /// GPS edges that passes brought, waiting for the next solve applied (not saved: the
    /// caller's store keeps them with that solve; [`coverage`]).
    #[serde(skip)]
    pass_fixes: Vec<crate::GpsEdge>,
    /// Fault drills ([`WrongMatches`]): the error to put on the next node's sequential
    /// match, and each match so made (its node, its measurement). Not saved.
    #[serde(skip)]
    next_match_error: Option<Pose2>,
    #[serde(skip)]
    wrong_matches_made: Vec<(usize, Pose2)>,
}

impl Mapper2d {
    /// A mapper with no scan yet. Parts of its network that nothing links yet (a robot
    /// that has met no other, without GPS) are optimized each in its own frame.
    pub fn new(params: Mapper2dParams) -> Mapper2d {
        Mapper2d {
            params,
            optimizer: Optimizer::for_parts(),
            ..Default::default()
        }
    }

    /// The pose network so far: node poses at their current estimates, and the edges.
    pub fn graph(&self) -> &PoseGraph {
        &self.graph
    }

    /// What the mapper did so far.
    pub fn stats(&self) -> MapperStats {
        self.stats
    }

    /// The report of the last optimization that ran.
    pub fn last_optimization(&self) -> Option<&OptimizeReport> {
        self.last_optimization.as_ref()
    }

    /// The current pose estimate of a scan the mapper placed.
    pub fn pose_of(&self, placed: Placed) -> Pose2 {
        match placed {
            Placed::Node(n) => self.graph.poses[n],
            Placed::Attached { node, offset } => self.graph.poses[node].compose(&offset),
        }
    }

    /// The scan of node `node`, in its own frame.
    pub fn node_scan(&self, node: usize) -> &Scan2 {
        &self.node_scans[node]
    }

    /// Every node's scan at the node's current pose estimate, by node index: the
    /// scan-based map, as [`crate::grid::OccupancyGrid::from_scans`] takes it.
    pub fn node_scans_at_poses(&self) -> impl Iterator<Item = (Pose2, &Scan2)> + '_ {
        self.graph.poses.iter().copied().zip(&self.node_scans)
    }

    /// The robot of node `node` and the node's place in its chain.
    pub fn node_robot(&self, node: usize) -> (usize, usize) {
        self.node_robot[node]
    }

    /// Adds a scan taken at `odometry` (any consistent odometry frame) by a single robot:
    /// [`Self::add_robot_scan`] for robot 0 without GPS.
    pub fn add_scan(&mut self, odometry: Pose2, scan: Scan2) -> Result<Placed, GraphError> {
        self.add_robot_scan(0, odometry, scan, &[])
    }

    /// Adds a scan of robot `robot` (a small index) taken at `odometry` (the robot's
    /// odometry frame), with the GPS fixes the robot has for it (none, one, or every fix
    /// since its last scan, each carried to this scan's frame: see
    /// [`GpsObservation::lever_arm_m`]): a new node when the robot moved far enough since its
    /// last node (or it has none yet), one GPS edge per fix; else attached to its last node,
    /// its fixes dropped.
    pub fn add_robot_scan(
        &mut self,
        robot: usize,
        odometry: Pose2,
        scan: Scan2,
        gps: &[GpsObservation],
    ) -> Result<Placed, GraphError> {
        self.stats.scans += 1;
        if self.chains.len() <= robot {
            self.chains.resize(robot + 1, None);
        }
        let Some(chain) = self.chains[robot] else {
            // A robot's first node may already see another robot's map.
            let node = self.push_node(robot, odometry, odometry, 0.0, scan);
            self.record_chain_step(robot, node, None);
            let closed = self.close_loops(node);
            let closed = closed
                + self.search_submaps(node, closed)
                + self.search_globally(node)
                + self.seek_first_contact(node)
                > 0;
            if self.add_gps(node, gps) || closed {
                self.optimize_when_anchored(node)?;
            }
            return Ok(Placed::Node(node));
        };
        let last = chain.last_node;
        let step = chain.last_odometry.between(&odometry);
        let moved = step.x.hypot(step.y) >= self.params.node_distance_m
            || wrap_angle(step.theta).abs() >= self.params.node_rotation_rad;
        // Match against the last node from the odometry guess.
        let matched = self
            .sequential_match(last, &scan, step, moved)
            .filter(|m| self.agrees_with_odometry(m, &step));
        if !moved {
            let offset = matched.map_or(step, |m| m.pose);
            return Ok(Placed::Attached { node: last, offset });
        }
        // Unmatched after passes: from the last pass's map pose (located against the map),
        // not through the odometry of every pass since the last node.
        let after_passes = chain
            .passed
            .pose
            .zip(chain.passed.odometry)
            .map(|(pose, at)| pose.compose(&at.between(&odometry)));
        let estimate = match (&matched, after_passes) {
            (None, Some(estimate)) => estimate,
            _ => self.graph.poses[last].compose(&matched.as_ref().map_or(step, |m| m.pose)),
        };
        // Through the nodes passed since the last, if any.
        let from = chain.passed.odometry.unwrap_or(chain.last_odometry);
        let to_here = from.between(&odometry);
        let path = self.node_path_m[last] + chain.passed.path_m + to_here.x.hypot(to_here.y);
        let node = self.push_node(robot, estimate, odometry, path, scan);
        // The scan match when the gate accepts it, else odometry. Where both exist the match
        // alone is kept unless `fuse_odometry`: with wheel odometry the match is far more
        // precise and odometry would only pull it off (its errors are not independent white
        // noise); with a good gyro the two are comparable and both count.
        if let Some(m) = &matched {
            self.stats.sequential_matches += 1;
            self.graph.edges.push(RelativeEdge {
                from: last,
                to: node,
                measurement: m.pose,
                information: self.match_information(&m.covariance),
                kind: EdgeKind::ScanMatch,
                robust: Robust::None,
            });
        } else {
            self.stats.sequential_rejected += 1;
        }
        if matched.is_none() || self.params.fuse_odometry {
            self.graph.edges.push(RelativeEdge {
                from: last,
                to: node,
                measurement: step,
                information: self.odometry_information(&step),
                kind: EdgeKind::Odometry,
                robust: Robust::None,
            });
        }
        self.record_chain_step(robot, node, Some(last));
        let expired = self.expire_closures(false);
        let closed = self.close_loops(node);
        let closed = expired
            + closed
            + self.search_submaps(node, closed)
            + self.search_globally(node)
            + self.seek_first_contact(node)
            > 0;
        if self.add_gps(node, gps) || closed {
            self.optimize_when_anchored(node)?;
        }
        Ok(Placed::Node(node))
    }

    /// Optimizes the network one last time; call after the last scan.
    /// Closures still waiting for support are decided first.
    pub fn finish(&mut self) -> Result<OptimizeReport, GraphError> {
        self.expire_closures(true);
        self.optimize()
    }

    fn push_node(
        &mut self,
        robot: usize,
        estimate: Pose2,
        odometry: Pose2,
        path_m: f64,
        scan: Scan2,
    ) -> usize {
        let node = self.graph.poses.len();
        let length = self.chains[robot].map_or(0, |c| c.length + c.passed.nodes);
        self.chains[robot] = Some(Chain {
            last_node: node,
            last_odometry: odometry,
            length: length + 1,
            passed: coverage::Passed::default(),
        });
        self.node_robot.push((robot, length));
        self.node_path_m.push(path_m);
        self.graph.poses.push(estimate);
        self.near.refile(&self.graph.poses, &[]);
        self.node_scans.push(scan);
        self.stats.nodes += 1;
        node
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::synthetic::{Scene, uniform_bearings};
    use nalgebra::{Matrix2, Vector2};
    use std::f64::consts::PI;

    /// A 361-beam scan of the synthetic park from `pose` (1 cm noise): the mapper tests' scan.
    pub(super) fn scan_at(pose: &Pose2, seed: u64) -> Scan2 {
        let bearings = uniform_bearings(361, -PI / 2.0, PI / 360.0);
        let ranges = Scene::park().scan(pose, &bearings, 40.0, 0.01, seed);
        Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths")
    }

    fn fix_at(pose: &Pose2) -> GpsObservation {
        GpsObservation {
            position_m: Vector2::new(pose.x, pose.y),
            covariance_m2: Matrix2::identity() * 0.25,
            lever_arm_m: Vector2::zeros(),
        }
    }

    #[test]
    fn a_match_that_contradicts_good_odometry_is_rejected() {
        let params = Mapper2dParams {
            odometry_sigma_xy_m: 0.01,
            odometry_sigma_xy_per_m: 0.01,
            odometry_sigma_theta_rad: 0.002,
            match_odometry_max_chi2: 16.0,
            fuse_odometry: true,
            ..Mapper2dParams::default()
        };
        let truth = [Pose2::new(-2.0, 0.0, 0.0), Pose2::new(-1.4, 0.0, 0.0)];
        // Right odometry: the match agrees and is fused with it.
        let mut mapper = Mapper2d::new(params.clone());
        for (k, pose) in truth.iter().enumerate() {
            mapper
                .add_scan(*pose, scan_at(pose, k as u64))
                .expect("add");
        }
        let stats = mapper.stats();
        assert_eq!(
            (stats.sequential_matches, stats.sequential_rejected),
            (1, 0)
        );
        assert_eq!(mapper.graph().edges.len(), 2, "match and odometry");
        // Odometry 0.3 m off (σ 0.016 m): the match, right as it is, counts as wrong.
        let mut mapper = Mapper2d::new(params);
        let odometry = [truth[0], Pose2::new(-1.1, 0.0, 0.0)];
        for (k, (pose, odo)) in truth.iter().zip(&odometry).enumerate() {
            mapper.add_scan(*odo, scan_at(pose, k as u64)).expect("add");
        }
        let stats = mapper.stats();
        assert_eq!(
            (stats.sequential_matches, stats.sequential_rejected),
            (0, 1)
        );
    }

    #[test]
    fn gps_anchors_a_second_robot_and_bad_fixes_are_dropped() {
        let mut mapper = Mapper2d::new(Mapper2dParams::default());
        let poses = |y: f64| (0..4).map(move |k| Pose2::new(-2.0 + 0.6 * k as f64, y, 0.0));
        for (k, pose) in poses(0.0).enumerate() {
            mapper
                .add_robot_scan(0, pose, scan_at(&pose, k as u64), &[fix_at(&pose)])
                .expect("robot 0");
        }
        // Robot 1 starts 4 m apart (beyond the inter-robot search radius), linked to robot 0
        // by nothing but GPS. Its first fix alone cannot anchor it: until a second does, its
        // part is solved in its own frame (its first node fixed), and robot 0's map still is.
        let mut bad_nan = fix_at(&Pose2::IDENTITY);
        bad_nan.position_m.x = f64::NAN;
        let mut bad_covariance = fix_at(&Pose2::IDENTITY);
        bad_covariance.covariance_m2 = Matrix2::new(1.0, 2.0, 2.0, 1.0);
        let mut solved_at_start = None;
        for (k, pose) in poses(-4.0).enumerate() {
            let fixes = match k {
                1 => vec![bad_nan],
                2 => vec![bad_covariance, fix_at(&pose)],
                _ => vec![fix_at(&pose)],
            };
            mapper
                .add_robot_scan(1, pose, scan_at(&pose, 10 + k as u64), &fixes)
                .expect("robot 1");
            if k == 0 {
                let stats = mapper.stats();
                solved_at_start = Some((stats.optimizations, stats.deferred_optimizations));
                assert_eq!(
                    mapper.graph().poses[4],
                    pose,
                    "its own gauge, where it started"
                );
            }
        }
        let stats = mapper.stats();
        assert!(
            solved_at_start.is_some_and(|(solved, deferred)| solved > 0 && deferred == 0),
            "{stats:?}"
        );
        assert_eq!(stats.gps_edges, 4 + 3, "{stats:?}");
        assert_eq!(mapper.node_robot(4), (1, 0));
        mapper.finish().expect("anchored by then");
    }
}
