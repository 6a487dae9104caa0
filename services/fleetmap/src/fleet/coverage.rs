//! Bounded growth (docs/services.md, "Bounded growth"): a robot mapping where the map already
//! has nodes passes over them. Its node is predicted from the chain's last node (added or
//! passed) by odometry; when the place is covered (`slam::CoverageParams`) and the chain's
//! last node was covered too, the node is located by IDC against the nearest covering node
//! and taken like a localized node (numbered, acked, a span in the store), not added. The
//! first covered node of a stretch is added: its loop closures tie the chain to the map.

use super::{FleetMap, Sequence};
use slam::Pose2;
use wire::Node;

/// Where a chain's last node stood, for the next one's prediction.
#[derive(Clone, Debug)]
pub(super) struct Cover {
    /// Its node_seq.
    seq: u64,
    /// Its scan frame in the odometry frame.
    odometry: Pose2,
    /// Its map pose when passed; `None` when added (the node's estimate, as solved since).
    located: Option<Pose2>,
    /// Whether its place was covered.
    covered: bool,
    /// Path driven since the chain's last node located or added (m).
    unlocated_m: f64,
    /// When located: the node it was located against, and its GPS fixes (they become that
    /// node's once the pass is taken, [`FleetMap::take_pass_evidence`]).
    evidence: Option<(usize, Vec<slam::GpsObservation>)>,
}

impl FleetMap {
    /// The map pose of `node` when it passes over covered ground (it is then taken with
    /// [`FleetMap::take_localized`], not [`FleetMap::ingest`]); `None` when it is to be added.
    pub fn pass(&mut self, node: &Node) -> Option<Pose2> {
        if !self.mapper.params().coverage.enabled || self.sequence(node) != Sequence::Next {
            return None;
        }
        let r = *self.by_id.get(&node.robot)?;
        let chain = self.robots[r].chain(node.chain_id)?;
        let last_node = chain.last_node;
        let key = (node.robot.clone(), node.chain_id);
        let odometry = Pose2::from_isometry3(&node.odometry.pose).compose(&node.scan_origin);
        // From the chain's last node, added or passed (its passes stored with their map pose
        // are restored, [`FleetMap::restore_span`]); after a restart whose chain's last node
        // was added, from that node, and its first covered node is added.
        let last = self.covers.get(&key).filter(|c| c.seq + 1 == node.node_seq);
        let (from_odometry, from_map, was_covered, unlocated_m) = match last {
            Some(c) => (
                c.odometry,
                c.located.unwrap_or(self.poses()[last_node]),
                c.covered,
                c.unlocated_m,
            ),
            None => (
                self.nodes[last_node].odometry,
                self.poses()[last_node],
                false,
                0.0,
            ),
        };
        let step = from_odometry.between(&odometry);
        let predicted = from_map.compose(&step);
        let network_chain = chain.network_chain;
        let path_m = self.mapper.path_at(network_chain, &odometry);
        let covering = self.mapper.covering(&predicted, network_chain, path_m);
        let p = self.mapper.params().coverage.clone();
        let covered = covering.len() >= p.max_nodes;
        let passes = covered && was_covered;
        let located = passes
            .then(|| {
                let scan = node.matching_scan(self.max_range_m);
                self.mapper.locate_against(covering[0], &predicted, &scan)
            })
            .flatten();
        let evidence = located.map(|_| (covering[0], self.gps_of(node)));
        // A pass not located goes on by the odometry of the last one located, for a while.
        let unlocated_m = match located {
            Some(_) => 0.0,
            None => unlocated_m + step.x.hypot(step.y),
        };
        let passed = located.or((passes && unlocated_m <= p.max_unlocated_m).then_some(predicted));
        self.covers.insert(
            key,
            Cover {
                seq: node.node_seq,
                odometry,
                located: passed,
                covered,
                unlocated_m: if passed.is_some() { unlocated_m } else { 0.0 },
                evidence,
            },
        );
        passed
    }

    /// A pass of `node`'s chain taken: the GPS fixes it brought, located against a covering
    /// node, become that node's (waiting for the next solve applied). Where the pass was on
    /// the map, and the path since one was located; `None` when [`FleetMap::pass`] did not
    /// pass it.
    pub(super) fn take_pass_evidence(&mut self, node: &Node) -> Option<(Pose2, f64)> {
        let key = (node.robot.clone(), node.chain_id);
        let cover = self
            .covers
            .get_mut(&key)
            .filter(|c| c.seq == node.node_seq)?;
        let located = cover.located?;
        let unlocated_m = cover.unlocated_m;
        if let Some((near, gps)) = cover.evidence.take() {
            self.mapper.add_pass_fixes(near, &located, &gps);
        }
        Some((located, unlocated_m))
    }

    /// A stored run of passes taken again (a restart): the chain's next node is predicted
    /// from its last pass, as without the restart. Passes stored without their map pose
    /// leave it to the chain's last added node.
    pub(super) fn restore_cover(&mut self, span: &super::LocalizedSpan, passed: &slam::Passed) {
        let (Some(odometry), Some(pose)) = (passed.odometry, passed.pose) else {
            return;
        };
        self.covers.insert(
            (span.robot.clone(), span.chain_id),
            Cover {
                seq: span.last_seq,
                odometry,
                located: Some(pose),
                covered: true,
                unlocated_m: passed.unlocated_m,
                evidence: None,
            },
        );
    }
}
