//! The loop closures' consistency check in the mapper: every closure, the matcher's or one
//! added from outside, waits as a candidate until it belongs to a maximum set of pairwise
//! consistent closures nearby (PCM over a bounded window), or it agrees with the map as it
//! stands and no larger set contradicts it; then it becomes an edge. A closure that neither
//! holds within `window_nodes` nodes is rejected. Right closures after much drift arrive in
//! runs that agree with each other; a wrong one stands alone or against them.

use super::Mapper2d;
use super::consistency::{ChainPaths, Closure, Uncertain, cycle_chi2, ends_gap, maximum_clique};
use crate::network::{EdgeKind, GraphError, RelativeEdge};
use crate::se2::Pose2;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// What became of a candidate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
enum State {
    Pending,
    Accepted,
    Rejected,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Candidate {
    /// With the covariance the check uses (the match's plus the floors).
    closure: Closure,
    /// The edge's information, as the matcher gave it.
    information: Matrix3<f64>,
    state: State,
}

/// The candidates so far, the chains they are checked along, and the pairs checked.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct ClosureBook {
    pub(super) paths: ChainPaths,
    candidates: Vec<Candidate>,
    pending: Vec<usize>,
    /// Pair (lower index, higher index) → consistent; chains never change, so neither does this.
    consistent: HashMap<(usize, usize), bool>,
}

/// At most this many candidates take part in one clique search (the nearest ones).
const MAX_NEIGHBOURS: usize = 63;

impl Mapper2d {
    /// Records node `node`'s step from `last` on chain `robot` (its sequential edges, fused),
    /// for the consistency check; `None` for a chain's first node.
    pub(super) fn record_chain_step(&mut self, robot: usize, node: usize, last: Option<usize>) {
        let Some(last) = last else {
            return self.book.paths.start(node, robot);
        };
        let c = &self.params.loop_consistency;
        let sequential = self
            .graph
            .edges
            .iter()
            .rev()
            .take_while(|e| e.to == node)
            .filter(|e| e.from == last);
        let mut information = Matrix3::zeros();
        let mut measurement = None;
        for e in sequential {
            information += e.information;
            if measurement.is_none() || e.kind == EdgeKind::ScanMatch {
                measurement = Some(e.measurement);
            }
        }
        let floor = Vector3::new(
            c.step_min_sigma_xy_m.powi(2),
            c.step_min_sigma_xy_m.powi(2),
            c.step_min_sigma_theta_rad.powi(2),
        );
        let covariance = information
            .try_inverse()
            .unwrap_or_else(|| Matrix3::from_diagonal_element(1e6))
            + Matrix3::from_diagonal(&floor);
        let step = Uncertain {
            pose: measurement.unwrap_or(Pose2::IDENTITY),
            covariance,
        };
        self.book.paths.extend(node, robot, &step);
    }

    /// Adds a loop-closure candidate from outside the matcher (a place recognizer, another
    /// mapper, a test's wrong closure): node `to` seen from node `from` with its covariance
    /// (m², rad²). It goes through the same consistency check as the matcher's closures and
    /// becomes an edge only when it passes; returns how many edges that added now (it may
    /// also let waiting closures through), and re-optimizes if any.
    pub fn add_closure_candidate(
        &mut self,
        from: usize,
        to: usize,
        measurement: Pose2,
        covariance: [[f64; 3]; 3],
    ) -> Result<usize, GraphError> {
        let nodes = self.graph.poses.len();
        let edge = self.graph.edges.len();
        if let Some(&node) = [from, to].iter().find(|&&n| n >= nodes) {
            return Err(GraphError::MissingNode { edge, node, nodes });
        }
        if from == to {
            return Err(GraphError::SelfLoop { edge });
        }
        let information = self.match_information(&covariance);
        if !measurement.is_finite() || !covariance.iter().flatten().all(|v| v.is_finite()) {
            return Err(GraphError::NotFinite { edge });
        }
        self.stats.external_closures += 1;
        let added = self.submit_and_verify(from, to, measurement, information);
        if added > 0 {
            self.optimize_when_anchored(to)?;
        }
        Ok(added)
    }

    /// Checks a new closure against its neighbours; returns how many edges that added.
    pub(super) fn submit_closure(
        &mut self,
        from: usize,
        to: usize,
        measurement: Pose2,
        information: Matrix3<f64>,
    ) -> usize {
        let c = &self.params.loop_consistency;
        let floor = Vector3::new(
            c.closure_min_sigma_xy_m.powi(2),
            c.closure_min_sigma_xy_m.powi(2),
            c.closure_min_sigma_theta_rad.powi(2),
        );
        let covariance = information
            .try_inverse()
            .unwrap_or_else(|| Matrix3::from_diagonal_element(1e6))
            + Matrix3::from_diagonal(&floor);
        let index = self.book.candidates.len();
        self.book.candidates.push(Candidate {
            closure: Closure {
                from,
                to,
                measurement: Uncertain {
                    pose: measurement,
                    covariance,
                },
            },
            information,
            state: State::Pending,
        });
        if !self.params.loop_consistency.enabled {
            self.accept(index);
            return 1;
        }
        self.book.pending.push(index);
        self.resolve(index)
    }

    /// Decides the closures waiting longer than the window (all of them with `all`, after the
    /// last scan): accepted if a large enough consistent set holds them now, else rejected.
    /// Returns how many edges that added.
    pub(super) fn expire_closures(&mut self, all: bool) -> usize {
        let window = self.params.loop_consistency.window_nodes;
        let pending = std::mem::take(&mut self.book.pending);
        let mut added = 0;
        let mut waiting = Vec::new();
        for index in pending {
            if self.book.candidates[index].state != State::Pending {
                continue;
            }
            let c = self.book.candidates[index].closure;
            let place = self.book.paths.place(c.from.max(c.to));
            let behind = self.book.paths.chain_len(place.chain) - 1 - place.place;
            if !all && behind <= window {
                waiting.push(index);
                continue;
            }
            added += self.resolve(index);
            if self.book.candidates[index].state == State::Pending {
                self.book.candidates[index].state = State::Rejected;
                self.stats.loop_closures_rejected += 1;
            }
        }
        self.book.pending = waiting;
        added
    }

    /// The maximum consistent set among `index` and its neighbours: its waiting members
    /// become edges when it is large enough. Returns how many edges that added.
    fn resolve(&mut self, index: usize) -> usize {
        let p = self.params.loop_consistency.clone();
        let here = self.book.candidates[index].closure;
        let mut near: Vec<(usize, usize)> = (0..self.book.candidates.len())
            .filter(|&k| k != index && self.book.candidates[k].state != State::Rejected)
            .filter_map(|k| {
                let gap = ends_gap(&here, &self.book.candidates[k].closure, &self.book.paths)?;
                (gap <= p.window_nodes).then_some((gap, k))
            })
            .collect();
        near.sort_unstable();
        near.truncate(MAX_NEIGHBOURS);
        let members: Vec<usize> = std::iter::once(index)
            .chain(near.iter().map(|&(_, k)| k))
            .collect();
        let mut adjacent = vec![0u64; members.len()];
        let mut preferred = 0u64;
        for (i, &a) in members.iter().enumerate() {
            if self.book.candidates[a].state == State::Accepted {
                preferred |= 1 << i;
            }
            for (j, &b) in members.iter().enumerate().skip(i + 1) {
                if self.consistent(a, b, p.max_chi2) {
                    adjacent[i] |= 1 << j;
                    adjacent[j] |= 1 << i;
                }
            }
        }
        let clique = maximum_clique(&adjacent, preferred);
        if (clique.count_ones() as usize) < p.min_group.max(1) {
            // Alone, or with too few: it may still agree with the map as it stands.
            if clique & 1 != 0 && self.agrees_with_map(index, p.agree_max_chi2) {
                self.accept(index);
                return 1;
            }
            return 0;
        }
        let mut added = 0;
        for (i, &k) in members.iter().enumerate() {
            if clique & (1 << i) != 0 && self.book.candidates[k].state == State::Pending {
                self.accept(k);
                added += 1;
            }
        }
        added
    }

    /// Whether candidates `a` and `b` are pairwise consistent (cached).
    fn consistent(&mut self, a: usize, b: usize, max_chi2: f64) -> bool {
        let key = (a.min(b), a.max(b));
        if let Some(&known) = self.book.consistent.get(&key) {
            return known;
        }
        let (ca, cb) = (
            &self.book.candidates[a].closure,
            &self.book.candidates[b].closure,
        );
        let known = cycle_chi2(ca, cb, &self.book.paths).is_some_and(|chi2| chi2 <= max_chi2);
        self.book.consistent.insert(key, known);
        known
    }

    /// Whether candidate `index` lies within `max_chi2` of the current estimate.
    fn agrees_with_map(&self, index: usize, max_chi2: f64) -> bool {
        let c = &self.book.candidates[index].closure;
        let estimate = self.graph.poses[c.from].between(&self.graph.poses[c.to]);
        let error = Uncertain {
            pose: c.measurement.pose.between(&estimate),
            covariance: c.measurement.covariance,
        };
        error.chi2_from_identity() <= max_chi2
    }

    /// Whether candidate `index` still waits.
    pub(super) fn is_pending(&self, index: usize) -> bool {
        self.book.candidates[index].state == State::Pending
    }

    /// How many candidates there are.
    pub(super) fn candidate_count(&self) -> usize {
        self.book.candidates.len()
    }

    /// Node `offset` places from `node` along its chain.
    pub(super) fn chain_neighbour(&self, node: usize, offset: isize) -> Option<usize> {
        self.book.paths.neighbour(node, offset)
    }

    /// Candidate `index` becomes an edge.
    fn accept(&mut self, index: usize) {
        let candidate = &mut self.book.candidates[index];
        candidate.state = State::Accepted;
        let Closure {
            from,
            to,
            measurement,
        } = candidate.closure;
        let information = candidate.information;
        let inter_robot = self.node_robot[from].0 != self.node_robot[to].0;
        self.join_parts(from, to, &measurement.pose);
        self.graph.edges.push(RelativeEdge {
            from,
            to,
            measurement: measurement.pose,
            information,
            kind: if inter_robot {
                EdgeKind::InterRobot
            } else {
                EdgeKind::LoopClosure
            },
            robust: self.params.loop_robust,
        });
        self.stats.loop_closures += 1;
        self.stats.inter_robot_closures += usize::from(inter_robot);
    }
}

#[cfg(test)]
mod tests {
    use super::super::Mapper2dParams;
    use super::*;
    use crate::matching::Scan2;
    use crate::matching::synthetic::{Scene, uniform_bearings};
    use std::f64::consts::PI;

    /// Four nodes 0.6 m apart in the simulated park, and where they truly are.
    fn four_nodes(params: Mapper2dParams) -> (Mapper2d, Vec<Pose2>) {
        let mut mapper = Mapper2d::new(params);
        let truth: Vec<Pose2> = (0..4)
            .map(|k| Pose2::new(-2.0 + 0.6 * k as f64, 0.0, 0.0))
            .collect();
        let bearings = uniform_bearings(361, -PI / 2.0, PI / 360.0);
        for (k, pose) in truth.iter().enumerate() {
            let ranges = Scene::park().scan(pose, &bearings, 40.0, 0.01, k as u64);
            let scan = Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths");
            mapper.add_scan(*pose, scan).expect("add");
        }
        assert_eq!(mapper.graph().poses.len(), 4);
        (mapper, truth)
    }

    const COVARIANCE: [[f64; 3]; 3] = [[4e-4, 0.0, 0.0], [0.0, 4e-4, 0.0], [0.0, 0.0, 1e-4]];

    #[test]
    fn a_closure_that_agrees_with_the_map_is_an_edge_a_wrong_one_is_not() {
        let (mut mapper, truth) = four_nodes(Mapper2dParams::default());
        let edges = mapper.graph().edges.len();
        let between = |a: usize, b: usize| truth[a].between(&truth[b]);
        // A right closure agrees with the map as it stands: an edge at once.
        assert_eq!(
            mapper.add_closure_candidate(0, 2, between(0, 2), COVARIANCE),
            Ok(1)
        );
        // A wrong one (1 m off) contradicts it and the map: it waits, and is rejected at the end.
        let wrong = between(1, 3).compose(&Pose2::new(1.0, 0.0, 0.1));
        assert_eq!(mapper.add_closure_candidate(1, 3, wrong, COVARIANCE), Ok(0));
        mapper.finish().expect("optimize");
        let stats = mapper.stats();
        assert_eq!(mapper.graph().edges.len(), edges + 1);
        assert_eq!(
            (
                stats.external_closures,
                stats.loop_closures,
                stats.loop_closures_rejected
            ),
            (2, 1, 1)
        );
    }

    #[test]
    fn without_the_check_every_closure_is_an_edge_and_bad_ones_are_errors() {
        let mut params = Mapper2dParams::default();
        params.loop_consistency.enabled = false;
        let (mut mapper, _) = four_nodes(params);
        let wrong = Pose2::new(5.0, 1.0, 1.0);
        assert_eq!(mapper.add_closure_candidate(0, 3, wrong, COVARIANCE), Ok(1));
        assert_eq!(mapper.stats().loop_closures, 1);
        assert!(matches!(
            mapper.add_closure_candidate(0, 9, wrong, COVARIANCE),
            Err(GraphError::MissingNode { node: 9, .. })
        ));
        assert!(matches!(
            mapper.add_closure_candidate(2, 2, wrong, COVARIANCE),
            Err(GraphError::SelfLoop { .. })
        ));
        let nan = Pose2::new(f64::NAN, 0.0, 0.0);
        assert!(matches!(
            mapper.add_closure_candidate(0, 3, nan, COVARIANCE),
            Err(GraphError::NotFinite { .. })
        ));
    }
}
