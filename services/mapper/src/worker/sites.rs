//! The worker in cluster mode (`crate::cluster`): it maps only the sites this host owns,
//! and appends each site's batch to the site's log in JetStream before the store's commit,
//! so a node is acked only once JetStream acked its record. A site comes with its lease
//! ([`Work::Adopt`](super::Work::Adopt): its map restored from the log) and goes when the
//! lease is lost ([`Work::Drop`](super::Work::Drop)) or an append is fenced: it is dropped
//! at once, with whatever of it was mapped and not acked.

use super::ChangeError;
use super::{Batch, Worker, commit::Unstored};
use crate::store::SiteChange;
use crate::store::{FleetBatch, StoreError};
use crate::views::instruments::Instruments;
use fleetmap::{FleetMap, SnapshotCovers};
use sitelog::{Appended, LogError, RecordId, SiteLog};
use std::collections::HashMap;

/// The logs of the sites this host owns, and how to reach them from the worker's thread.
pub struct SiteLogs {
    runtime: tokio::runtime::Handle,
    logs: HashMap<String, SiteLog>,
    /// Sites dropped by the worker itself (a fenced append): their keepers stop renewing.
    fenced: Fenced,
    /// Where the snapshots of the sites owned go to be shared.
    shelf: crate::cluster::Shelf,
}

/// Sites whose append was fenced, from the worker to their keepers (`crate::cluster`).
pub type Fenced = std::sync::Arc<std::sync::Mutex<std::collections::HashSet<String>>>;

impl SiteLogs {
    /// No site yet; appends run on `runtime`; fenced sites are told on `fenced`; snapshots
    /// go on `shelf`.
    pub fn new(
        runtime: tokio::runtime::Handle,
        fenced: Fenced,
        shelf: crate::cluster::Shelf,
    ) -> SiteLogs {
        SiteLogs {
            runtime,
            logs: HashMap::new(),
            fenced,
            shelf,
        }
    }

    /// Appends each batch to its site's log, setting its `log_sequence`; the sites whose
    /// append was fenced (their batches are left without a sequence). An append JetStream
    /// did not ack fails the whole commit: it is tried again, and the records already
    /// stored come back as duplicates.
    fn append(
        &mut self,
        batches: &mut [FleetBatch<'_>],
        instruments: &Instruments,
    ) -> Result<Vec<String>, StoreError> {
        let mut fenced = Vec::new();
        for batch in batches.iter_mut() {
            let Some(log) = self.logs.get_mut(batch.fleet) else {
                return Err(StoreError::Log(format!("site {}: no log", batch.fleet)));
            };
            let started = std::time::Instant::now();
            match self.runtime.block_on(append_batch(log, batch)) {
                Ok(sequence) => {
                    Instruments::time(&instruments.log_append, started.elapsed());
                    batch.log_sequence = Some(sequence);
                }
                Err(LogError::Fenced { expected, detail }) => {
                    tracing::warn!(site = batch.fleet, expected, "append fenced: {detail}");
                    instruments.appends_fenced.inc();
                    fenced.push(batch.fleet.to_owned());
                }
                Err(e) => return Err(StoreError::Log(format!("site {}: {e}", batch.fleet))),
            }
        }
        Ok(fenced)
    }
}

/// Appends a batch's records; the sequence of its last. A record found stored already under
/// its id must be this very record (a retry after a lost ack); anything else under its id
/// was written by another owner this host did not see: a fence.
async fn append_batch(log: &mut SiteLog, batch: &FleetBatch<'_>) -> Result<u64, LogError> {
    let mut last = log.last_sequence();
    for (id, record) in crate::cluster::record::records_of(batch) {
        last = append_record(log, &id, bytes::Bytes::from(record.encode())).await?;
    }
    Ok(last)
}

/// Appends one record; its sequence. A record found stored already under its id must be this
/// very record (a retry after a lost ack); anything else under its id was written by another
/// owner this host did not see: a fence.
async fn append_record(
    log: &mut SiteLog,
    id: &RecordId,
    bytes: bytes::Bytes,
) -> Result<u64, LogError> {
    match log.append(id, bytes.clone()).await? {
        Appended::New(sequence) => Ok(sequence),
        Appended::Duplicate(sequence) => {
            if log.get(sequence).await?.payload != bytes {
                return Err(LogError::Fenced {
                    expected: log.last_sequence(),
                    detail: format!("record {id} at {sequence} was written by another owner"),
                });
            }
            Ok(sequence)
        }
    }
}

impl Worker {
    /// In cluster mode, this host's site logs.
    pub fn with_site_logs(mut self, logs: SiteLogs) -> Worker {
        self.sites = Some(logs);
        self
    }

    /// Whether nodes of `fleet` are this host's to map: always in single-machine mode, in
    /// cluster mode while it owns the site.
    pub(super) fn owns(&self, fleet: &str) -> bool {
        self.sites.is_none() || self.fleets.contains_key(fleet)
    }

    /// In cluster mode, appends each batch to its site's log before the store commits it;
    /// the sites fenced, their batches removed.
    pub(super) fn append_to_logs(
        &mut self,
        batches: &mut Vec<FleetBatch<'_>>,
    ) -> Result<Vec<String>, StoreError> {
        let Some(sites) = &mut self.sites else {
            return Ok(Vec::new());
        };
        let fenced = sites.append(batches, &self.shared.instruments)?;
        batches.retain(|b| !fenced.iter().any(|f| f == b.fleet));
        let mut told = sites.fenced.lock().expect("fenced lock");
        told.extend(fenced.iter().cloned());
        drop(told);
        Ok(fenced)
    }

    /// In cluster mode, hands the committed batches' clouds to be shared: they are not the
    /// record (their nodes are acked without waiting), and one that finds the shelf full is
    /// counted and left.
    pub(super) fn share_clouds(&self, batches: &[FleetBatch<'_>]) {
        let Some(sites) = &self.sites else { return };
        for batch in batches {
            for &(node, cloud) in &batch.clouds {
                if !sites.shelf.shelve_cloud(batch.fleet, node, cloud) {
                    self.shared.instruments.clouds_unshared.inc();
                }
            }
        }
    }

    /// Appends `change` to `site`'s log, then stores it. A fenced append drops the site, as
    /// a fenced batch does.
    pub(super) fn change_site(
        &mut self,
        site: &str,
        change: &SiteChange,
        file: Option<Vec<u8>>,
        asked_ns: u64,
        batch: &mut Batch,
    ) -> Result<(), ChangeError> {
        let not_owner = || ChangeError::NotOwner(site.to_owned());
        let Some(sites) = &mut self.sites else {
            return Err(not_owner());
        };
        let Some(log) = sites.logs.get_mut(site) else {
            return Err(not_owner());
        };
        let id = crate::cluster::record::change_id(change, asked_ns);
        let bytes = bytes::Bytes::from(crate::cluster::record::encode_change(change));
        match sites.runtime.block_on(append_record(log, &id, bytes)) {
            Ok(sequence) => self
                .store
                .apply_site_change(site, sequence, change, file)
                .map_err(|e| ChangeError::Store(e.to_string())),
            Err(LogError::Fenced { expected, detail }) => {
                tracing::warn!(site, expected, "change fenced: {detail}");
                self.shared.instruments.appends_fenced.inc();
                sites
                    .fenced
                    .lock()
                    .expect("fenced lock")
                    .insert(site.to_owned());
                self.drop_site(site, "another host appended to its log", batch);
                Err(not_owner())
            }
            Err(e) => Err(ChangeError::Log(format!("site {site}: {e}"))),
        }
    }

    /// Takes over `site`: its map (restored from its log), how many nodes its snapshot
    /// covered, its log.
    pub(super) fn adopt(&mut self, site: String, map: FleetMap, covered: usize, log: SiteLog) {
        tracing::info!(site, nodes = map.nodes().len(), "site taken over");
        self.shared.instruments.sites_adopted.inc();
        self.shared.publish_map(&map, 0.0);
        self.edges_stored
            .insert(site.clone(), map.graph().edges.len());
        self.snapshots.insert(site.clone(), covered);
        self.fleets.insert(site.clone(), map);
        if let Some(sites) = &mut self.sites {
            sites.logs.insert(site, log);
        }
        self.shared
            .instruments
            .sites_owned
            .set(self.fleets.len() as i64);
    }

    /// Drops `site` at once: its map, its log, its solve out, what of it was mapped and not
    /// stored (in `batch`, and kept from a failed commit). Nothing of it is acked after this.
    pub(super) fn drop_site(&mut self, site: &str, why: &str, batch: &mut Batch) {
        if self.fleets.remove(site).is_none() {
            return;
        }
        tracing::warn!(site, "site dropped: {why}");
        self.shared.instruments.sites_dropped.inc();
        self.edges_stored.remove(site);
        self.snapshots.remove(site);
        self.localizing.remove(site);
        if let Some(sites) = &mut self.sites {
            sites.logs.remove(site);
        }
        self.solving.forget(site);
        without_site(batch, site);
        if let Some(unstored) = &mut self.unstored {
            without_site(&mut unstored.batch, site);
            unstored.solves.retain(|(fleet, ..)| fleet != site);
        }
        self.shared.fleets.write().expect("views lock").remove(site);
        self.shared
            .instruments
            .sites_owned
            .set(self.fleets.len() as i64);
    }

    /// In cluster mode, shares a snapshot of `site` just stored: tagged with the last log
    /// record the store holds of it (the snapshot holds nothing the store does not).
    pub(super) fn share_snapshot(&self, site: &str, covers: SnapshotCovers, bytes: Vec<u8>) {
        let Some(sites) = &self.sites else { return };
        let log_sequence = match self.store.site_log_sequence(site) {
            Ok(sequence) => sequence,
            Err(e) => {
                tracing::warn!(site, "snapshot not shared: {e}");
                return;
            }
        };
        let tag = sitelog::SnapshotTag {
            log_sequence,
            nodes: covers.nodes,
            solves: covers.solves,
            mapping_version: self.config.mapping_version().to_string(),
        };
        sites.shelf.shelve(crate::cluster::Shelved {
            site: site.to_owned(),
            tag,
            bytes,
        });
    }

    /// Drops the sites whose appends were fenced from what a commit held.
    pub(super) fn drop_fenced(&mut self, fenced: &[String], work: &mut Unstored) {
        for site in fenced {
            work.solves.retain(|(fleet, ..)| fleet != site);
            self.drop_site(site, "another host appended to its log", &mut work.batch);
        }
    }
}

/// `batch` without the entries of `site`.
fn without_site(batch: &mut Batch, site: &str) {
    batch.accepted.retain(|a| a.fleet != site);
    batch.reacks.retain(|r| r.fleet != site);
    batch.localized.retain(|l| l.fleet != site);
}
