//! First contact between parts of the network that share no frame: a robot that floats
//! alone (no GPS anchor, no closure with another robot) cannot be looked for near its
//! estimate, which is in a frame of its own. Instead, every pair of submaps of two robots
//! in different parts (one of them floating) is searched when the later of the two is
//! finished, and again once both robots have driven the check's stretch beyond it; both
//! ways: one submap's returns in the other's grid, whole and at every heading (the
//! correlative matcher needs no guess). Pairs, not a robot's nodes against whatever
//! submaps exist at the time: two robots that pass the same place minutes apart, in either
//! order, are compared.
//!
//! Outdoors a place holds few landmarks, and the park's lamp posts stand in rows: a submap's
//! best pose is often wrong, and its score does not tell (wrong poses of the park scored up
//! to 0.86, true ones 0.20–0.69). What tells is the robots' longer stretches of path around the
//! match ([`super::contact_check`]): placed by the match, each robot's returns near the other's
//! path must fall on the other's returns. Even then a match is only a hypothesis (where one
//! part lies in the other) until a second, from another pair of submaps, places the two parts
//! the same way (`agree_m` plus `agree_drift` of the path between them, `agree_rad`). Then
//! both become inter-robot closures and one part is moved onto the other ([`super::parts`]); from
//! then on the ordinary searches find its closures.

use super::Mapper2d;
use super::contact_check::ContactCheckParams;
use crate::matching::correlative::{CorrelativeParams, search, thin_points};
use crate::network::{EdgeKind, RelativeEdge};
use crate::se2::wrap_angle;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// How parts that share no frame are searched for one another.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FirstContactParams {
    /// Search at all.
    pub enabled: bool,
    /// Pairs of submaps searched per new node at most; the rest wait for the next nodes.
    pub pairs_per_node: usize,
    /// Translations within the submap's extent plus this margin (m).
    pub margin_m: f64,
    /// The query keeps one return per square of this side (m): two cells of the submap
    /// grid (`SubmapSearchParams::grid`, 0.1 m), which a match's error stays within.
    pub query_spacing_m: f64,
    /// The query keeps the returns within this range of its middle node (m): the grid's own
    /// range. Outdoors a submap holds a few dozen landmark returns; 10 m (the global
    /// search's) left too few to tell places apart.
    pub query_range_m: f64,
    /// The best pose must score at least this (mean cell value under the returns). Only a
    /// floor for the search: between robots, true matches scored 0.20–0.69 in the park, as
    /// low as many wrong ones; the stretches decide.
    pub min_score: f64,
    /// How the two robots' stretches of path around a match must agree.
    pub check: ContactCheckParams,
    /// Two matches confirm each other when they place the parts within this (m)…
    pub agree_m: f64,
    /// …plus this share of the path (m) between the two matches' nodes on each part, over
    /// which the estimates drift apart…
    pub agree_drift: f64,
    /// …and this (rad) of each other.
    pub agree_rad: f64,
}

impl Default for FirstContactParams {
    fn default() -> Self {
        FirstContactParams {
            enabled: true,
            pairs_per_node: 32,
            margin_m: 5.0,
            query_spacing_m: 0.2,
            query_range_m: 20.0,
            min_score: 0.2,
            check: ContactCheckParams::default(),
            agree_m: 0.5,
            agree_drift: 0.01,
            agree_rad: 2f64.to_radians(),
        }
    }
}

/// The submaps whose pairs are searched, and the matches that wait for a second.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct ContactSearch {
    /// Pairs of finished submaps, searched as soon as the later is finished.
    finished: PairCursor,
    /// Finished submaps seen so far.
    seen: usize,
    /// Finished submaps whose robot has not yet driven the check's stretch beyond them.
    waiting: Vec<usize>,
    /// Submaps whose stretch is complete, in that order…
    ripe: Vec<usize>,
    /// …and their pairs, searched a second time then: at the first search the check saw
    /// only the stretch driven so far.
    second_look: PairCursor,
    /// Each robot's path (m) at its newest node.
    robot_path_m: Vec<f64>,
    hypotheses: Vec<Hypothesis>,
    /// By submap: its part was anchored when last asked. An anchor is never lost (parts only
    /// merge), so a pair of anchored submaps is passed over without asking the parts: each
    /// new submap's walk over every earlier one costs a look-up per pair, not two walks up
    /// the part tree. Made again on use: not saved.
    #[serde(skip)]
    anchored: Vec<bool>,
}

/// Walks the pairs of a growing list once each: entry `later` with every `earlier` before
/// it, then the next.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct PairCursor {
    later: usize,
    earlier: usize,
}

impl PairCursor {
    /// The next pair among the first `len` entries (later, earlier), if any is left.
    fn next(&mut self, len: usize) -> Option<(usize, usize)> {
        while self.later < len {
            if self.earlier < self.later {
                self.earlier += 1;
                return Some((self.later, self.earlier - 1));
            }
            (self.later, self.earlier) = (self.later + 1, 0);
        }
        None
    }
}

/// A match between parts: the closure it would be.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Hypothesis {
    edge: RelativeEdge,
    /// The two submaps searched: a second hypothesis must come from two others (the same
    /// pair searched the other way sees the same places, and is no second opinion).
    #[serde(default)]
    submaps: [usize; 2],
}

/// Hypotheses kept (the oldest go).
const MAX_HYPOTHESES: usize = 64;

impl Mapper2d {
    /// Searches the next pairs of submaps, at most `pairs_per_node` of them (the rest wait
    /// for the next node: a lone robot in a big map has many); returns how many parts it
    /// joined. A pair is searched when the later submap is finished, and again once both
    /// robots have driven the check's stretch beyond it, so that the check sees the whole
    /// stretch on both sides whatever order the robots' nodes arrive in.
    pub(super) fn seek_first_contact(&mut self, node: usize) -> usize {
        let p = self.params.first_contact.clone();
        if !p.enabled {
            return 0;
        }
        self.ripen_submaps(node, p.check.stretch_m);
        let (mut joined, mut budget) = (0, p.pairs_per_node);
        self.sync_parts();
        while budget > 0 {
            let contact = &mut self.contact;
            let pair = match contact.finished.next(self.submaps.done.len()) {
                Some(pair) => pair,
                None => match contact.second_look.next(contact.ripe.len()) {
                    Some((later, earlier)) => (contact.ripe[later], contact.ripe[earlier]),
                    None => break,
                },
            };
            let robots_differ = self.submaps.done[pair.0].robot != self.submaps.done[pair.1].robot;
            if robots_differ && self.submaps_may_meet(pair.0, pair.1) {
                budget -= 1;
                joined += self.search_pair(pair.0, pair.1, &p);
            }
        }
        joined
    }

    /// Whether the parts of submaps `a` and `b` may meet ([`crate::PartTracker::may_meet`]
    /// of their anchors).
    fn submaps_may_meet(&mut self, a: usize, b: usize) -> bool {
        let anchored = &mut self.contact.anchored;
        if anchored.len() < self.submaps.done.len() {
            anchored.resize(self.submaps.done.len(), false);
        }
        if anchored[a] && anchored[b] {
            return false;
        }
        let (x, y) = (self.submaps.done[a].anchor, self.submaps.done[b].anchor);
        anchored[a] = !self.parts.floats(x);
        anchored[b] = !self.parts.floats(y);
        self.parts.may_meet(x, y)
    }

    /// Moves the finished submaps whose robot has driven `stretch_m` beyond them (at
    /// `node`, the newest) to the ripe ones.
    fn ripen_submaps(&mut self, node: usize, stretch_m: f64) {
        let robot = self.node_robot[node].0;
        let contact = &mut self.contact;
        if contact.robot_path_m.len() <= robot {
            contact.robot_path_m.resize(robot + 1, 0.0);
        }
        contact.robot_path_m[robot] = self.node_path_m[node];
        contact
            .waiting
            .extend(contact.seen..self.submaps.done.len());
        contact.seen = self.submaps.done.len();
        let done = &self.submaps.done;
        let (ripe, waiting): (Vec<usize>, Vec<usize>) = contact.waiting.iter().partition(|&&k| {
            let driven = contact.robot_path_m.get(done[k].robot).copied();
            driven.is_some_and(|m| m >= done[k].last_path_m + stretch_m)
        });
        contact.ripe.extend(ripe);
        contact.waiting = waiting;
    }

    /// Each submap's returns in the other's grid, until two parts join; returns how many
    /// parts it joined.
    fn search_pair(&mut self, later: usize, earlier: usize, p: &FirstContactParams) -> usize {
        for (target, query) in [(earlier, later), (later, earlier)] {
            self.stats.contact_searches += 1;
            let Some(edge) = self.contact_between(target, query, p) else {
                continue;
            };
            let joined = self.confirm_contact(edge, [later, earlier], p);
            if joined > 0 {
                return joined;
            }
        }
        0
    }

    /// Keeps `edge` as a hypothesis; then, while two hypotheses place two parts the same
    /// way, joins those parts with both (a join can make older hypotheses agree: they are
    /// taken at today's estimates). Returns how many parts it joined.
    fn confirm_contact(
        &mut self,
        edge: RelativeEdge,
        submaps: [usize; 2],
        p: &FirstContactParams,
    ) -> usize {
        let hypotheses = &mut self.contact.hypotheses;
        if hypotheses.len() == MAX_HYPOTHESES {
            hypotheses.remove(0);
        }
        hypotheses.push(Hypothesis { edge, submaps });
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
    /// estimates, from four distinct nodes and four distinct submaps.
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
                .find(|&i| {
                    let shared = h[i].submaps.iter().any(|k| h[j].submaps.contains(k));
                    !shared && agree(&h[i].edge, &h[j].edge)
                })
                .map(|i| (i, j))
        })
    }

    /// Submap `query`'s returns searched in the whole of submap `target`, every heading;
    /// the inter-robot closure (refined by IDC where IDC holds) if the two robots'
    /// stretches of path around the match agree.
    fn contact_between(
        &self,
        target: usize,
        query: usize,
        p: &FirstContactParams,
    ) -> Option<RelativeEdge> {
        let returns = self.submap_returns(query, p.query_range_m);
        let returns = thin_points(&returns, p.query_spacing_m, p.query_range_m);
        let submap = &self.submaps.done[target];
        let (initial, window) = submap.whole_window(p.margin_m);
        let grids = self.pooled_grids(target);
        let grid = &self.params.submaps.grid;
        let found = search(&grids, &returns, initial, &window, p.min_score, grid)?;
        let anchor = submap.anchor;
        let nodes = &self.submaps.done[query].nodes;
        let node = nodes[nodes.len() / 2].0;
        if !self.stretches_agree(anchor, node, &found.pose, &p.check) {
            return None;
        }
        // Two scans of a place seen from far apart often fail IDC or its gate: the
        // correlative pose stands then.
        let (from, measurement, information) =
            match self.refine_in_submap(target, node, &found.pose, false) {
                Some((near, m)) => (near, m.pose, self.match_information(&m.covariance)),
                None => (anchor, found.pose, correlative_information(grid)),
            };
        Some(RelativeEdge {
            from,
            to: node,
            measurement,
            information,
            kind: EdgeKind::InterRobot,
            robust: self.params.loop_robust,
        })
    }
}

/// A correlative pose's information: a cell's error in translation; in rotation the
/// angular step, which moves a return at the grid's range by one cell.
fn correlative_information(grid: &CorrelativeParams) -> Matrix3<f64> {
    let sigma_m = grid.resolution_m;
    let sigma_rad = grid.resolution_m / grid.max_range_m;
    Matrix3::from_diagonal(&Vector3::new(
        sigma_m.powi(-2),
        sigma_m.powi(-2),
        sigma_rad.powi(-2),
    ))
}

#[cfg(test)]
mod tests {
    use super::PairCursor;

    /// Every pair of a list that grows between calls comes once, the later entry first.
    #[test]
    fn a_pair_cursor_walks_each_pair_of_a_growing_list_once() {
        let mut cursor = PairCursor::default();
        let mut pairs = Vec::new();
        for len in [0, 1, 3, 3, 4] {
            while let Some(pair) = cursor.next(len) {
                pairs.push(pair);
            }
        }
        assert_eq!(pairs, [(1, 0), (2, 0), (2, 1), (3, 0), (3, 1), (3, 2)]);
    }
}
