//! The worker's store step and its failure path: a batch is made durable through the
//! journal before it is acked. A batch whose commit failed (a full disk) is kept, as the maps
//! hold it already, and committed again every second until that succeeds; no node is taken
//! meanwhile. A site whose log alone did not take its part (cluster mode) is kept the same
//! way, and only its nodes wait: the other sites' parts are committed and acked.

use super::{Batch, Worker, fleets_of};
use crate::journal::SiteFault;
use crate::store::{FleetBatch, SolvePoint, StoreError};
use std::collections::BTreeSet;
use std::time::{Duration, Instant};

/// How often a commit that failed is tried again.
const STORE_RETRY: Duration = Duration::from_secs(1);

/// What the maps hold and the journal does not: a batch or solve points whose commit failed.
/// The maps cannot give nodes back, so it is committed again until that succeeds; its nodes
/// are acked and shown only then.
#[derive(Default)]
pub(super) struct Unstored {
    /// Nodes mapped, and robots to re-ack.
    pub(super) batch: Batch,
    /// Solves applied whose point is not stored, with the passes' GPS fixes they moved into
    /// the network.
    pub(super) solves: Vec<(String, SolvePoint, Vec<slam::GpsEdge>)>,
    /// The sites that wait for it: `None` when the store failed (every site waits).
    pub(super) sites: Option<BTreeSet<String>>,
}

impl Unstored {
    /// Whether `site`'s nodes wait for this to be committed.
    pub(super) fn holds(&self, site: &str) -> bool {
        self.sites.as_ref().is_none_or(|s| s.contains(site))
    }

    /// What of this is of `sites`, taken out.
    fn take_sites(&mut self, sites: &BTreeSet<String>) -> Unstored {
        let of = |fleet: &str| sites.contains(fleet);
        let batch = &mut self.batch;
        let taken = Batch {
            accepted: batch.accepted.extract_if(.., |a| of(&a.fleet)).collect(),
            reacks: batch.reacks.extract_if(.., |r| of(&r.fleet)).collect(),
            localized: batch.localized.extract_if(.., |l| of(&l.fleet)).collect(),
            ..Batch::default()
        };
        Unstored {
            batch: taken,
            solves: self
                .solves
                .extract_if(.., |(fleet, ..)| of(fleet))
                .collect(),
            sites: Some(sites.clone()),
        }
    }

    /// Whether nothing is kept: no node, re-ack or solve, and no site waits.
    pub(super) fn is_empty(&self) -> bool {
        self.sites.as_ref().is_some_and(|s| s.is_empty())
            && self.batch.accepted.is_empty()
            && self.batch.reacks.is_empty()
            && self.batch.localized.is_empty()
            && self.solves.is_empty()
    }
}

impl Worker {
    /// Commits what the maps took, then acks it, shows it and runs the solves that are due.
    /// On a failure it is kept for [`Self::retry_store`]: nothing of it is acked or shown.
    pub(super) fn store_and_ack(&mut self, mut work: Unstored, started: Instant) {
        let Ok(faults) = self.commit(&work) else {
            self.store_failed(work, None);
            return;
        };
        let mut waiting = BTreeSet::new();
        for (site, fault) in faults {
            match fault {
                SiteFault::Fenced(_) => {
                    work.solves.retain(|(fleet, ..)| *fleet != site);
                    self.drop_site(&site, "another host appended to its log", &mut work.batch);
                }
                SiteFault::Unavailable(why) => {
                    if !self.site_waits(&site) {
                        tracing::warn!(
                            site,
                            "the site's entries are not durable; its nodes wait: {why}"
                        );
                    }
                    waiting.insert(site);
                }
            }
        }
        if !waiting.is_empty() {
            let kept = work.take_sites(&waiting);
            self.store_failed(kept, Some(waiting));
        }
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

    /// Journals the nodes' rows, their clouds, the new edges of their fleets and the solve
    /// points (on a single machine, one transaction). The sites whose part was not made
    /// durable, with why; `Err` when the store failed and nothing was.
    pub(super) fn commit(
        &mut self,
        work: &Unstored,
    ) -> Result<Vec<(String, SiteFault)>, StoreError> {
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
        let result = self.journal.commit(&mut batches);
        if result.is_ok() {
            for b in &batches {
                *self.edges_stored.entry(b.fleet.to_owned()).or_default() += b.edges.len();
            }
        }
        drop(batches);
        self.note_store(
            result.as_ref().map(|_| ()),
            accepted.len() + localized.len(),
        );
        result
    }

    /// A commit's outcome as `/healthz` shows it; logged when it changes, not every retry.
    fn note_store(&self, result: Result<(), &StoreError>, nodes: usize) {
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

    /// Keeps what a failed commit held, to be committed again after [`STORE_RETRY`]; the
    /// sites that wait for it (`None`: the store failed, every site waits).
    pub(super) fn store_failed(&mut self, work: Unstored, sites: Option<BTreeSet<String>>) {
        self.retry_at = Instant::now() + STORE_RETRY;
        let kept = self.unstored.get_or_insert_with(|| Unstored {
            sites: Some(BTreeSet::new()),
            ..Unstored::default()
        });
        kept.sites = match (kept.sites.take(), sites) {
            (Some(mut waiting), Some(more)) => {
                waiting.extend(more);
                Some(waiting)
            }
            _ => None,
        };
        kept.batch.accepted.extend(work.batch.accepted);
        kept.batch.reacks.extend(work.batch.reacks);
        kept.batch.localized.extend(work.batch.localized);
        kept.solves.extend(work.solves);
    }

    /// Whether the store itself failed and every site waits.
    pub(super) fn store_stalled(&self) -> bool {
        self.unstored.as_ref().is_some_and(|u| u.sites.is_none())
    }

    /// Whether `site`'s entries wait for a commit.
    pub(super) fn site_waits(&self, site: &str) -> bool {
        self.unstored.as_ref().is_some_and(|u| u.holds(site))
    }
}
