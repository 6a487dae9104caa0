//! The connected parts of a growing network, kept as edges and fixes are appended: what
//! [`PoseGraph::components`] and [`PoseGraph::unanchored_part_roots`] compute over the whole
//! network, at a cost per new edge instead of per question. The mapper asks about parts at
//! every node; over the whole network that cost grew with the map.
//!
//! A union-find by size; each set remembers its smallest node (the part's label, as
//! `components` gives it) and whether GPS fixes at two distinct nodes anchor it.

use crate::network::PoseGraph;
use serde::{Deserialize, Serialize};

/// Parts of a network that only grows (nodes, edges and fixes appended, never removed).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PartTracker {
    parent: Vec<usize>,
    /// By set root: nodes in the set.
    size: Vec<usize>,
    /// By set root: its smallest node, the part's label.
    label: Vec<usize>,
    /// By set root: the first node with a fix, if any.
    first_fixed: Vec<Option<usize>>,
    /// By set root: fixes at two distinct nodes.
    anchored: Vec<bool>,
    edges_seen: usize,
    fixes_seen: usize,
}

impl PartTracker {
    /// Takes in what was appended to `graph` since the last call.
    pub fn sync(&mut self, graph: &PoseGraph) {
        for node in self.parent.len()..graph.poses.len() {
            self.parent.push(node);
            self.size.push(1);
            self.label.push(node);
            self.first_fixed.push(None);
            self.anchored.push(false);
        }
        for e in &graph.edges[self.edges_seen..] {
            self.union(e.from, e.to);
        }
        self.edges_seen = graph.edges.len();
        for g in &graph.gps[self.fixes_seen..] {
            let root = self.root(g.node);
            match self.first_fixed[root] {
                None => self.first_fixed[root] = Some(g.node),
                Some(first) if first != g.node => self.anchored[root] = true,
                Some(_) => {}
            }
        }
        self.fixes_seen = graph.gps.len();
    }

    /// The part of `node`: its smallest node, as [`PoseGraph::components`] labels it.
    pub fn part(&self, node: usize) -> usize {
        self.label[self.root(node)]
    }

    /// Whether the part of `node` floats: no fixes at two distinct nodes anchor it.
    pub fn floats(&self, node: usize) -> bool {
        !self.anchored[self.root(node)]
    }

    /// Whether `a` and `b` are in one part.
    pub fn same_part(&self, a: usize, b: usize) -> bool {
        self.root(a) == self.root(b)
    }

    /// Whether the parts of `a` and `b` differ and one of them floats: the two have no
    /// frame in common.
    pub fn may_meet(&self, a: usize, b: usize) -> bool {
        !self.same_part(a, b) && (self.floats(a) || self.floats(b))
    }

    /// Nodes taken in so far.
    pub fn nodes(&self) -> usize {
        self.parent.len()
    }

    // Union by size keeps trees O(log n) deep, so lookups need no `&mut`.
    fn root(&self, mut node: usize) -> usize {
        while self.parent[node] != node {
            node = self.parent[node];
        }
        node
    }

    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.root(a), self.root(b));
        if ra == rb {
            return;
        }
        let (big, small) = if self.size[ra] >= self.size[rb] {
            (ra, rb)
        } else {
            (rb, ra)
        };
        self.parent[small] = big;
        self.size[big] += self.size[small];
        self.label[big] = self.label[big].min(self.label[small]);
        self.anchored[big] = self.anchored[big]
            || self.anchored[small]
            || matches!(
                (self.first_fixed[big], self.first_fixed[small]),
                (Some(x), Some(y)) if x != y
            );
        self.first_fixed[big] = self.first_fixed[big].or(self.first_fixed[small]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::{EdgeKind, GpsEdge, RelativeEdge};
    use crate::robust::Robust;
    use crate::se2::Pose2;
    use nalgebra::{Matrix2, Matrix3, Vector2};

    fn edge(from: usize, to: usize) -> RelativeEdge {
        RelativeEdge {
            from,
            to,
            measurement: Pose2::IDENTITY,
            information: Matrix3::identity(),
            kind: EdgeKind::LoopClosure,
            robust: Robust::None,
        }
    }

    fn fix(node: usize) -> GpsEdge {
        GpsEdge {
            node,
            position_m: Vector2::zeros(),
            information: Matrix2::identity(),
            lever_arm_m: Vector2::zeros(),
            robust: Robust::None,
        }
    }

    /// Random growth, checked after every step against the whole-network answers.
    #[test]
    fn agrees_with_the_whole_network_answers_as_the_network_grows() {
        let mut graph = PoseGraph::default();
        let mut parts = PartTracker::default();
        let mut state = 7u64;
        let mut next = |m: usize| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as usize % m
        };
        for step in 0..600 {
            match next(4) {
                0 | 1 => graph.poses.push(Pose2::IDENTITY),
                2 if graph.poses.len() > 1 => {
                    let (a, b) = (next(graph.poses.len()), next(graph.poses.len()));
                    if a != b {
                        graph.edges.push(edge(a, b));
                    }
                }
                _ if !graph.poses.is_empty() => graph.gps.push(fix(next(graph.poses.len()))),
                _ => continue,
            }
            parts.sync(&graph);
            let labels = graph.components();
            let floating = graph.unanchored_part_roots();
            for (node, &label) in labels.iter().enumerate() {
                assert_eq!(parts.part(node), label, "step {step}, node {node}");
                let floats = floating.binary_search(&label).is_ok();
                assert_eq!(parts.floats(node), floats, "step {step}, node {node}");
            }
        }
        assert!(graph.edges.len() > 50 && graph.gps.len() > 50);
    }
}
