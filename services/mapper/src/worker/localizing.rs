//! The worker's side of localizing robots: a node of a robot set to localize is taken in
//! its chain's sequence (a span in the store, no network node), found on the version's map,
//! and, once its batch is committed, acked with the others and answered on
//! `levelmap/{fleet}/robots/{robot}/localization`.

use super::{Batch, Worker};
use crate::localization::{FleetModes, NodeLocalization, Outcome, RobotMode};
use fleetmap::{IngestError, LocalizedSpan};
use slam::Pose2;
use slam::localize::{LocalizationMap, SearchKind, TrackStatus};
use std::collections::HashMap;
use std::sync::Arc;
use wire::{Localized, Node};

/// A node localized in this batch, not yet committed.
pub(super) struct LocalizedNode {
    pub(super) fleet: String,
    pub(super) robot: String,
    pub(super) chain_id: u64,
    /// Its run of localized nodes, as the store keeps it.
    pub(super) span: LocalizedSpan,
    /// The answer to its robot.
    pub(super) message: Localized,
    /// What the API lists of it.
    pub(super) entry: NodeLocalization,
}

impl LocalizedNode {
    fn new(
        input: &Node,
        span: LocalizedSpan,
        (message, entry): (Localized, NodeLocalization),
    ) -> Self {
        LocalizedNode {
            fleet: input.fleet.clone(),
            robot: input.robot.clone(),
            chain_id: input.chain_id,
            span,
            message,
            entry,
        }
    }
}

impl Worker {
    /// The version `robot` localizes on, if it does.
    pub(super) fn localizes(&self, fleet: &str, robot: &str) -> Option<u64> {
        match self.localizing.get(fleet)?.mode(robot) {
            RobotMode::Localize { version } => Some(version),
            RobotMode::Map => None,
        }
    }

    /// Takes `input` (the next node of its chain) as localized and finds it on `version`.
    pub(super) fn localize(&mut self, key: &str, input: &Node, version: u64, batch: &mut Batch) {
        let Some(span) = self.take_span(key, input, false) else {
            return;
        };
        let localizing = self
            .localizing
            .get_mut(&input.fleet)
            .expect("the robot localizes");
        let answers = localizing.localize(
            input,
            version,
            &self.config.localization.track,
            self.config.max_range_m,
            runtime::session::now_ns(),
        );
        batch
            .localized
            .push(LocalizedNode::new(input, span, answers));
    }

    /// Takes `input` as passed over covered ground, at `pose` on the live map (docs/services.md,
    /// "Bounded growth"): numbered and acked like a localized node, answered to its robot as
    /// one (map version 0: the live map).
    pub(super) fn take_passed(&mut self, key: &str, input: &Node, pose: Pose2, batch: &mut Batch) {
        let started = std::time::Instant::now();
        let Some(span) = self.take_span(key, input, true) else {
            return;
        };
        crate::views::Metrics::bump(&self.shared.metrics.nodes_passed);
        let outcome = Outcome {
            version: 0,
            status: TrackStatus::Localized,
            pose: Some(pose),
            found: None,
            search: Some(SearchKind::Window),
            reason: None,
        };
        let took_ms = started.elapsed().as_secs_f64() * 1e3;
        let answers = outcome.answers(input, took_ms, runtime::session::now_ns());
        batch
            .localized
            .push(LocalizedNode::new(input, span, answers));
    }

    /// The span `input` (the next node of its chain) extends, localized or `passed`; `None`
    /// (counted, logged) when its fleet's map refuses it.
    fn take_span(&mut self, key: &str, input: &Node, passed: bool) -> Option<LocalizedSpan> {
        let map = self
            .fleets
            .get_mut(&input.fleet)
            .expect("made by the caller");
        match map.take_localized(input, passed) {
            Ok(span) => Some(span),
            Err(IngestError::Refused { source, .. }) => {
                self.reject(source.reason(), key, &source);
                None
            }
            Err(e) => {
                self.reject("invalid_value", key, &e);
                None
            }
        }
    }

    /// A fleet's new modes.
    pub(super) fn set_modes(
        &mut self,
        fleet: &str,
        modes: FleetModes,
        maps: HashMap<u64, Arc<LocalizationMap>>,
    ) {
        tracing::info!(fleet, modes = ?modes, "robot modes set");
        self.localizing
            .entry(fleet.to_owned())
            .or_default()
            .set(modes, maps);
    }

    /// The committed localizations: to their robots, to the API's log and the event stream.
    pub(super) fn publish_localized(&self, nodes: &[LocalizedNode]) {
        let history = self.config.localization.history.get();
        for n in nodes {
            self.bus.localization(&self.shared.metrics, &n.message);
            if n.entry.version != 0 {
                crate::views::Metrics::bump(&self.shared.metrics.nodes_localized);
            }
            self.shared
                .localizations
                .push(&n.fleet, &n.robot, n.entry.clone(), history);
            self.shared.event(&serde_json::json!({
                "type": "localization",
                "fleet": n.fleet,
                "robot": n.robot,
                "node_seq": n.entry.node_seq,
                "version": n.entry.version,
                "status": n.entry.status,
                "pose": n.entry.pose,
            }));
        }
    }
}
