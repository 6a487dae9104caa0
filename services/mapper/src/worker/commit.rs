//! The worker's store step and its failure path: a batch is committed before it is acked; a
//! batch whose commit failed (a full disk) is kept, as the maps hold it already, and committed
//! again every second until that succeeds. No node is taken meanwhile.

use super::{Batch, Worker, fleets_of};
use crate::store::{FleetBatch, SolvePoint, StoreError};
use std::time::{Duration, Instant};

/// How often a commit that failed is tried again.
const STORE_RETRY: Duration = Duration::from_secs(1);

/// What the maps hold and the store does not: a batch or solve points whose commit failed.
/// The maps cannot give nodes back, so it is committed again until that succeeds; its nodes
/// are acked and shown only then.
#[derive(Default)]
pub(super) struct Unstored {
    /// Nodes mapped, and robots to re-ack.
    pub(super) batch: Batch,
    /// Solves applied whose point is not stored, with the passes' GPS fixes they moved into
    /// the network.
    pub(super) solves: Vec<(String, SolvePoint, Vec<slam::GpsEdge>)>,
}

impl Worker {
    /// Commits what the maps took, then acks it, shows it and runs the solves that are due.
    /// On a failure it is kept for [`Self::retry_store`]: nothing of it is acked or shown.
    pub(super) fn store_and_ack(&mut self, mut work: Unstored, started: Instant) {
        let fenced = match self.commit(&work) {
            Ok(fenced) => fenced,
            Err(_) => {
                self.store_failed(work);
                return;
            }
        };
        self.drop_fenced(&fenced, &mut work);
        self.ack(&work.batch);
        self.publish(&work.batch.accepted, started);
        self.publish_localized(&work.batch.localized);
        for (fleet, point, _) in &work.solves {
            self.publish_solve(fleet, started, point);
        }
        self.due_solves();
    }

    /// Commits what a failed commit left, once [`STORE_RETRY`] has passed since.
    pub(super) fn retry_store(&mut self) {
        if Instant::now() < self.retry_at {
            return;
        }
        if let Some(work) = self.unstored.take() {
            self.store_and_ack(work, Instant::now());
        }
    }

    /// Commits the nodes' rows, their clouds, the new edges of their fleets and the solve
    /// points in one transaction; in cluster mode each site's part is first appended to its
    /// log. The sites whose append was fenced (not committed: the caller drops them).
    pub(super) fn commit(&mut self, work: &Unstored) -> Result<Vec<String>, StoreError> {
        let accepted = &work.batch.accepted;
        let localized = &work.batch.localized;
        let mut touched = fleets_of(accepted);
        touched.extend(localized.iter().map(|l| l.fleet.as_str()));
        touched.sort_unstable();
        touched.dedup();
        if touched.is_empty() && work.solves.is_empty() {
            return Ok(Vec::new());
        }
        let mut batches: Vec<FleetBatch> = touched
            .iter()
            .map(|&fleet| {
                let stored = self.edges_stored.get(fleet).copied().unwrap_or(0);
                let of_fleet = || accepted.iter().filter(move |a| a.fleet == fleet);
                FleetBatch {
                    fleet,
                    solved: None,
                    pass_fixes: &[],
                    nodes: of_fleet()
                        .map(|a| (a.arrival, a.payload.as_slice()))
                        .collect(),
                    senders: of_fleet()
                        .map(|a| (a.robot.as_str(), a.chain_id, a.node_seq))
                        .collect(),
                    clouds: of_fleet()
                        .filter_map(|a| Some((a.node as u64, a.cloud.as_deref()?)))
                        .collect(),
                    first_edge: stored as u64,
                    edges: crate::store::encode_edges(&self.fleets[fleet].graph().edges[stored..]),
                    localized: localized
                        .iter()
                        .filter(|l| l.fleet == fleet)
                        .map(|l| l.span.clone())
                        .collect(),
                    log_sequence: None,
                }
            })
            .collect();
        batches.extend(work.solves.iter().map(|(fleet, point, fixes)| FleetBatch {
            fleet,
            solved: Some(*point),
            pass_fixes: fixes,
            ..Default::default()
        }));
        let fenced = match self.append_to_logs(&mut batches) {
            Ok(fenced) => fenced,
            Err(e) => {
                let result = Err(e);
                self.note_store(&result, accepted.len() + localized.len());
                return result.map(|()| Vec::new());
            }
        };
        let result = self.store.commit(&batches);
        if result.is_ok() {
            for b in &batches {
                *self.edges_stored.entry(b.fleet.to_owned()).or_default() += b.edges.len();
            }
            self.share_clouds(&batches);
        }
        drop(batches);
        self.note_store(&result, accepted.len() + localized.len());
        result.map(|()| fenced)
    }

    /// A commit's outcome as `/healthz` shows it; logged when it changes, not every retry.
    fn note_store(&self, result: &Result<(), StoreError>, nodes: usize) {
        let mut fault = self.shared.store_fault.write().expect("fault lock");
        match (result, fault.is_some()) {
            (Ok(()), false) => {}
            (Ok(()), true) => {
                tracing::info!(nodes, "the store commits again: resumed");
                *fault = None;
            }
            (Err(e), was_failing) => {
                if !was_failing {
                    tracing::error!("store commit failed; no acks until it succeeds: {e}");
                }
                *fault = Some(e.to_string());
            }
        }
    }

    /// Keeps what a failed commit held, to be committed again after [`STORE_RETRY`].
    pub(super) fn store_failed(&mut self, work: Unstored) {
        self.retry_at = Instant::now() + STORE_RETRY;
        let kept = self.unstored.get_or_insert_default();
        kept.batch.accepted.extend(work.batch.accepted);
        kept.batch.reacks.extend(work.batch.reacks);
        kept.batch.localized.extend(work.batch.localized);
        kept.solves.extend(work.solves);
    }
}
