//! The worker's snapshots of the fleets' maps (`fleetmap::snapshot`): a fleet's is
//! written once it took `[store] snapshot_every_nodes` nodes and solves since its last one
//! (what a restore from it would replay), and at a
//! graceful stop. Only between solves (none of the fleet's out, so its state is whole) and
//! after its nodes and solve points are committed: a snapshot never holds what the store
//! does not. It has a transaction of its own, so a failed one costs no node its ack.

use super::Worker;
use std::collections::HashMap;
use std::time::Instant;

impl Worker {
    /// The nodes each fleet's stored snapshot covers, as the restore found them (the solves
    /// it covers are not counted: a fleet restored with solves after its snapshot soon gets
    /// a new one).
    pub fn with_snapshots(mut self, covered: HashMap<String, usize>) -> Worker {
        self.snapshots = covered;
        self
    }

    /// Writes the snapshots that are due; with `all`, of every fleet that took a node since
    /// its last one.
    pub(super) fn snapshots_due(&mut self, all: bool) {
        let every = self.config.store.snapshot_every_nodes as usize;
        if every == 0 || self.store_stalled() {
            return;
        }
        let mut ids: Vec<String> = self.fleets.keys().cloned().collect();
        ids.sort_unstable();
        for id in ids {
            let map = &self.fleets[&id];
            let nodes = map.nodes().len();
            // What a restore from the last snapshot would replay: the nodes and the solves
            // after it (robots passing over mapped ground add solves, not nodes).
            let covers = fleetmap::SnapshotCovers {
                nodes: nodes as u64,
                solves: map.solves_applied(),
            };
            let work = (covers.nodes + covers.solves) as usize;
            let covered = self.snapshots.get(&id).copied().unwrap_or(0);
            let due = match all {
                true => work > covered,
                false => work >= covered + every,
            };
            if !due || self.solve_out(&id) || self.site_waits(&id) {
                continue;
            }
            let started = Instant::now();
            let Some(snapshot) = self.fleets[&id].snapshot() else {
                continue;
            };
            let encoded = started.elapsed();
            let bytes = snapshot.len();
            let stored = self.journal.snapshot(&id, covers, snapshot);
            let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
            match stored {
                Ok(()) => {
                    tracing::info!(
                        fleet = %id,
                        nodes,
                        bytes,
                        "snapshot stored: encoded in {:.1} ms, written in {:.1} ms",
                        ms(encoded),
                        ms(started.elapsed() - encoded)
                    );
                }
                // Tried again after as many nodes: the last one stays usable.
                Err(e) => tracing::warn!(fleet = %id, "snapshot not stored: {e}"),
            }
            self.snapshots.insert(id, work);
        }
    }
}
