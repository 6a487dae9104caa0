//! The one seam through which the mapper's single writer, the worker, makes a site's record
//! durable. Every change of a site's record is one typed entry: a batch of nodes with their
//! edges and solve points ([`FleetBatch`]), or a version added or deleted, or robots' modes
//! set ([`SiteChange`]). The worker makes the entries; a [`Journal`] makes them durable.
//!
//! On a single machine the journal is the store itself ([`StoreJournal`]): an entry is
//! durable once redb committed it. In cluster mode (the `cluster` crate's `LogJournal`) each site's
//! entries are first appended to the site's log in JetStream (fenced, deduplicated; the sites'
//! appends go out in parallel), then committed to the host's store, its cache of the logs. A
//! site whose log does not take its entries fails alone ([`SiteFault`]): the other sites'
//! entries are committed and acked.

use crate::store::{FleetBatch, SiteChange, Store, StoreError};
use fleetmap::SnapshotCovers;
use std::sync::Arc;

/// Why a site's entries were not made durable, while other sites' may have been.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SiteFault {
    /// Another writer appended to the site's log: this host no longer holds the site. The
    /// writer drops it.
    Fenced(String),
    /// The site's log did not take the entries in time (no leader, cut off): kept by the
    /// writer and tried again; the site's nodes wait meanwhile.
    Unavailable(String),
}

impl std::fmt::Display for SiteFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SiteFault::Fenced(why) => write!(f, "fenced: {why}"),
            SiteFault::Unavailable(why) => write!(f, "the site's log is unavailable: {why}"),
        }
    }
}

/// Why a change of a site's versions or modes was not made.
#[derive(Debug, thiserror::Error)]
pub enum ChangeError {
    /// This host does not hold the site (any more): its owner takes the change.
    #[error("this host does not hold site {0} now; ask again (through a gateway)")]
    NotOwner(String),
    /// Another writer appended to the site's log: the writer drops the site.
    #[error("fenced: {0}")]
    Fenced(String),
    /// The site's log did not take it (not reachable in time).
    #[error("{0}")]
    Log(String),
    /// The store failed to keep it (in cluster mode, after the log took it: the log has it).
    #[error("{0}")]
    Store(String),
}

/// Makes the writer's entries durable. Called from the worker's thread only.
pub trait Journal: Send {
    /// Whether this host writes `site`'s record: always on a single machine, in cluster
    /// mode while it holds the site.
    fn holds(&self, site: &str) -> bool;

    /// Makes `batches` (one per site, each a site's entries of one turn) durable. On `Ok`,
    /// `batches` keeps the ones committed and the faults name the sites whose entries were
    /// not (removed from `batches`). `Err`: the store failed, nothing was committed.
    fn commit(
        &mut self,
        batches: &mut Vec<FleetBatch<'_>>,
    ) -> Result<Vec<(String, SiteFault)>, StoreError>;

    /// Makes `change` of `site` durable (`file`: an added version's file). `asked_ns` names
    /// a change of modes, so only its retries are one.
    fn change(
        &mut self,
        site: &str,
        change: &SiteChange,
        file: Option<Vec<u8>>,
        asked_ns: u64,
    ) -> Result<(), ChangeError>;

    /// `site` comes to this host (cluster mode: its log, read to its end, came with it).
    fn adopt(&mut self, _site: &str) {}

    /// `site` leaves this host: nothing more of it is written.
    fn drop_site(&mut self, _site: &str) {}

    /// Keeps a snapshot of `site`'s map, which covers what `covers` says (a cache of the
    /// record, not an entry of it: in cluster mode shared with the other hosts too).
    fn snapshot(
        &self,
        site: &str,
        covers: SnapshotCovers,
        bytes: Vec<u8>,
    ) -> Result<(), StoreError>;
}

/// The single machine's journal: the store.
pub struct StoreJournal {
    store: Arc<Store>,
}

impl StoreJournal {
    /// Entries committed to `store`.
    pub fn new(store: Arc<Store>) -> StoreJournal {
        StoreJournal { store }
    }
}

impl Journal for StoreJournal {
    fn holds(&self, _site: &str) -> bool {
        true
    }

    fn commit(
        &mut self,
        batches: &mut Vec<FleetBatch<'_>>,
    ) -> Result<Vec<(String, SiteFault)>, StoreError> {
        self.store.commit(batches)?;
        Ok(Vec::new())
    }

    fn change(
        &mut self,
        site: &str,
        change: &SiteChange,
        file: Option<Vec<u8>>,
        _asked_ns: u64,
    ) -> Result<(), ChangeError> {
        self.store
            .apply_site_change(site, None, change, file)
            .map_err(|e| ChangeError::Store(e.to_string()))
    }

    fn snapshot(
        &self,
        site: &str,
        _covers: SnapshotCovers,
        bytes: Vec<u8>,
    ) -> Result<(), StoreError> {
        self.store.put_snapshot(site, &bytes)
    }
}
