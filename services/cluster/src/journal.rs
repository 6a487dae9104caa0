//! The cluster's [`Journal`]: each site's entries appended to the site's log in JetStream
//! before the host's store commits them, so a node is acked only once JetStream acked its
//! record. The sites' appends go out together and fail alone: a site whose log is fenced or
//! does not answer is returned as that site's fault, and the others are committed.
//!
//! A site's log comes with the site: the keeper hands it over ([`LogInbox`]) before it sends
//! the worker [`mapper::inbox::Work::Adopt`], and the worker's [`Journal::adopt`] takes it
//! in. A fence also goes back to the site's keeper, on the alarm handed over with the log,
//! so that it reads the log again while it still holds the lease.

use super::record::{change_id, encode_change, records_of};
use super::shelf::{Shelf, Shelved};
use bytes::Bytes;
use fleetmap::SnapshotCovers;
use mapper::journal::{ChangeError, Journal, SiteFault};
use mapper::store::{FleetBatch, SiteChange, Store, StoreError};
use mapper::views::Shared;
use mapper::views::instruments::Instruments;
use sitelog::{Appended, LogError, RecordId, SiteLog};
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

/// How long the worker waits, in one turn, for the appends of a site whose log failed to take
/// its last entries (a stream electing a leader takes 4–9 s): the site's entries are tried
/// again every second, and each try holds the worker, and so the other sites' acks, at most
/// this long. Well above a healthy append (milliseconds), well under a lease. A site whose
/// log answered last time is given the log's own retry deadline (the lease's time).
const WAITING_SITE_BOUND: Duration = Duration::from_millis(250);

/// A batch's records, by its index among the turn's batches.
type BatchRecords = (usize, Vec<(RecordId, Bytes)>);

/// A site's log on its way from the keeper to the journal, with the alarm that tells the
/// keeper of a fence.
pub struct HandedLog {
    site: String,
    log: SiteLog,
    fence_alarm: tokio::sync::oneshot::Sender<()>,
}

impl HandedLog {
    /// `site`'s `log`, read to its end; a fence is told on the receiver returned.
    pub fn new(site: &str, log: SiteLog) -> (HandedLog, tokio::sync::oneshot::Receiver<()>) {
        let (fence_alarm, fenced) = tokio::sync::oneshot::channel();
        let handed = HandedLog {
            site: site.to_owned(),
            log,
            fence_alarm,
        };
        (handed, fenced)
    }
}

/// The keepers' end of the journal: where a site's log is handed over.
pub type LogInbox = mpsc::Sender<HandedLog>;

/// A site this host holds: its log, and its keeper's alarm.
struct HeldLog {
    log: SiteLog,
    fence_alarm: Option<tokio::sync::oneshot::Sender<()>>,
}

impl HeldLog {
    fn fenced(&mut self) {
        if let Some(alarm) = self.fence_alarm.take() {
            let _ = alarm.send(());
        }
    }
}

/// The sites' logs of this host, written from the worker's thread.
pub struct LogJournal {
    runtime: tokio::runtime::Handle,
    store: Arc<Store>,
    shared: Arc<Shared>,
    logs: HashMap<String, HeldLog>,
    /// Logs handed over and not adopted yet.
    handed: mpsc::Receiver<HandedLog>,
    waiting: HashMap<String, HandedLog>,
    /// Where the snapshots and clouds of the sites held go to be shared.
    shelf: Shelf,
    /// Tags the snapshots shared.
    mapping_version: String,
    /// Sites whose log did not take their last entries: their next appends are bounded by
    /// [`WAITING_SITE_BOUND`] per turn.
    waiting_sites: std::collections::HashSet<String>,
}

impl LogJournal {
    /// No site yet; appends run on `runtime`; snapshots and clouds go on `shelf`. The
    /// keepers hand the sites' logs over on the inbox returned.
    pub fn new(
        runtime: tokio::runtime::Handle,
        store: Arc<Store>,
        shared: Arc<Shared>,
        shelf: Shelf,
        mapping_version: String,
    ) -> (LogJournal, LogInbox) {
        let (inbox, handed) = mpsc::channel();
        let journal = LogJournal {
            runtime,
            store,
            shared,
            logs: HashMap::new(),
            handed,
            waiting: HashMap::new(),
            shelf,
            mapping_version,
            waiting_sites: Default::default(),
        };
        (journal, inbox)
    }

    fn instruments(&self) -> &Instruments {
        &self.shared.instruments
    }
}

impl Journal for LogJournal {
    fn holds(&self, site: &str) -> bool {
        self.logs.contains_key(site)
    }

    fn commit(
        &mut self,
        batches: &mut Vec<FleetBatch<'_>>,
    ) -> Result<Vec<(String, SiteFault)>, StoreError> {
        // Each site's batches, in order, as the records its log keeps.
        let mut by_site: BTreeMap<&str, Vec<BatchRecords>> = BTreeMap::new();
        for (i, batch) in batches.iter().enumerate() {
            let records = records_of(batch)
                .into_iter()
                .map(|(id, record)| (id, Bytes::from(record.encode())))
                .collect();
            by_site.entry(batch.fleet).or_default().push((i, records));
        }
        let mut faults: Vec<(String, SiteFault)> = Vec::new();
        let mut appends = Vec::new();
        for (site, held) in self.logs.iter_mut() {
            if let Some(records) = by_site.remove(site.as_str()) {
                let bound = self
                    .waiting_sites
                    .contains(site.as_str())
                    .then_some(WAITING_SITE_BOUND);
                appends.push(append_site(site.as_str(), held, records, bound));
            }
        }
        for site in by_site.keys() {
            let why = "this host holds no log of it".to_owned();
            faults.push((site.to_string(), SiteFault::Fenced(why)));
        }
        let appended = self
            .runtime
            .block_on(futures_util::future::join_all(appends));
        let mut sequences = Vec::new();
        let mut fenced = Vec::new();
        for (site, result) in appended {
            match result {
                Ok((took, sites_sequences)) => {
                    self.waiting_sites.remove(&site);
                    Instruments::time(&self.shared.instruments.log_append, took);
                    sequences.extend(sites_sequences);
                }
                Err(LogError::Fenced { expected, detail }) => {
                    tracing::warn!(site, expected, "append fenced: {detail}");
                    self.instruments().appends_fenced.inc();
                    fenced.push(site.clone());
                    faults.push((site, SiteFault::Fenced(detail)));
                }
                Err(e) => {
                    self.waiting_sites.insert(site.clone());
                    faults.push((site, SiteFault::Unavailable(e.to_string())));
                }
            }
        }
        for site in fenced {
            if let Some(held) = self.logs.get_mut(&site) {
                held.fenced();
            }
        }
        for (i, sequence) in sequences {
            batches[i].log_sequence = Some(sequence);
        }
        batches.retain(|b| !faults.iter().any(|(site, _)| site == b.fleet));
        self.store.commit(batches)?;
        // Clouds are not the record: their nodes are acked without waiting, and one that
        // finds the shelf full is counted and left.
        for batch in batches.iter() {
            for &(node, cloud) in &batch.clouds {
                if !self.shelf.shelve_cloud(batch.fleet, node, cloud) {
                    self.instruments().clouds_unshared.inc();
                }
            }
        }
        Ok(faults)
    }

    fn change(
        &mut self,
        site: &str,
        change: &SiteChange,
        file: Option<Vec<u8>>,
        asked_ns: u64,
    ) -> Result<(), ChangeError> {
        let Some(held) = self.logs.get_mut(site) else {
            return Err(ChangeError::NotOwner(site.to_owned()));
        };
        let id = change_id(change, asked_ns);
        let bytes = Bytes::from(encode_change(change));
        match self
            .runtime
            .block_on(append_record(&mut held.log, &id, bytes))
        {
            Ok(sequence) => self
                .store
                .apply_site_change(site, Some(sequence), change, file)
                .map_err(|e| ChangeError::Store(e.to_string())),
            Err(LogError::Fenced { expected, detail }) => {
                tracing::warn!(site, expected, "change fenced: {detail}");
                held.fenced();
                self.instruments().appends_fenced.inc();
                Err(ChangeError::Fenced(detail))
            }
            Err(e) => Err(ChangeError::Log(format!("site {site}: {e}"))),
        }
    }

    fn adopt(&mut self, site: &str) {
        while let Ok(handed) = self.handed.try_recv() {
            self.waiting.insert(handed.site.clone(), handed);
        }
        match self.waiting.remove(site) {
            Some(HandedLog {
                log, fence_alarm, ..
            }) => {
                let held = HeldLog {
                    log,
                    fence_alarm: Some(fence_alarm),
                };
                self.logs.insert(site.to_owned(), held);
            }
            None => tracing::error!(site, "cluster: a site adopted without its log"),
        }
    }

    fn drop_site(&mut self, site: &str) {
        self.logs.remove(site);
        self.waiting_sites.remove(site);
    }

    fn snapshot(
        &self,
        site: &str,
        covers: SnapshotCovers,
        bytes: Vec<u8>,
    ) -> Result<(), StoreError> {
        self.store.put_snapshot(site, &bytes)?;
        // Tagged with the last log record the store holds of the site: the snapshot holds
        // nothing the store does not.
        let log_sequence = match self.store.site_log_sequence(site) {
            Ok(sequence) => sequence,
            Err(e) => {
                tracing::warn!(site, "snapshot not shared: {e}");
                return Ok(());
            }
        };
        let tag = sitelog::SnapshotTag {
            log_sequence,
            nodes: covers.nodes,
            solves: covers.solves,
            mapping_version: self.mapping_version.clone(),
        };
        self.shelf.shelve(Shelved {
            site: site.to_owned(),
            tag,
            bytes,
        });
        Ok(())
    }
}

/// What one site's appends gave: the time they took and the sequence of each batch's last
/// record, or the failure that stopped them.
type SiteAppended = (String, Result<(Duration, Vec<(usize, u64)>), LogError>);

/// Appends a site's batches' records in order, within `bound` if one is given. An append
/// given up on at the bound may still land: its retry carries the same record ids, which
/// the log takes as duplicates.
async fn append_site(
    site: &str,
    held: &mut HeldLog,
    batches: Vec<BatchRecords>,
    bound: Option<Duration>,
) -> SiteAppended {
    let Some(bound) = bound else {
        return append_site_unbounded(site, held, batches).await;
    };
    match tokio::time::timeout(bound, append_site_unbounded(site, held, batches)).await {
        Ok(appended) => appended,
        Err(_) => {
            let why = format!("no ack within {bound:?} while the site's log recovers");
            (site.to_owned(), Err(LogError::Unavailable(bound, why)))
        }
    }
}

/// [`append_site`] without a bound of its own (each append is bounded by the log's deadline).
async fn append_site_unbounded(
    site: &str,
    held: &mut HeldLog,
    batches: Vec<BatchRecords>,
) -> SiteAppended {
    let started = Instant::now();
    let mut sequences = Vec::new();
    for (i, records) in batches {
        let mut last = held.log.last_sequence();
        for (id, bytes) in records {
            match append_record(&mut held.log, &id, bytes).await {
                Ok(sequence) => last = sequence,
                Err(e) => return (site.to_owned(), Err(e)),
            }
        }
        sequences.push((i, last));
    }
    (site.to_owned(), Ok((started.elapsed(), sequences)))
}

/// Appends one record; its sequence. A record found stored already under its id must be this
/// very record (a retry after a lost ack); anything else under its id was written by another
/// owner this host did not see: a fence.
async fn append_record(log: &mut SiteLog, id: &RecordId, bytes: Bytes) -> Result<u64, LogError> {
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
