//! Wrong sequential matches on purpose, to see the mapper find them: a node's match with its
//! robot's last node moved off by a little, as a match that slid along a corridor or turned
//! into a wrong minimum would be. It is evaluated and gated at that pose as the matcher's own
//! result is, then checked as any match before it becomes an edge.

use super::Mapper2d;
use super::wrong_closures::offset;
use crate::network::{EdgeKind, PoseGraph};
use crate::splitmix::SplitMix;

/// How far a wrong match is off (m, rad): uniform in these ranges, random direction and sign.
const OFF_M: (f64, f64) = (0.3, 1.0);
const OFF_RAD: (f64, f64) = (2f64.to_radians(), 10f64.to_radians());

/// Seeded generator of wrong sequential matches.
#[derive(Clone, Debug)]
pub struct WrongMatches {
    fraction: f64,
    draw: SplitMix,
    /// Wrong matches owed (a fraction of the nodes made).
    owed: f64,
    nodes_seen: usize,
}

impl WrongMatches {
    /// `fraction` wrong matches per node of the mapper, drawn from `seed`.
    pub fn new(fraction: f64, seed: u64) -> WrongMatches {
        WrongMatches {
            fraction,
            draw: SplitMix::new(seed),
            owed: 0.0,
            nodes_seen: 0,
        }
    }

    /// Wrong matches `mapper` made so far (each put on a node's match, before its checks).
    pub fn injected(&self, mapper: &Mapper2d) -> usize {
        mapper.wrong_matches_made.len()
    }

    /// How many of them are edges of `mapper`'s graph (passed the mapper's checks).
    pub fn accepted(&self, mapper: &Mapper2d) -> usize {
        let graph: &PoseGraph = &mapper.graph;
        mapper
            .wrong_matches_made
            .iter()
            .filter(|&&(to, measurement)| {
                graph.edges.iter().any(|e| {
                    e.kind == EdgeKind::ScanMatch && e.to == to && e.measurement == measurement
                })
            })
            .count()
    }

    /// Call after each scan: for every node made since the last call, `fraction` of a wrong
    /// match, put on the match of the next node that has one.
    pub fn inject(&mut self, mapper: &mut Mapper2d) {
        let nodes = mapper.graph.poses.len();
        self.owed += self.fraction * (nodes - self.nodes_seen) as f64;
        self.nodes_seen = nodes;
        if self.owed >= 1.0 && mapper.next_match_error.is_none() {
            self.owed -= 1.0;
            mapper.next_match_error = Some(offset(&mut self.draw, OFF_M, OFF_RAD));
        }
    }
}
