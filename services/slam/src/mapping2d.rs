//! Scan-based 2D SLAM (paper section 4) on a stream of scans with odometry: nodes every few
//! decimetres or degrees, odometry and IDC edges between successive nodes, loop closures
//! verified by IDC and the quality gate, and the network re-optimized as closures arrive.
//! Scans between nodes hang off their node by an IDC offset, so every scan gets a pose.
//!
//! Loop-closure candidates are earlier nodes whose current estimate lies within a search
//! radius of the new node's, excluding its recent predecessors; a candidate becomes an edge
//! only when IDC matches it and the gate accepts the match, and then with a soft robust
//! kernel (Cauchy, c = 10): a closure that slips through wrongly is down-weighted, while a
//! right one that arrives after much drift still pulls the map. (DCS was measured on ACES:
//! it discarded the right closures too, and the relation error tripled.)

use crate::matching::{IdcParams, QualityGate, Scan2, accept, idc};
use crate::network::{EdgeKind, GraphError, PoseGraph, RelativeEdge};
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
    /// Loop-closure candidates: earlier nodes within this distance (m) of the new node, plus
    /// `loop_search_growth` times the path travelled between them (drift grows with it)…
    pub loop_search_radius_m: f64,
    pub loop_search_growth: f64,
    /// …and at least this many nodes back.
    pub loop_min_node_gap: usize,
    /// At most this many candidates are matched per new node (the nearest first).
    pub loop_max_candidates: usize,
    /// Robust kernel of loop closures.
    pub loop_robust: Robust,
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
            loop_search_radius_m: 3.0,
            loop_search_growth: 0.2,
            loop_min_node_gap: 20,
            loop_max_candidates: 4,
            loop_robust: Robust::Cauchy { c: 10.0 },
            idc: IdcParams::default(),
            gate: QualityGate::default(),
            optimize: OptimizeParams::default(),
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MapperStats {
    pub scans: usize,
    pub nodes: usize,
    pub sequential_matches: usize,
    pub sequential_rejected: usize,
    pub loop_candidates: usize,
    pub loop_closures: usize,
    pub optimizations: usize,
}

/// The incremental 2D mapper.
#[derive(Debug, Default)]
pub struct Mapper2d {
    params: Mapper2dParams,
    graph: PoseGraph,
    node_scans: Vec<Scan2>,
    node_odometry: Vec<Pose2>,
    /// Path length travelled up to each node (m).
    node_path_m: Vec<f64>,
    optimizer: Optimizer,
    stats: MapperStats,
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

    /// Adds a scan taken at `odometry` (any consistent odometry frame): a new node when the
    /// robot moved far enough since the last node, else attached to the last node.
    pub fn add_scan(&mut self, odometry: Pose2, scan: Scan2) -> Result<Placed, GraphError> {
        self.stats.scans += 1;
        let Some(&last_odometry) = self.node_odometry.last() else {
            self.push_node(odometry, odometry, scan);
            return Ok(Placed::Node(0));
        };
        let last = self.graph.poses.len() - 1;
        let step = last_odometry.between(&odometry);
        let moved = step.x.hypot(step.y) >= self.params.node_distance_m
            || wrap_angle(step.theta).abs() >= self.params.node_rotation_rad;
        // Match against the last node from the odometry guess.
        let matched = idc(&self.node_scans[last], &scan, step, &self.params.idc)
            .ok()
            .filter(|m| accept(m, &self.params.gate));
        if !moved {
            let offset = matched.map_or(step, |m| m.pose);
            return Ok(Placed::Attached { node: last, offset });
        }
        let node = self.graph.poses.len();
        let estimate = self.graph.poses[last].compose(&matched.as_ref().map_or(step, |m| m.pose));
        self.push_node(estimate, odometry, scan);
        // The scan match when the gate accepts it, else odometry: where both exist, the
        // match is far more precise and odometry would only pull it off (its errors are not
        // independent white noise).
        match matched {
            Some(m) => {
                self.stats.sequential_matches += 1;
                self.graph.edges.push(RelativeEdge {
                    from: last,
                    to: node,
                    measurement: m.pose,
                    information: self.match_information(&m.covariance),
                    kind: EdgeKind::ScanMatch,
                    robust: Robust::None,
                });
            }
            None => {
                self.stats.sequential_rejected += 1;
                self.graph.edges.push(RelativeEdge {
                    from: last,
                    to: node,
                    measurement: step,
                    information: self.odometry_information(&step),
                    kind: EdgeKind::Odometry,
                    robust: Robust::None,
                });
            }
        }
        if self.close_loops(node) > 0 {
            self.optimize()?;
        }
        Ok(Placed::Node(node))
    }

    /// Optimizes the network one last time; call after the last scan.
    pub fn finish(&mut self) -> Result<OptimizeReport, GraphError> {
        self.optimize()
    }

    fn push_node(&mut self, estimate: Pose2, odometry: Pose2, scan: Scan2) {
        let path = match (self.node_odometry.last(), self.node_path_m.last()) {
            (Some(previous), Some(length)) => {
                length + (odometry.x - previous.x).hypot(odometry.y - previous.y)
            }
            _ => 0.0,
        };
        self.node_path_m.push(path);
        self.graph.poses.push(estimate);
        self.node_odometry.push(odometry);
        self.node_scans.push(scan);
        self.stats.nodes += 1;
    }

    /// Matches `node` against earlier nodes near it; returns how many closures were added.
    fn close_loops(&mut self, node: usize) -> usize {
        let p = self.params.clone();
        let here = self.graph.poses[node];
        let mut candidates: Vec<(f64, usize)> = (0..node.saturating_sub(p.loop_min_node_gap))
            .map(|j| {
                (
                    (self.graph.poses[j].x - here.x).hypot(self.graph.poses[j].y - here.y),
                    j,
                )
            })
            .filter(|&(d, j)| {
                d <= p.loop_search_radius_m
                    + p.loop_search_growth * (self.node_path_m[node] - self.node_path_m[j])
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Spread the candidates along the path: the nearest one, then others at least
        // loop_min_node_gap nodes from those taken.
        let mut taken: Vec<usize> = Vec::new();
        for (_, j) in candidates {
            if taken.len() >= p.loop_max_candidates {
                break;
            }
            if taken.iter().all(|&t| t.abs_diff(j) >= p.loop_min_node_gap) {
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
            self.graph.edges.push(RelativeEdge {
                from: j,
                to: node,
                measurement: m.pose,
                information: self.match_information(&m.covariance),
                kind: EdgeKind::LoopClosure,
                robust: p.loop_robust,
            });
            self.stats.loop_closures += 1;
            added += 1;
        }
        added
    }

    fn optimize(&mut self) -> Result<OptimizeReport, GraphError> {
        self.stats.optimizations += 1;
        self.optimizer
            .optimize(&mut self.graph, &self.params.optimize)
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
