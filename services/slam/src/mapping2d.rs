//! Scan-based 2D SLAM (paper section 4) on a stream of scans with odometry: nodes every few
//! decimetres or degrees, odometry and IDC edges between successive nodes, loop closures
//! verified by IDC and the quality gate, and the network re-optimized as closures arrive.
//! Scans between nodes hang off their node by an IDC offset, so every scan gets a pose.
//!
//! Several robots share one network: each has its own chain of nodes, its first node at its
//! odometry pose (robots start with odometry in the map frame, as from a known dock, or GPS
//! pulls them in), and loop-closure candidates include the other robots' nodes, so robots
//! that meet share one map. GPS fixes become GPS edges with a robust kernel; while a part of
//! the network has fixes at fewer than two nodes and no link to the first robot's chain, it
//! is not optimized yet (it keeps its dead-reckoned estimates).
//!
//! Loop-closure candidates are earlier nodes whose current estimate lies within a search
//! radius of the new node's, excluding its recent predecessors; a candidate becomes an edge
//! only when IDC matches it and the gate accepts the match, and then with a soft robust
//! kernel (Cauchy, c = 10): a closure that slips through wrongly is down-weighted, while a
//! right one that arrives after much drift still pulls the map. (DCS was measured on ACES:
//! it discarded the right closures too, and the relation error tripled.)

use crate::matching::{IdcParams, Match, QualityGate, Scan2, accept, idc};
use crate::network::{EdgeKind, GpsEdge, GraphError, PoseGraph, RelativeEdge, is_information};
use crate::optimize::{OptimizeParams, OptimizeReport, Optimizer};
use crate::robust::Robust;
use crate::se2::{Pose2, wrap_angle};
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// Tunables of the 2D mapper, each with its unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Mapper2dParams {
    /// A new node after this much travel (m)…
    pub node_distance_m: f64,
    /// …or this much rotation (rad).
    pub node_rotation_rad: f64,
    /// Odometry noise per step: σ_xy = a + b·distance (m), σ_θ = c + d·|rotation| (rad).
    pub odometry_sigma_xy_m: f64,
    pub odometry_sigma_xy_per_m: f64,
    pub odometry_sigma_theta_rad: f64,
    pub odometry_sigma_theta_per_rad: f64,
    /// Floor on the standard deviations taken from a scan match (m, rad): IDC's covariance
    /// is optimistic on clean data.
    pub match_min_sigma_xy_m: f64,
    pub match_min_sigma_theta_rad: f64,
    /// A match between nodes of one chain is rejected when it disagrees with odometry: the
    /// squared Mahalanobis distance between the two (odometry and match covariances
    /// summed) above this. Infinite: no check.
    pub match_odometry_max_chi2: f64,
    /// Keep the odometry edge beside an accepted match between successive nodes (odometry
    /// and scan matching fused), rather than the match alone.
    pub fuse_odometry: bool,
    /// Do not optimize while adding scans; the caller runs [`Mapper2d::optimize_pending`]
    /// (a server batching the nodes that arrived together into one solve).
    pub defer_optimization: bool,
    /// Loop-closure candidates: earlier nodes within this distance (m) of the new node, plus
    /// `loop_search_growth` times the path travelled between them (drift grows with it)…
    pub loop_search_radius_m: f64,
    pub loop_search_growth: f64,
    /// …and at least this many nodes back.
    pub loop_min_node_gap: usize,
    /// At most this many candidates are matched per new node (the nearest first).
    pub loop_max_candidates: usize,
    /// Robust kernel of loop closures (within and between robots).
    pub loop_robust: Robust,
    /// Candidates on another robot's chain: within this distance (m) of the new node.
    pub inter_robot_search_radius_m: f64,
    /// Robust kernel of GPS edges (multipath jumps).
    pub gps_robust: Robust,
    pub idc: IdcParams,
    pub gate: QualityGate,
    pub optimize: OptimizeParams,
}

impl Default for Mapper2dParams {
    fn default() -> Self {
        Mapper2dParams {
            node_distance_m: 0.5,
            node_rotation_rad: 20f64.to_radians(),
            odometry_sigma_xy_m: 0.02,
            odometry_sigma_xy_per_m: 0.1,
            odometry_sigma_theta_rad: 1f64.to_radians(),
            odometry_sigma_theta_per_rad: 0.1,
            match_min_sigma_xy_m: 0.01,
            match_min_sigma_theta_rad: 0.2f64.to_radians(),
            match_odometry_max_chi2: f64::INFINITY,
            fuse_odometry: false,
            defer_optimization: false,
            loop_search_radius_m: 3.0,
            loop_search_growth: 0.2,
            loop_min_node_gap: 20,
            loop_max_candidates: 4,
            loop_robust: Robust::Cauchy { c: 10.0 },
            inter_robot_search_radius_m: 3.0,
            gps_robust: Robust::Cauchy { c: 2.0 },
            idc: IdcParams::default(),
            gate: QualityGate::default(),
            optimize: OptimizeParams::default(),
        }
    }
}

impl Mapper2dParams {
    /// For robots with precise dead reckoning (a fibre-optic-class gyro, bias ~10°/h, and
    /// wheels with 0.5 % scale error, as the simulator's `DeadReckoning::default()`), which
    /// errs by 0.001–0.04 m and about 0.01° over 5 m, and sparse leveled scans of open
    /// ground (a few dozen returns): odometry is then no worse than a sparse match, so a
    /// match that contradicts it is rejected and an accepted one is fused with it. Measured
    /// in `services/sim/tests/fleet_mapping.rs` and used by `levelmap demo`.
    pub fn precise_dead_reckoning() -> Mapper2dParams {
        let defaults = Mapper2dParams::default();
        Mapper2dParams {
            odometry_sigma_xy_m: 0.01,
            odometry_sigma_xy_per_m: 0.01,
            odometry_sigma_theta_rad: 0.002,
            odometry_sigma_theta_per_rad: 0.01,
            match_odometry_max_chi2: 16.0,
            fuse_odometry: true,
            idc: crate::matching::IdcParams {
                min_correspondences: 10,
                ..defaults.idc.clone()
            },
            ..defaults
        }
    }
}

/// Where a scan went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Placed {
    /// It started node `node`.
    Node(usize),
    /// It hangs off node `node` at `offset` (its frame in the node's frame).
    Attached { node: usize, offset: Pose2 },
}

/// What the mapper did so far.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MapperStats {
    pub scans: usize,
    pub nodes: usize,
    pub sequential_matches: usize,
    pub sequential_rejected: usize,
    pub loop_candidates: usize,
    /// Loop closures, within a robot's chain and between robots.
    pub loop_closures: usize,
    /// Of `loop_closures`, those between two robots.
    pub inter_robot_closures: usize,
    pub gps_edges: usize,
    pub optimizations: usize,
    /// Optimizations put off because a part of the network was not anchored yet.
    pub deferred_optimizations: usize,
}

pub use crate::gnss::GpsObservation;

/// One robot's chain of nodes.
#[derive(Clone, Copy, Debug)]
struct Chain {
    last_node: usize,
    last_odometry: Pose2,
    /// Nodes in the chain so far.
    length: usize,
}

/// The incremental 2D mapper.
#[derive(Debug, Default)]
pub struct Mapper2d {
    params: Mapper2dParams,
    graph: PoseGraph,
    node_scans: Vec<Scan2>,
    /// The robot of each node, and the node's place in that robot's chain.
    node_robot: Vec<(usize, usize)>,
    /// Path length the node's robot travelled up to the node (m).
    node_path_m: Vec<f64>,

    /// Each robot's chain, by robot index.
    chains: Vec<Option<Chain>>,
    optimizer: Optimizer,
    stats: MapperStats,
    last_optimization: Option<OptimizeReport>,
    optimization_pending: bool,
}

impl Mapper2d {
    pub fn new(params: Mapper2dParams) -> Mapper2d {
        Mapper2d {
            params,
            ..Default::default()
        }
    }

    pub fn graph(&self) -> &PoseGraph {
        &self.graph
    }

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
            let closed = self.close_loops(node) > 0;
            if self.add_gps(node, gps) || closed {
                self.optimize_when_anchored()?;
            }
            return Ok(Placed::Node(node));
        };
        let last = chain.last_node;
        let step = chain.last_odometry.between(&odometry);
        let moved = step.x.hypot(step.y) >= self.params.node_distance_m
            || wrap_angle(step.theta).abs() >= self.params.node_rotation_rad;
        // Match against the last node from the odometry guess.
        let matched = idc(&self.node_scans[last], &scan, step, &self.params.idc)
            .ok()
            .filter(|m| accept(m, &self.params.gate) && self.agrees_with_odometry(m, &step));
        if !moved {
            let offset = matched.map_or(step, |m| m.pose);
            return Ok(Placed::Attached { node: last, offset });
        }
        let estimate = self.graph.poses[last].compose(&matched.as_ref().map_or(step, |m| m.pose));
        let path = self.node_path_m[last] + step.x.hypot(step.y);
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
        let closed = self.close_loops(node) > 0;
        if self.add_gps(node, gps) || closed {
            self.optimize_when_anchored()?;
        }
        Ok(Placed::Node(node))
    }

    /// Optimizes the network one last time; call after the last scan.
    pub fn finish(&mut self) -> Result<OptimizeReport, GraphError> {
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
        let length = self.chains[robot].map_or(0, |c| c.length);
        self.chains[robot] = Some(Chain {
            last_node: node,
            last_odometry: odometry,
            length: length + 1,
        });
        self.node_robot.push((robot, length));
        self.node_path_m.push(path_m);
        self.graph.poses.push(estimate);
        self.node_scans.push(scan);
        self.stats.nodes += 1;
        node
    }

    /// Whether match `m` of two nodes of one chain agrees with their odometry `step` (see
    /// `match_odometry_max_chi2`).
    fn agrees_with_odometry(&self, m: &Match, step: &Pose2) -> bool {
        let limit = self.params.match_odometry_max_chi2;
        if limit == f64::INFINITY {
            return true;
        }
        let Some(odometry) = self.odometry_information(step).try_inverse() else {
            return false;
        };
        let Some(matched) = self.match_information(&m.covariance).try_inverse() else {
            return false;
        };
        let e = nalgebra::Vector3::new(
            m.pose.x - step.x,
            m.pose.y - step.y,
            wrap_angle(m.pose.theta - step.theta),
        );
        (odometry + matched)
            .try_inverse()
            .is_some_and(|i| (e.transpose() * i * e)[(0, 0)] <= limit)
    }

    /// Adds a GPS edge per fix of `node`; returns whether it added any.
    fn add_gps(&mut self, node: usize, gps: &[GpsObservation]) -> bool {
        let mut added = false;
        for fix in gps {
            added |= self.add_gps_edge(node, fix);
        }
        added
    }

    /// Adds the GPS edge of one fix of `node`; returns whether it was taken.
    fn add_gps_edge(&mut self, node: usize, fix: &GpsObservation) -> bool {
        // A fix the network would reject (NaN, a covariance not positive definite) is
        // dropped here rather than failing every later optimization.
        let Some(information) = fix.covariance_m2.try_inverse() else {
            return false;
        };
        if !(is_information(&information)
            && fix
                .position_m
                .iter()
                .chain(fix.lever_arm_m.iter())
                .all(|v| v.is_finite()))
        {
            return false;
        }
        let edge = GpsEdge {
            node,
            position_m: fix.position_m,
            information,
            lever_arm_m: fix.lever_arm_m,
            robust: self.params.gps_robust,
        };
        self.graph.gps.push(edge);
        self.stats.gps_edges += 1;
        true
    }

    /// Matches `node` against earlier nodes near it, its own robot's and the others';
    /// returns how many closures were added.
    fn close_loops(&mut self, node: usize) -> usize {
        let p = self.params.clone();
        let here = self.graph.poses[node];
        let (robot, place) = self.node_robot[node];
        let mut candidates: Vec<(f64, usize)> = (0..node)
            .filter_map(|j| {
                let d = (self.graph.poses[j].x - here.x).hypot(self.graph.poses[j].y - here.y);
                let (other, other_place) = self.node_robot[j];
                let near = if other == robot {
                    place >= other_place + p.loop_min_node_gap
                        && d <= p.loop_search_radius_m
                            + p.loop_search_growth * (self.node_path_m[node] - self.node_path_m[j])
                } else {
                    d <= p.inter_robot_search_radius_m
                };
                near.then_some((d, j))
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Spread the candidates along the chains: the nearest one, then others at least
        // loop_min_node_gap nodes from those taken on the same chain.
        let mut taken: Vec<usize> = Vec::new();
        for (_, j) in candidates {
            if taken.len() >= p.loop_max_candidates {
                break;
            }
            let (chain, at) = self.node_robot[j];
            if taken.iter().all(|&t| {
                let (c, a) = self.node_robot[t];
                c != chain || a.abs_diff(at) >= p.loop_min_node_gap
            }) {
                taken.push(j);
            }
        }
        let mut added = 0;
        for j in taken {
            self.stats.loop_candidates += 1;
            let guess = self.graph.poses[j].between(&here);
            let Ok(m) = idc(&self.node_scans[j], &self.node_scans[node], guess, &p.idc) else {
                continue;
            };
            if !accept(&m, &p.gate) {
                continue;
            }
            let inter_robot = self.node_robot[j].0 != robot;
            self.graph.edges.push(RelativeEdge {
                from: j,
                to: node,
                measurement: m.pose,
                information: self.match_information(&m.covariance),
                kind: if inter_robot {
                    EdgeKind::InterRobot
                } else {
                    EdgeKind::LoopClosure
                },
                robust: p.loop_robust,
            });
            self.stats.loop_closures += 1;
            self.stats.inter_robot_closures += usize::from(inter_robot);
            added += 1;
        }
        added
    }

    /// Optimizes now, or marks it pending with `defer_optimization`.
    fn optimize_when_anchored(&mut self) -> Result<(), GraphError> {
        if self.params.defer_optimization {
            self.optimization_pending = true;
            return Ok(());
        }
        self.optimize_anchored().map(drop)
    }

    /// Runs the optimization that scans added since the last one called for (with
    /// `defer_optimization`); returns whether one ran.
    pub fn optimize_pending(&mut self) -> Result<bool, GraphError> {
        if !std::mem::take(&mut self.optimization_pending) {
            return Ok(false);
        }
        self.optimize_anchored()
    }

    /// Optimizes now, pending or not, unless a part of the network is not anchored yet;
    /// returns whether it ran.
    pub fn optimize_now(&mut self) -> Result<bool, GraphError> {
        self.optimization_pending = false;
        self.optimize_anchored()
    }

    /// Optimizes unless a part of the network is not anchored yet; returns whether it ran.
    fn optimize_anchored(&mut self) -> Result<bool, GraphError> {
        match self.optimize() {
            Ok(_) => Ok(true),
            Err(GraphError::Disconnected { .. } | GraphError::Singular) => {
                self.stats.deferred_optimizations += 1;
                Ok(false)
            }
            Err(e) => Err(e),
        }
    }

    fn optimize(&mut self) -> Result<OptimizeReport, GraphError> {
        let report = self
            .optimizer
            .optimize(&mut self.graph, &self.params.optimize)?;
        self.stats.optimizations += 1;
        self.last_optimization = Some(report);
        Ok(report)
    }

    fn odometry_information(&self, step: &Pose2) -> Matrix3<f64> {
        let p = &self.params;
        let sxy = p.odometry_sigma_xy_m + p.odometry_sigma_xy_per_m * step.x.hypot(step.y);
        let st = p.odometry_sigma_theta_rad
            + p.odometry_sigma_theta_per_rad * wrap_angle(step.theta).abs();
        Matrix3::from_diagonal(&nalgebra::Vector3::new(
            1.0 / (sxy * sxy),
            1.0 / (sxy * sxy),
            1.0 / (st * st),
        ))
    }

    /// Information of a scan match: its covariance with a floor on each standard deviation.
    fn match_information(&self, covariance: &[[f64; 3]; 3]) -> Matrix3<f64> {
        let p = &self.params;
        let mut c = Matrix3::from_fn(|r, k| covariance[r][k]);
        c = (c + c.transpose()) * 0.5;
        let floor = [
            p.match_min_sigma_xy_m.powi(2),
            p.match_min_sigma_xy_m.powi(2),
            p.match_min_sigma_theta_rad.powi(2),
        ];
        for (d, f) in floor.iter().enumerate() {
            c[(d, d)] += f;
        }
        c.try_inverse()
            .filter(|i| i.iter().all(|v| v.is_finite()))
            .unwrap_or_else(|| {
                Matrix3::from_diagonal(&nalgebra::Vector3::new(
                    1.0 / floor[0],
                    1.0 / floor[1],
                    1.0 / floor[2],
                ))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::synthetic::{Scene, uniform_bearings};
    use nalgebra::{Matrix2, Vector2};
    use std::f64::consts::PI;

    fn scan_at(pose: &Pose2, seed: u64) -> Scan2 {
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
        // by nothing but GPS. Its first fix alone cannot anchor it: the optimization waits
        // instead of failing.
        let mut bad_nan = fix_at(&Pose2::IDENTITY);
        bad_nan.position_m.x = f64::NAN;
        let mut bad_covariance = fix_at(&Pose2::IDENTITY);
        bad_covariance.covariance_m2 = Matrix2::new(1.0, 2.0, 2.0, 1.0);
        let mut deferred_at_start = 0;
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
                deferred_at_start = mapper.stats().deferred_optimizations;
            }
        }
        let stats = mapper.stats();
        assert!(deferred_at_start > 0, "{stats:?}");
        assert_eq!(stats.gps_edges, 4 + 3, "{stats:?}");
        assert_eq!(mapper.node_robot(4), (1, 0));
        mapper.finish().expect("anchored by then");
    }
}
