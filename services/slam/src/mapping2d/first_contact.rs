//! First contact between robots that share no frame: a robot whose part of the network
//! floats alone (no GPS anchor, no closure with another robot) cannot be looked for near
//! its estimate, which is in a frame of its own. Its new nodes are searched instead in the
//! other robots' submaps, each whole and at every heading (the correlative matcher needs no
//! guess), a few submaps per node in turn. The query is not the node's scan alone but the
//! robot's recent nodes' scans in the node's frame: more of the place, fewer look-alikes.
//! A match that scores well and that IDC confirms is a hypothesis: where the robot's part
//! lies in the other part. Only when a second match, from another node, puts the part at
//! the same place (`agree_m`, `agree_rad`) do both become inter-robot closures, and the
//! robot's part is moved onto the map (`parts.rs`); from then on the ordinary searches
//! find its closures. A park's trees and a building's corridors repeat: one match alone,
//! searched over a whole map, is too often wrong.

use super::Mapper2d;
use crate::matching::Scan2;
use crate::matching::correlative::{SearchWindow, search};
use crate::network::{EdgeKind, RelativeEdge};
use crate::se2::{Pose2, wrap_angle};
use serde::{Deserialize, Serialize};

/// When and how hard a lone robot is looked for in the others' submaps.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FirstContactParams {
    /// Look for lone robots at all.
    pub enabled: bool,
    /// Search at a node when the robot has travelled this far since its last search (m).
    pub every_m: f64,
    /// Submaps searched per node; the next node takes the next ones.
    pub submaps_per_search: usize,
    /// Translations within the submap's extent plus this margin (m).
    pub margin_m: f64,
    /// The best pose must score at least this (a whole-map search scores many wrong poses).
    pub min_score: f64,
    /// The query: the robot's nodes over this much path up to the node (m).
    pub query_path_m: f64,
    /// Two matches confirm each other when they place the part within this (m)…
    pub agree_m: f64,
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
            every_m: 2.0,
            submaps_per_search: 4,
            margin_m: 5.0,
            min_score: 0.55,
            query_path_m: 12.0,
            agree_m: 0.5,
            agree_rad: 2f64.to_radians(),
            gated: false,
        }
    }
}

/// Per robot: its path at the last search, the next submap to search, and the matches
/// that wait for a second to confirm them.
#[derive(Clone, Debug, Default)]
pub(super) struct ContactSearch {
    last_search_m: Option<f64>,
    next_submap: usize,
    hypotheses: Vec<Hypothesis>,
}

/// A match of a lone robot's node in another part: the closure, and the motion that would
/// move the robot's part onto the other (its frame in the other's).
#[derive(Clone, Debug)]
struct Hypothesis {
    edge: RelativeEdge,
    motion: Pose2,
}

/// Hypotheses kept per robot (the oldest go).
const MAX_HYPOTHESES: usize = 16;

impl Mapper2d {
    /// Searches `node` in other robots' submaps when its robot floats alone; returns 1 when
    /// it found the robot (and moved its part onto the map), else 0.
    pub(super) fn seek_first_contact(&mut self, node: usize) -> usize {
        let p = self.params.first_contact.clone();
        let robot = self.node_robot[node].0;
        let others: Vec<usize> = (0..self.submaps.done.len())
            .filter(|&k| self.submaps.done[k].robot != robot)
            .collect();
        if !p.enabled || others.is_empty() {
            return 0;
        }
        if self.contact.len() <= robot {
            self.contact.resize(robot + 1, ContactSearch::default());
        }
        let path = self.node_path_m[node];
        if self.contact[robot]
            .last_search_m
            .is_some_and(|last| path - last < p.every_m)
            || !self.floats_alone(node)
        {
            return 0;
        }
        self.contact[robot].last_search_m = Some(path);
        let first = self.contact[robot].next_submap;
        self.contact[robot].next_submap = first + p.submaps_per_search;
        let query = self.contact_query(node, p.query_path_m);
        for i in 0..p.submaps_per_search.min(others.len()) {
            let k = others[(first + i) % others.len()];
            self.stats.contact_searches += 1;
            let Some(edge) = self.contact_in_submap(k, node, &query, &p) else {
                continue;
            };
            let poses = &self.graph.poses;
            let motion = poses[edge.from]
                .compose(&edge.measurement)
                .compose(&poses[node].inverse());
            let agreeing = self.contact[robot].hypotheses.iter().position(|h| {
                let d = h.motion.between(&motion);
                h.edge.from != edge.from
                    && h.edge.to != node
                    && d.x.hypot(d.y) <= p.agree_m
                    && wrap_angle(d.theta).abs() <= p.agree_rad
            });
            let Some(earlier) = agreeing else {
                let hypotheses = &mut self.contact[robot].hypotheses;
                if hypotheses.len() == MAX_HYPOTHESES {
                    hypotheses.remove(0);
                }
                hypotheses.push(Hypothesis { edge, motion });
                continue;
            };
            let confirmed = self.contact[robot].hypotheses.swap_remove(earlier).edge;
            self.contact[robot].hypotheses.clear();
            self.join_parts(edge.from, edge.to, &edge.measurement);
            self.graph.edges.push(confirmed);
            self.graph.edges.push(edge);
            self.stats.loop_closures += 2;
            self.stats.inter_robot_closures += 2;
            self.stats.first_contacts += 1;
            return 1;
        }
        0
    }

    /// The robot's nodes over `path_m` of path up to `node`, their returns in `node`'s frame
    /// at the current estimates, as one scan.
    fn contact_query(&self, node: usize, path_m: f64) -> Scan2 {
        let (robot, _) = self.node_robot[node];
        let here = self.graph.poses[node];
        let (mut bearings, mut ranges) = (Vec::new(), Vec::new());
        for n in (0..=node).rev() {
            if self.node_robot[n].0 != robot {
                continue;
            }
            if self.node_path_m[node] - self.node_path_m[n] > path_m {
                break;
            }
            let frame = here.between(&self.graph.poses[n]);
            for point in self.node_scans[n].points() {
                let [x, y] = frame.transform_point(*point);
                bearings.push(y.atan2(x) as f32);
                ranges.push(x.hypot(y) as f32);
            }
        }
        Scan2::from_polar(&bearings, &ranges, f32::MAX).expect("returns come in pairs")
    }

    /// Whether `node`'s part has no GPS anchor and no node of another robot.
    fn floats_alone(&self, node: usize) -> bool {
        let components = self.graph.components();
        let part = components[node];
        let robot = self.node_robot[node].0;
        self.graph
            .unanchored_part_roots()
            .binary_search(&part)
            .is_ok()
            && components
                .iter()
                .zip(&self.node_robot)
                .all(|(&c, &(r, _))| c != part || r == robot)
    }

    /// `node`'s scan searched in the whole of submap `k`, every heading; the inter-robot
    /// closure, refined by IDC, if it holds.
    fn contact_in_submap(
        &self,
        k: usize,
        node: usize,
        query: &Scan2,
        p: &FirstContactParams,
    ) -> Option<RelativeEdge> {
        let submap = &self.submaps.done[k];
        let (centre, reach) = submap.centre_and_reach();
        let window = SearchWindow {
            linear_m: reach + p.margin_m,
            angular_rad: std::f64::consts::PI,
        };
        let initial = Pose2::new(centre[0], centre[1], 0.0);
        let grid = &self.params.submaps.grid;
        let found = search(&submap.grids, query, initial, &window, p.min_score, grid);
        if std::env::var("FC_DEBUG").is_ok() {
            eprintln!(
                "node {node} r{} in submap {k} (r{}): {:?}",
                self.node_robot[node].0,
                submap.robot,
                found.map(|f| (f.score, f.nodes))
            );
        }
        let found = found?;
        let refined = self.refine_in_submap(k, node, &found.pose, p.gated);
        if std::env::var("FC_DEBUG").is_ok() {
            eprintln!(
                "   refined: {:?}",
                refined.as_ref().map(|(n, m)| (n, m.pose))
            );
        }
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
