//! Wrong sequential matches on purpose, to see the mapper find them: a node's match with its
//! robot's last node moved off by a little, as a match that slid along a corridor or turned
//! into a wrong minimum would be. It is evaluated and gated at that pose as the matcher's own
//! result is, then checked as any match before it becomes an edge.

use super::Mapper2d;
use super::wrong_closures::offset;
use crate::matching::{Match, Scan2, accept, evaluate};
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

impl Mapper2d {
    /// `m`, the match of `scan` with node `last`, made wrong when a wrong match is pending:
    /// its pose moved off, then evaluated and gated there against the last node's scan as
    /// the matcher's own result is (`None` when the gate rejects it).
    pub(super) fn made_wrong(&mut self, last: usize, scan: &Scan2, m: Match) -> Option<Match> {
        let Some(error) = self.next_match_error.take() else {
            return Some(m);
        };
        let pose = m.pose.compose(&error);
        self.wrong_matches_made.push((self.graph.poses.len(), pose));
        let moved = Match {
            iterations: m.iterations,
            converged: m.converged,
            ..evaluate(&self.node_scans[last], scan, &pose, &self.params.idc)
        };
        accept(&moved, &self.params.gate).then_some(moved)
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::scan_at;
    use super::*;
    use crate::Mapper2dParams;
    use crate::Pose2;

    /// A wrong match fails the gate where it puts the scan; with the sequential search the
    /// scan is found again and the edge is the true motion, without it the node falls back
    /// on odometry.
    #[test]
    fn a_wrong_match_is_gated_and_found_again_by_the_search() {
        let truth = [Pose2::new(-2.0, 0.0, 0.0), Pose2::new(-1.4, 0.0, 0.0)];
        for search in [true, false] {
            let mut mapper = Mapper2d::new(Mapper2dParams {
                sequential_search: search,
                ..Mapper2dParams::default()
            });
            mapper
                .add_scan(truth[0], scan_at(&truth[0], 0))
                .expect("add");
            mapper.next_match_error = Some(Pose2::new(0.5, 0.0, 5f64.to_radians()));
            mapper
                .add_scan(truth[1], scan_at(&truth[1], 1))
                .expect("add");
            let stats = mapper.stats();
            assert_eq!(mapper.wrong_matches_made.len(), 1);
            let edge = &mapper.graph.edges[0];
            if search {
                assert_eq!(
                    (stats.sequential_matches, stats.sequential_recovered),
                    (1, 1)
                );
                assert_eq!(edge.kind, EdgeKind::ScanMatch);
                let off = truth[0].between(&truth[1]).between(&edge.measurement);
                assert!(off.x.hypot(off.y) < 0.02, "{off:?}");
            } else {
                assert_eq!(
                    (stats.sequential_matches, stats.sequential_rejected),
                    (0, 1)
                );
                assert_eq!(edge.kind, EdgeKind::Odometry);
            }
        }
    }
}
