//! First contact between parts of the network that share no frame: a robot that floats
//! alone (no GPS anchor, no closure with another robot) cannot be looked for near its
//! estimate, which is in a frame of its own. Instead, every pair of submaps of two robots
//! in different parts (one of them floating) is searched once, when the later of the two
//! is finished, both ways: each node of one, its scan alone, in the other's grid, whole and
//! at every heading (the correlative matcher needs no guess). Pairs, not a robot's nodes
//! against whatever submaps exist at the time: two robots that pass the same place minutes
//! apart, in either order, are compared.
//!
//! Two robots on different paths see a place from different sides, so a true match scores
//! lower than a loop closure of one robot (`min_score`). What keeps wrong matches out is
//! the rest: a match whose runner-up elsewhere scores nearly as well is ambiguous and
//! dropped (the park's lamp posts stand in rows), IDC must confirm it, and it is only a
//! hypothesis (where one part lies in the other) until a second, from four other nodes,
//! places the two parts the same way (`agree_m` plus `agree_drift` of the path between
//! them, `agree_rad`). Then both become inter-robot closures and one part is moved onto the
//! other (`parts.rs`); from then on the ordinary searches find its closures.

use super::Mapper2d;
use crate::matching::correlative::SearchWindow;
use crate::network::{EdgeKind, RelativeEdge};
use crate::se2::{Pose2, wrap_angle};
use serde::{Deserialize, Serialize};

/// How parts that share no frame are searched for one another.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FirstContactParams {
    /// Search at all.
    pub enabled: bool,
    /// Pairs of submaps searched per new node at most; the rest wait for the next nodes.
    pub pairs_per_node: usize,
    /// Translations within the submap's extent plus this margin (m).
    pub margin_m: f64,
    /// The best pose must score at least this (a whole-map search scores many wrong poses).
    pub min_score: f64,
    /// Two matches confirm each other when they place the parts within this (m)…
    pub agree_m: f64,
    /// …plus this share of the path (m) between the two matches' nodes on each part, over
    /// which the estimates drift apart…
    pub agree_drift: f64,
    /// …and this (rad) of each other.
    pub agree_rad: f64,
    /// IDC's refinement must pass the quality gate too (else it must only stay near the
    /// correlative pose: two scans of a place from far apart often fail the gate's overlap
    /// share, and the second match is the check).
    pub gated: bool,
}

impl Default for FirstContactParams {
    fn default() -> Self {
        FirstContactParams {
            enabled: true,
            pairs_per_node: 32,
            margin_m: 5.0,
            min_score: 0.45,
            agree_m: 0.5,
            agree_drift: 0.01,
            agree_rad: 2f64.to_radians(),
            gated: false,
        }
    }
}

/// The submaps whose pairs are searched, and the matches that wait for a second.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct ContactSearch {
    /// The next pair to consider: submap `later` with submap `earlier` (< `later`).
    later: usize,
    earlier: usize,
    hypotheses: Vec<Hypothesis>,
}

/// A match between parts: the closure it would be.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Hypothesis {
    edge: RelativeEdge,
}

/// Hypotheses kept (the oldest go).
const MAX_HYPOTHESES: usize = 64;

impl Mapper2d {
    /// Searches the next pairs of submaps, at most `pairs_per_node` of them (the rest wait
    /// for the next node: a lone robot in a big map has many); returns how many parts it
    /// joined.
    pub(super) fn seek_first_contact(&mut self) -> usize {
        let p = self.params.first_contact.clone();
        let (mut joined, mut budget) = (0, p.pairs_per_node);
        self.sync_parts();
        while p.enabled && budget > 0 && self.contact.later < self.submaps.done.len() {
            let (later, earlier) = (self.contact.later, self.contact.earlier);
            if earlier >= later {
                (self.contact.later, self.contact.earlier) = (later + 1, 0);
                continue;
            }
            self.contact.earlier += 1;
            let (a, b) = (&self.submaps.done[later], &self.submaps.done[earlier]);
            if a.robot != b.robot && self.parts.may_meet(a.anchor, b.anchor) {
                budget -= 1;
                let joined_now = self.search_pair(later, earlier, &p);
                joined += joined_now;
            }
        }
        joined
    }

    /// Each node of one submap in the other's grid, both ways, until two parts join;
    /// returns how many parts it joined.
    fn search_pair(&mut self, later: usize, earlier: usize, p: &FirstContactParams) -> usize {
        for (grid, queries) in [(earlier, later), (later, earlier)] {
            let nodes: Vec<usize> = self.submaps.done[queries]
                .nodes
                .iter()
                .map(|n| n.0)
                .collect();
            for node in nodes {
                self.stats.contact_searches += 1;
                let Some(edge) = self.contact_in_submap(grid, node, p) else {
                    continue;
                };
                let joined = self.confirm_contact(edge, p);
                if joined > 0 {
                    return joined;
                }
            }
        }
        0
    }

    /// Keeps `edge` as a hypothesis; then, while two hypotheses place two parts the same
    /// way, joins those parts with both (a join can make older hypotheses agree: they are
    /// taken at today's estimates). Returns how many parts it joined.
    fn confirm_contact(&mut self, edge: RelativeEdge, p: &FirstContactParams) -> usize {
        let hypotheses = &mut self.contact.hypotheses;
        if hypotheses.len() == MAX_HYPOTHESES {
            hypotheses.remove(0);
        }
        hypotheses.push(Hypothesis { edge });
        let mut joined = 0;
        self.sync_parts();
        while let Some((i, j)) = self.agreeing_hypotheses(p) {
            let hypotheses = &mut self.contact.hypotheses;
            let second = hypotheses.remove(j).edge;
            let first = hypotheses.remove(i).edge;
            self.join_parts(second.from, second.to, &second.measurement);
            self.graph.edges.push(first);
            self.graph.edges.push(second);
            self.stats.loop_closures += 2;
            self.stats.inter_robot_closures += 2;
            self.stats.first_contacts += 1;
            joined += 1;
            // Hypotheses within one part now say nothing the searches will not find.
            self.sync_parts();
            let parts = &self.parts;
            self.contact
                .hypotheses
                .retain(|h| !parts.same_part(h.edge.from, h.edge.to));
        }
        joined
    }

    /// Two hypotheses (`i < j`) that place the same two parts the same way, at today's
    /// estimates, from four distinct nodes.
    fn agreeing_hypotheses(&self, p: &FirstContactParams) -> Option<(usize, usize)> {
        let parts = &self.parts;
        let (poses, path) = (&self.graph.poses, &self.node_path_m);
        // Moves the part of `to` onto the part of `from`.
        let motion = |e: &RelativeEdge| {
            poses[e.from]
                .compose(&e.measurement)
                .compose(&poses[e.to].inverse())
        };
        let agree = |a: &RelativeEdge, b: &RelativeEdge| {
            let ends = |e: &RelativeEdge| (parts.part(e.from), parts.part(e.to));
            // The same two ends, or swapped; and how far apart (path) the two matches'
            // nodes lie on each part, over which the estimates drift apart.
            let (d, apart_m) = if ends(a) == ends(b) {
                let apart = (path[a.from] - path[b.from]).abs() + (path[a.to] - path[b.to]).abs();
                (motion(a).between(&motion(b)), apart)
            } else if ends(a) == (ends(b).1, ends(b).0) {
                let apart = (path[a.from] - path[b.to]).abs() + (path[a.to] - path[b.from]).abs();
                (motion(a).inverse().between(&motion(b)), apart)
            } else {
                return false;
            };
            let nodes = [a.from, a.to];
            !nodes.contains(&b.from)
                && !nodes.contains(&b.to)
                && d.x.hypot(d.y) <= p.agree_m + p.agree_drift * apart_m
                && wrap_angle(d.theta).abs() <= p.agree_rad
        };
        let h = &self.contact.hypotheses;
        (0..h.len()).find_map(|j| {
            (0..j)
                .find(|&i| agree(&h[i].edge, &h[j].edge))
                .map(|i| (i, j))
        })
    }

    /// `node`'s scan searched in the whole of submap `k`, every heading; the inter-robot
    /// closure, refined by IDC, if it holds.
    fn contact_in_submap(
        &self,
        k: usize,
        node: usize,
        p: &FirstContactParams,
    ) -> Option<RelativeEdge> {
        let submap = &self.submaps.done[k];
        let (centre, reach) = submap.centre_and_reach();
        let window = SearchWindow {
            linear_m: reach + p.margin_m,
            angular_rad: std::f64::consts::PI,
        };
        let initial = Pose2::new(centre[0], centre[1], 0.0);
        let found = self.unambiguous_match(k, node, initial, &window, p.min_score)?;
        let refined = self.refine_in_submap(k, node, &found.pose, p.gated);
        let (near, m) = refined?;
        Some(RelativeEdge {
            from: near,
            to: node,
            measurement: m.pose,
            information: self.match_information(&m.covariance),
            kind: EdgeKind::InterRobot,
            robust: self.params.loop_robust,
        })
    }
}
