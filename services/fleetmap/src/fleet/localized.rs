//! Nodes a robot sent while localizing on a map version: numbered and acked like mapped
//! nodes (its outbox drops them, its chain goes on without a gap), but not added to the
//! network. The store keeps each unbroken run of them as a span (robot, chain, first and
//! last node_seq), one row however long the run, so that a restart knows where each chain
//! stands; a replay takes the spans in their place among the mapped nodes.

use super::{FleetMap, IngestError, MAX_CHAINS_PER_ROBOT, MAX_ROBOTS_PER_FLEET, Sequence};
use std::collections::{HashMap, VecDeque};
use wire::Node;

/// An unbroken run of a robot chain's nodes that were localized, not mapped.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalizedSpan {
    /// The robot.
    pub robot: String,
    /// Its chain (`Node.chain_id`).
    pub chain_id: u64,
    /// The run's first node_seq.
    pub first_seq: u64,
    /// Its last node_seq so far.
    pub last_seq: u64,
    /// Passed over covered ground while mapping, with the chain's passes so far (its
    /// odometry goes on through them); `None`: localized on a version (the chain's next
    /// mapped node starts a new part of the network).
    pub passed: Option<slam::Passed>,
}

/// Where each chain stands in localized nodes: by robot, then by chain, so that a robot's
/// chains are found without making a key (each view of the map reads every chain's).
#[derive(Debug, Default)]
pub(super) struct LocalizedChains {
    chains: HashMap<String, HashMap<u64, Chain>>,
    /// Chains in all (bounded).
    count: usize,
}

#[derive(Debug)]
struct Chain {
    last_seq: u64,
    /// The first node_seq of the run that ends at `last_seq`, while no mapped node followed.
    open_from: Option<u64>,
    /// Whether the open run was passed (not localized).
    open_passed: bool,
    /// A run localized on a version since the chain's last mapped node.
    breaks: bool,
}

impl LocalizedChains {
    /// The highest node_seq localized of a chain.
    pub(super) fn last_seq(&self, robot: &str, chain_id: u64) -> Option<u64> {
        self.last_seqs_of(robot)(chain_id)
    }

    /// The highest node_seq localized of each chain of `robot`, by chain id.
    pub(super) fn last_seqs_of(&self, robot: &str) -> impl Fn(u64) -> Option<u64> + '_ {
        let chains = self.chains.get(robot);
        move |chain_id| Some(chains?.get(&chain_id)?.last_seq)
    }

    /// Whether a run localized on a version came since the chain's last mapped node: its
    /// odometry link would span a drive the network never saw.
    pub(super) fn breaks(&self, robot: &str, chain_id: u64) -> bool {
        let chain = self.chains.get(robot).and_then(|c| c.get(&chain_id));
        chain.is_some_and(|c| c.breaks)
    }

    /// A mapped node of the chain ends its run.
    pub(super) fn close_span(&mut self, robot: &str, chain_id: u64) {
        let chain = self
            .chains
            .get_mut(robot)
            .and_then(|c| c.get_mut(&chain_id));
        if let Some(c) = chain {
            c.open_from = None;
            c.breaks = false;
        }
    }

    /// Chains in all.
    fn len(&self) -> usize {
        self.count
    }

    /// Takes node `seq` of the chain: the run it extends or starts.
    fn take(
        &mut self,
        robot: &str,
        chain_id: u64,
        seq: u64,
        passed: Option<slam::Passed>,
    ) -> LocalizedSpan {
        let chain = self.chain(robot, chain_id, seq);
        let first_seq = match chain.open_from {
            Some(first) if chain.last_seq + 1 == seq && chain.open_passed == passed.is_some() => {
                first
            }
            _ => seq,
        };
        chain.last_seq = seq;
        chain.open_from = Some(first_seq);
        chain.open_passed = passed.is_some();
        chain.breaks |= passed.is_none();
        LocalizedSpan {
            robot: robot.to_owned(),
            chain_id,
            first_seq,
            last_seq: seq,
            passed,
        }
    }

    fn restore(&mut self, span: &LocalizedSpan) {
        let chain = self.chain(&span.robot, span.chain_id, span.last_seq);
        chain.last_seq = chain.last_seq.max(span.last_seq);
        chain.open_from = Some(span.first_seq);
        chain.open_passed = span.passed.is_some();
        chain.breaks |= span.passed.is_none();
    }

    fn chain(&mut self, robot: &str, chain_id: u64, seq: u64) -> &mut Chain {
        if !self.chains.contains_key(robot) {
            self.chains.insert(robot.to_owned(), HashMap::new());
        }
        let count = &mut self.count;
        let chains = self.chains.get_mut(robot).expect("inserted above");
        chains.entry(chain_id).or_insert_with(|| {
            *count += 1;
            Chain {
                last_seq: seq,
                open_from: None,
                open_passed: false,
                breaks: false,
            }
        })
    }
}

impl FleetMap {
    /// Takes `node` (the next of its chain) as localized on a version, or `passed` over
    /// covered ground: numbered and acked, not mapped. The span it starts or extends is what
    /// the store keeps of it.
    pub fn take_localized(
        &mut self,
        node: &Node,
        passed: bool,
    ) -> Result<LocalizedSpan, IngestError> {
        if self.sequence(node) != Sequence::Next {
            return Err(IngestError::Sequence {
                robot: node.robot.clone(),
                node_seq: node.node_seq,
                problem: "not the next node of its chain".into(),
            });
        }
        let bound = MAX_ROBOTS_PER_FLEET * MAX_CHAINS_PER_ROBOT;
        let known = self
            .localized
            .last_seq(&node.robot, node.chain_id)
            .is_some();
        if !known && self.localized.len() >= bound {
            return Err(IngestError::Refused {
                robot: node.robot.clone(),
                node_seq: node.node_seq,
                source: wire::WireError::Implausible {
                    field: "localized chains",
                    index: None,
                    value: (bound + 1) as f64,
                    limit: bound as f64,
                    reason: "too_many_chains",
                },
            });
        }
        // A pass is counted in its chain's path (the next mapped node's loop closures) with
        // where it was on the map (the next pass's prediction), and its GPS fixes go to the
        // node it passed.
        let passed = passed
            .then(|| {
                let (pose, unlocated_m) = self.take_pass_evidence(node).unzip();
                let network_chain = self.network_chain_of(&node.robot, node.chain_id)?;
                let odometry =
                    slam::Pose2::from_isometry3(&node.odometry.pose).compose(&node.scan_origin);
                Some(self.mapper.note_pass(
                    network_chain,
                    odometry,
                    pose,
                    unlocated_m.unwrap_or(0.0),
                ))
            })
            .flatten();
        Ok(self
            .localized
            .take(&node.robot, node.chain_id, node.node_seq, passed))
    }

    /// A stored span taken again (a replay): a passed run's chain goes on from its last
    /// pass, as it would have without the restart.
    pub fn restore_span(&mut self, span: &LocalizedSpan) {
        self.localized.restore(span);
        if let Some(passed) = span.passed
            && let Some(network_chain) = self.network_chain_of(&span.robot, span.chain_id)
        {
            self.mapper.restore_passed(network_chain, passed);
            self.restore_cover(span, &passed);
        }
    }
}

/// A fleet's stored spans, handed to the map in their place among the mapped nodes of a
/// replay: a span goes in before the first mapped node of its chain that comes after it.
pub struct SpanReplay {
    by_chain: HashMap<(String, u64), VecDeque<LocalizedSpan>>,
}

impl SpanReplay {
    /// The spans, in any order.
    pub fn new(mut spans: Vec<LocalizedSpan>) -> SpanReplay {
        spans.sort_by_key(|s| s.first_seq);
        let mut by_chain: HashMap<(String, u64), VecDeque<LocalizedSpan>> = HashMap::new();
        for span in spans {
            by_chain
                .entry((span.robot.clone(), span.chain_id))
                .or_default()
                .push_back(span);
        }
        SpanReplay { by_chain }
    }

    /// Takes the spans of `node`'s chain that came before it.
    pub fn before(&mut self, map: &mut FleetMap, node: &Node) {
        let Some(spans) = self.by_chain.get_mut(&(node.robot.clone(), node.chain_id)) else {
            return;
        };
        while let Some(span) = spans.front().filter(|s| s.last_seq < node.node_seq) {
            map.restore_span(span);
            spans.pop_front();
        }
    }

    /// Takes the spans after every mapped node.
    pub fn rest(self, map: &mut FleetMap) {
        for span in self.by_chain.into_values().flatten() {
            map.restore_span(&span);
        }
    }
}
