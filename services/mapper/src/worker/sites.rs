//! The sites the worker writes, as the journal holds them: on a single machine every fleet,
//! in cluster mode those whose lease this host holds. A site comes with
//! [`Work::Adopt`](crate::inbox::Work::Adopt) (its map restored) and goes with
//! [`Work::Drop`](crate::inbox::Work::Drop) or a fenced entry: it is dropped at once, with
//! whatever of it was mapped and not acked. A change of a site's versions or modes is
//! journaled like a batch.

use super::{Batch, Worker};
use crate::journal::ChangeError;
use crate::store::SiteChange;
use fleetmap::FleetMap;

impl Worker {
    /// Whether nodes of `fleet` are this host's to map.
    pub(super) fn owns(&self, fleet: &str) -> bool {
        self.journal.holds(fleet)
    }

    /// Journals `change` of `site`. A fenced one drops the site, as a fenced batch does.
    pub(super) fn change_site(
        &mut self,
        site: &str,
        change: &SiteChange,
        file: Option<Vec<u8>>,
        asked_ns: u64,
        batch: &mut Batch,
    ) -> Result<(), ChangeError> {
        match self.journal.change(site, change, file, asked_ns) {
            Err(ChangeError::Fenced(_)) => {
                self.drop_site(site, "another host appended to its log", batch);
                Err(ChangeError::NotOwner(site.to_owned()))
            }
            done => done,
        }
    }

    /// Takes over `site`: its map (restored from its log), how many nodes its snapshot
    /// covered.
    pub(super) fn adopt(&mut self, site: String, map: FleetMap, covered: usize) {
        tracing::info!(site, nodes = map.nodes().len(), "site taken over");
        self.shared.instruments.sites_adopted.inc();
        self.shared.publish_map(&map, 0.0);
        self.edges_stored
            .insert(site.clone(), map.graph().edges.len());
        self.snapshots.insert(site.clone(), covered);
        self.journal.adopt(&site);
        self.fleets.insert(site, map);
        self.shared
            .instruments
            .sites_owned
            .set(self.fleets.len() as i64);
    }

    /// Drops `site` at once: its map, its journal, its solve out, what of it was mapped and
    /// not stored (in `batch`, and kept from a failed commit). Nothing of it is acked after
    /// this.
    pub(super) fn drop_site(&mut self, site: &str, why: &str, batch: &mut Batch) {
        if self.fleets.remove(site).is_none() {
            return;
        }
        tracing::warn!(site, "site dropped: {why}");
        self.shared.instruments.sites_dropped.inc();
        self.edges_stored.remove(site);
        self.snapshots.remove(site);
        self.localizing.remove(site);
        self.journal.drop_site(site);
        self.solving.forget(site);
        without_site(batch, site);
        if let Some(unstored) = &mut self.unstored {
            without_site(&mut unstored.batch, site);
            unstored.solves.retain(|(fleet, ..)| fleet != site);
            if let Some(waiting) = &mut unstored.sites {
                waiting.remove(site);
            }
        }
        if self.unstored.as_ref().is_some_and(|u| u.is_empty()) {
            self.unstored = None;
        }
        self.shared.fleets.write().expect("views lock").remove(site);
        self.shared
            .instruments
            .sites_owned
            .set(self.fleets.len() as i64);
    }
}

/// `batch` without the entries of `site`.
fn without_site(batch: &mut Batch, site: &str) {
    batch.accepted.retain(|a| a.fleet != site);
    batch.reacks.retain(|r| r.fleet != site);
    batch.localized.retain(|l| l.fleet != site);
}
