//! Bounded growth: where the map already has nodes, a robot passing again adds nothing. A
//! place is *covered* when the map has `max_nodes` nodes within `radius_m` of it, heading
//! within `heading_rad`, in the same part of the network. The caller (the fleet's map)
//! decides per node: the first covered node of a stretch is added (its loop closures tie the
//! chain to the map and correct its drift); the covered ones after it are only located,
//! by IDC against the nearest covering node, and not added; a node that cannot be located
//! is added. So the network's nodes per area stay bounded however often a place is passed.

use super::Mapper2d;
use crate::matching::correlative::{SearchWindow, search};
use crate::matching::{Scan2, accept, idc};
use crate::se2::{Pose2, wrap_angle};
use crate::{GpsEdge, GpsObservation};
use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

/// When a place counts as covered, and how a pass is located.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CoverageParams {
    /// Pass over covered places at all (the fleet's map decides; the mapper only answers).
    pub enabled: bool,
    /// A place is covered by nodes within this distance (m)…
    pub radius_m: f64,
    /// …whose heading is within this of the robot's (rad): a place seen the other way is
    /// another view…
    pub heading_rad: f64,
    /// …when there are this many. A robot's own nodes count once it has driven
    /// `min_path_gap_m` (m) since them.
    pub max_nodes: usize,
    /// See `max_nodes` (m).
    pub min_path_gap_m: f64,
    /// A pass located by IDC must lie within this of where odometry put it (m); the
    /// correlative search looks this far…
    pub max_shift_m: f64,
    /// …and turns this far (rad)…
    pub max_turn_rad: f64,
    /// …for a pose that scores at least this (mean cell value under the returns).
    pub min_score: f64,
    /// Passes not located go on by odometry from the last one located for at most this
    /// path (m); the next is added (its closures tie the chain again).
    pub max_unlocated_m: f64,
    /// A located pass's GPS fixes become GPS edges of the node it passed, up to this many
    /// GPS edges per node: averaging 64 fixes takes a fix's noise down 8×, below what the
    /// scan matches hold the nodes to, and the network stays bounded however long a fleet
    /// drives.
    pub max_fixes_per_node: usize,
}

impl Default for CoverageParams {
    fn default() -> Self {
        CoverageParams {
            enabled: true,
            radius_m: 3.0,
            heading_rad: 45f64.to_radians(),
            max_nodes: 1,
            min_path_gap_m: 20.0,
            max_shift_m: 0.5,
            max_turn_rad: 5f64.to_radians(),
            min_score: 0.6,
            max_unlocated_m: 15.0,
            max_fixes_per_node: 64,
        }
    }
}

/// A chain's nodes passed since its last node: how many, the path they drove, the last one's
/// odometry and map pose. The chain's next node counts them in its path and place, so that
/// its loop closures see how far the robot went (a lap passed is a lap driven). The next pass
/// is predicted from the last one's map pose (after a restart too), and so is the next node
/// when its scan does not match the chain's last node's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Passed {
    /// Nodes passed.
    pub nodes: usize,
    /// Path from the chain's last node through them (m).
    pub path_m: f64,
    /// The last one's odometry pose (scan frame in the odometry frame).
    pub odometry: Option<Pose2>,
    /// The last one's map pose: located, or carried on by odometry from the last located;
    /// `None` when not known (passes stored before it was kept).
    pub pose: Option<Pose2>,
    /// Path driven since a pass was last located (m).
    pub unlocated_m: f64,
}

impl Mapper2d {
    /// Counts a node of `robot`'s chain passed at `odometry`, at `pose` on the map (when
    /// known) with `unlocated_m` driven since a pass was last located; the chain's passes so
    /// far.
    pub fn note_pass(
        &mut self,
        robot: usize,
        odometry: Pose2,
        pose: Option<Pose2>,
        unlocated_m: f64,
    ) -> Passed {
        let Some(chain) = self.chains.get_mut(robot).and_then(Option::as_mut) else {
            return Passed::default();
        };
        let from = chain.passed.odometry.unwrap_or(chain.last_odometry);
        let step = from.between(&odometry);
        chain.passed = Passed {
            nodes: chain.passed.nodes + 1,
            path_m: chain.passed.path_m + step.x.hypot(step.y),
            odometry: Some(odometry),
            pose,
            unlocated_m,
        };
        chain.passed
    }

    /// A chain's passes as stored (a replay).
    pub fn restore_passed(&mut self, robot: usize, passed: Passed) {
        if let Some(chain) = self.chains.get_mut(robot).and_then(Option::as_mut) {
            chain.passed = passed;
        }
    }

    /// The path `robot`'s chain will have driven at a node at `odometry` (m): what
    /// [`Mapper2d::add_robot_scan`] gives it, passes included.
    pub fn path_at(&self, robot: usize, odometry: &Pose2) -> f64 {
        let Some(chain) = self.chains.get(robot).copied().flatten() else {
            return 0.0;
        };
        let from = chain.passed.odometry.unwrap_or(chain.last_odometry);
        let step = from.between(odometry);
        self.node_path_m[chain.last_node] + chain.passed.path_m + step.x.hypot(step.y)
    }

    /// The nodes that cover `pose` (a node of `robot`'s chain after `path_m` of driving) in
    /// its part of the network, nearest first; the place is covered when there are
    /// `coverage.max_nodes` of them. The chain's own nodes count once it has driven
    /// `min_path_gap_m` since them: the nodes just behind a robot are not a place it passes
    /// again.
    pub fn covering(&self, pose: &Pose2, robot: usize, path_m: f64) -> Vec<usize> {
        let p = &self.params.coverage;
        let Some(chain) = self.chains.get(robot).copied().flatten() else {
            return Vec::new();
        };
        let mut near: Vec<(f64, usize)> = self
            .near
            .near(pose, p.radius_m)
            .filter(|&n| self.parts.same_part(n, chain.last_node))
            .filter(|&n| {
                self.node_robot[n].0 != robot || path_m - self.node_path_m[n] >= p.min_path_gap_m
            })
            .filter_map(|n| {
                let q = &self.graph.poses[n];
                let d = (q.x - pose.x).hypot(q.y - pose.y);
                let turn = wrap_angle(q.theta - pose.theta).abs();
                (d <= p.radius_m && turn <= p.heading_rad).then_some((d, n))
            })
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        near.into_iter().map(|(_, n)| n).collect()
    }

    /// Where `scan`, predicted at `predicted`, lies: IDC against node `near` from the
    /// prediction, gated like a sequential match and within `coverage.max_shift_m` of it;
    /// failing that, the correlative search in the finished submap holding `near`, in a
    /// window of that size (sparse scans a metre or two from a node often fail IDC's gate).
    pub fn locate_against(&self, near: usize, predicted: &Pose2, scan: &Scan2) -> Option<Pose2> {
        let p = &self.params.coverage;
        let frame = self.graph.poses[near];
        let guess = frame.between(predicted);
        // Not asking for convergence: the prediction is odometry's, centimetres off.
        let gate = crate::matching::QualityGate {
            require_converged: false,
            ..self.params.gate.clone()
        };
        let by_idc = idc(&self.node_scans[near], scan, guess, &self.params.idc)
            .ok()
            .filter(|m| accept(m, &gate))
            .map(|m| frame.compose(&m.pose))
            .filter(|pose| (pose.x - predicted.x).hypot(pose.y - predicted.y) <= p.max_shift_m);
        by_idc.or_else(|| {
            let k = self.submap_of(near)?;
            let anchor = self.graph.poses[self.submaps.done[k].anchor];
            let window = SearchWindow {
                linear_m: p.max_shift_m,
                angular_rad: p.max_turn_rad,
            };
            let grids = self.pooled_grids(k);
            let initial = anchor.between(predicted);
            let grid = &self.params.submaps.grid;
            let found = search(&grids, scan, initial, &window, p.min_score, grid)?;
            Some(anchor.compose(&found.pose))
        })
    }

    /// A pass located at `located` against node `near` brings its GPS fixes to that node,
    /// each antenna where the pass had it, in `near`'s frame: they wait for the next solve
    /// applied ([`Self::flush_pass_fixes`]), and call for one. At most `coverage.max_fixes_per_node` GPS edges
    /// per node, those waiting included. How many were taken.
    pub fn add_pass_fixes(
        &mut self,
        near: usize,
        located: &Pose2,
        gps: &[GpsObservation],
    ) -> usize {
        let room = self
            .params
            .coverage
            .max_fixes_per_node
            .saturating_sub(self.fixes_on(near))
            .saturating_sub(self.pass_fixes.iter().filter(|f| f.node == near).count());
        let in_near = self.graph.poses[near].between(located);
        let edges: Vec<GpsEdge> = gps
            .iter()
            .filter_map(|fix| {
                let [x, y] = in_near.transform_point([fix.lever_arm_m.x, fix.lever_arm_m.y]);
                let carried = GpsObservation {
                    lever_arm_m: Vector2::new(x, y),
                    ..*fix
                };
                self.gps_edge(near, &carried)
            })
            .take(room)
            .collect();
        let taken = edges.len();
        self.pass_fixes.extend(edges);
        // A robot that only passes adds no node that would call for one.
        self.optimization_pending |= taken > 0;
        taken
    }

    /// Moves the passes' waiting fixes into the network, to count from the next solve on.
    /// Call it when a solve was applied, and store what it returns with that solve: a replay
    /// puts them back there ([`Self::restore_pass_fixes`]), so that it rebuilds the same
    /// network whatever happened between two solves.
    pub fn flush_pass_fixes(&mut self) -> Vec<GpsEdge> {
        let fixes = std::mem::take(&mut self.pass_fixes);
        self.restore_pass_fixes(&fixes);
        fixes
    }

    /// Fixes that [`Self::flush_pass_fixes`] moved, put back where it did (a replay).
    pub fn restore_pass_fixes(&mut self, fixes: &[GpsEdge]) {
        if fixes.is_empty() {
            return;
        }
        self.graph.gps.extend_from_slice(fixes);
        self.stats.gps_edges += fixes.len();
        self.stats.pass_fixes += fixes.len();
        self.optimization_pending = true;
    }

    /// The parameters.
    pub fn params(&self) -> &super::Mapper2dParams {
        &self.params
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::scan_at;
    use super::*;
    use nalgebra::Matrix2;

    /// A pass 1.5 m ahead of and turned from the node it is located against: its fix ends up
    /// on that node with the antenna where the pass had it, so the fix holds exactly at the
    /// node's true pose; the node takes at most `max_fixes_per_node`, and only once a solve
    /// was applied do they enter the network.
    #[test]
    fn a_pass_fix_holds_the_node_passed_where_the_pass_was() {
        let params = super::super::Mapper2dParams {
            coverage: CoverageParams {
                max_fixes_per_node: 3,
                ..Default::default()
            },
            ..Default::default()
        };
        let mut mapper = Mapper2d::new(params);
        let node_pose = Pose2::new(2.0, 1.0, 0.3);
        mapper.add_scan(node_pose, scan_at(&node_pose, 1)).unwrap();
        let located = node_pose.compose(&Pose2::new(1.5, -0.4, 0.2));
        // The antenna 0.5 m behind the pass's scan frame, at its true place.
        let lever = Vector2::new(-0.5, 0.0);
        let [ax, ay] = located.transform_point([lever.x, lever.y]);
        let fix = GpsObservation {
            position_m: Vector2::new(ax, ay),
            covariance_m2: Matrix2::identity() * 0.04,
            lever_arm_m: lever,
        };
        assert_eq!(mapper.add_pass_fixes(0, &located, &[fix, fix]), 2);
        assert_eq!(
            mapper.add_pass_fixes(0, &located, &[fix, fix]),
            1,
            "bounded"
        );
        assert!(mapper.graph.gps.is_empty(), "waiting for a solve applied");
        let flushed = mapper.flush_pass_fixes();
        assert_eq!((flushed.len(), mapper.graph.gps.len()), (3, 3));
        assert_eq!(mapper.stats.pass_fixes, 3);
        for edge in &mapper.graph.gps {
            let [x, y] = node_pose.transform_point([edge.lever_arm_m.x, edge.lever_arm_m.y]);
            let residual = (x - ax).hypot(y - ay);
            assert!(residual < 1e-12, "{residual} m at the node's true pose");
        }
        assert_eq!(mapper.add_pass_fixes(0, &located, &[fix]), 0, "full");
    }

    /// A node added after passes the sequential match cannot bridge is placed from the last
    /// pass's map pose, not through the odometry of every pass since the chain's last node,
    /// which drifts (here 5 % long and 0.5° a step).
    #[test]
    fn a_node_after_passes_is_placed_from_the_last_pass() {
        let mut mapper = Mapper2d::new(super::super::Mapper2dParams::default());
        let start = Pose2::new(-8.0, -2.0, 0.0);
        mapper.add_scan(start, scan_at(&start, 1)).unwrap();
        let drifting = Pose2::new(0.525, 0.0, 0.5f64.to_radians());
        let (mut truth, mut odometry) = (start, start);
        for _ in 0..30 {
            truth = truth.compose(&Pose2::new(0.5, 0.0, 0.0));
            odometry = odometry.compose(&drifting);
            mapper.note_pass(0, odometry, Some(truth), 0.0);
        }
        truth = truth.compose(&Pose2::new(0.5, 0.0, 0.0));
        odometry = odometry.compose(&drifting);
        let super::super::Placed::Node(node) =
            mapper.add_scan(odometry, scan_at(&truth, 2)).unwrap()
        else {
            panic!("a node");
        };
        let placed = mapper.graph.poses[node];
        let off = (placed.x - truth.x).hypot(placed.y - truth.y);
        let through_passes = start.compose(&start.between(&odometry));
        let drifted = (through_passes.x - truth.x).hypot(through_passes.y - truth.y);
        assert!(drifted > 2.0, "the odometry drifted {drifted} m");
        assert!(off < 0.05, "placed {off} m from the truth");
    }
}
