//! Reading a site's log into this host's store: the standby's rounds of following it, and
//! the takeover (the tail after what the store holds, then the map restored and handed to the
//! worker).

use super::Host;
use super::record::{LogRecord, SiteRecord};
use anyhow::{Context, Result, bail};
use mapper::inbox::Work;
use mapper::store::{SiteChange, Store};
use sitelog::{RetryPolicy, SiteLog};
use std::sync::Arc;
use std::time::Duration;

/// Records read into the store per transaction while catching up.
const CATCH_UP_BATCH: usize = 256;

/// A standby's round of following gives up after this (and opens the log again next
/// round): a round takes milliseconds, and the keeper claims nothing while it runs.
const FOLLOW_BOUND: Duration = Duration::from_millis(500);

/// Records a standby reads in one round at most: a long log is read over several rounds, and
/// the keeper looks at the lease between them.
const FOLLOW_MAX: usize = 4 * CATCH_UP_BATCH;

/// A takeover's open of the site's log, given up after its bound.
#[derive(Debug, thiserror::Error)]
#[error("the site's log did not open within a third of the lease's time")]
pub(super) struct LogNotOpened;

/// A takeover's outcome: the records read, and the alarm that rings if the site's journal
/// is fenced while this host holds it.
pub(super) type TakenOver = (usize, tokio::sync::oneshot::Receiver<()>);

/// [`take_over`] after `pause`.
pub(super) async fn take_over_after(
    pause: Duration,
    host: Arc<Host>,
    site: String,
) -> Result<TakenOver> {
    tokio::time::sleep(pause).await;
    take_over(host, site).await
}

/// One round of [`follow`], bounded by [`FOLLOW_BOUND`] so that a stream without a leader
/// does not keep the standby from claiming the site when its lease lapses. A failure is
/// logged once until a round succeeds, and the log opened again next round.
pub(super) async fn follow_round(
    host: &Arc<Host>,
    site: &str,
    follower: &mut Option<SiteLog>,
    failed: &mut bool,
) {
    let followed = tokio::time::timeout(FOLLOW_BOUND, follow(host, site, follower))
        .await
        .unwrap_or_else(|_| Err(anyhow::anyhow!("no answer in {FOLLOW_BOUND:?}")));
    match followed {
        Ok(()) => *failed = false,
        Err(e) => {
            if !*failed {
                tracing::warn!(site, "cluster: following the site's log: {e:#}");
            }
            *failed = true;
            *follower = None;
        }
    }
}

/// As the site's standby (the next host in its order): reads what was appended to its log
/// since into this host's store, so that a takeover reads a short tail only.
async fn follow(host: &Arc<Host>, site: &str, follower: &mut Option<SiteLog>) -> Result<()> {
    if follower.is_none() {
        let retry = RetryPolicy::default();
        *follower = Some(SiteLog::open(host.js.clone(), site, host.cluster.replicas, retry).await?);
    }
    let log = follower.as_mut().expect("opened above");
    let read = catch_up(host, site, log, FOLLOW_MAX).await?;
    host.shared.instruments.records_followed.inc_by(read as u64);
    if let Err(e) = super::shelf::take_in(host, site).await {
        // The log is followed all the same; the snapshot is looked at again next round.
        tracing::debug!(site, "cluster: the shared snapshot not taken in: {e:#}");
    }
    Ok(())
}

/// Reads `site`'s log after what this host's store holds into the store, at most `max`
/// records, in transactions of [`CATCH_UP_BATCH`]; how many it read.
async fn catch_up(host: &Arc<Host>, site: &str, log: &mut SiteLog, max: usize) -> Result<usize> {
    let store = host.store.clone();
    let name = site.to_owned();
    let mut have = tokio::task::spawn_blocking(move || store.site_log_sequence(&name)).await??;
    let (first, last) = log.bounds().await?;
    if first > have + 1 {
        // A log rebuilt from a host's store (`levelmap site-log rebuild`) starts past every
        // record of the one it replaced: what this store holds of the site is of that one.
        tracing::warn!(
            site,
            "cluster: the site's log was rebuilt (its first record is {first}, this host's \
             store held records up to {have}): the site's rows here are dropped and the log \
             read from its start"
        );
        let (store, name) = (host.store.clone(), site.to_owned());
        tokio::task::spawn_blocking(move || store.forget_site(&name)).await??;
        have = 0;
    }
    if last < have {
        bail!(
            "its log ends at {last} but this host's store holds records up to {have}: the log \
             was lost and made anew; write it again from a store with `levelmap site-log \
             rebuild {site}` (docs/cluster.md, \"A site's log lost\")"
        );
    }
    let (mut next, mut read) = (have + 1, 0);
    while read < max {
        let entries = log.read_some(next, CATCH_UP_BATCH.min(max - read)).await?;
        let Some(newest) = entries.last() else { break };
        next = newest.sequence + 1;
        read += entries.len();
        let records = read_records(host, site, &entries).await?;
        let (store, name) = (host.store.clone(), site.to_owned());
        tokio::task::spawn_blocking(move || commit_records(&store, &name, &records)).await??;
    }
    Ok(read)
}

/// A record of the log as this host stores it.
pub(crate) enum Read {
    /// A batch, at its sequence, with its passes' GPS fixes.
    Batch(u64, SiteRecord, Vec<slam::GpsEdge>),
    /// A change, at its sequence, with an added version's file (`None`: deleted since).
    Change(u64, SiteChange, Option<Vec<u8>>),
}

/// The log's `entries` of `site` decoded, with the files of the versions they add.
async fn read_records(host: &Host, site: &str, entries: &[sitelog::Entry]) -> Result<Vec<Read>> {
    let mut records = Vec::with_capacity(entries.len());
    for e in entries {
        let what = || format!("record {} ({})", e.sequence, e.id);
        records.push(match LogRecord::decode(&e.payload).with_context(what)? {
            LogRecord::Batch(record) => {
                let fixes = record.pass_fixes().with_context(what)?;
                Read::Batch(e.sequence, record, fixes)
            }
            LogRecord::Change(change) => {
                let file = match &change {
                    SiteChange::VersionAdded {
                        number, host: by, ..
                    } => host
                        .version_files
                        .get(site, *number, by)
                        .await
                        .with_context(what)?,
                    _ => None,
                };
                Read::Change(e.sequence, change, file)
            }
        });
    }
    Ok(records)
}

/// Stores the log's `records` of `site` as the worker would have: each run of batches in one
/// commit, each change in its order.
pub(crate) fn commit_records(store: &Store, site: &str, records: &[Read]) -> Result<()> {
    let mut batches = Vec::new();
    for record in records {
        match record {
            Read::Batch(sequence, record, fixes) => {
                let mut batch = record.as_batch(site, *sequence);
                batch.pass_fixes = fixes;
                batches.push(batch);
            }
            Read::Change(sequence, change, file) => {
                if !batches.is_empty() {
                    store.commit(&std::mem::take(&mut batches))?;
                }
                store.apply_site_change(site, Some(*sequence), change, file.clone())?;
            }
        }
    }
    store.commit(&batches)?;
    Ok(())
}

/// Takes `site` over: its log after what this host's store holds read into the store, its
/// map restored, the log handed to the journal and the map to the worker.
pub(super) async fn take_over(host: Arc<Host>, site: String) -> Result<TakenOver> {
    // An append that outlasts the lease is no use: the site is another host's by then. The
    // worker, which appends for every site of this host, waits no longer than that.
    let retry = RetryPolicy {
        deadline: host.leases.ttl(),
        ..RetryPolicy::default()
    };
    // A request sent while the stream elects a leader is never answered: it would wait the
    // client's 10 s. Given up after a third of the lease (as the lease reads) and sent again,
    // so that the takeover follows the election's end within about that.
    let open = SiteLog::open(host.js.clone(), &site, host.cluster.replicas, retry);
    let mut log = tokio::time::timeout(host.leases.ttl() / 3, open)
        .await
        .map_err(|_| LogNotOpened)??;
    let records = catch_up(&host, &site, &mut log, usize::MAX).await?;
    // The newest shared snapshot, if this host's store has none as new: the restore then
    // replays only the nodes after it. Never waited on for longer than a lease.
    let taken_in = tokio::time::timeout(host.leases.ttl(), super::shelf::take_in(&host, &site));
    match taken_in.await {
        Ok(Ok(())) => {}
        Ok(Err(e)) => tracing::warn!(site, "cluster: the shared snapshot not taken in: {e:#}"),
        Err(_) => tracing::warn!(site, "cluster: the shared snapshot not taken in: timed out"),
    }
    host.shared
        .instruments
        .records_taken_over
        .inc_by(records as u64);
    let (store, shared, config) = (host.store.clone(), host.shared.clone(), host.config.clone());
    let name = site.clone();
    let (map, covered) = tokio::task::spawn_blocking(move || {
        let unrecorded = mapper::restore::Unrecorded::Running;
        mapper::restore::restore_fleet(&config, &store, &shared, &name, unrecorded)
    })
    .await??;
    // Its robots' modes as its log left them, with their versions' maps (built here, off
    // the worker), handed over before its nodes.
    let (store, maps, name) = (host.store.clone(), host.maps.clone(), site.clone());
    let (modes, maps) = tokio::task::spawn_blocking(move || -> Result<_> {
        let stored = store.modes()?.into_iter().find(|(fleet, _)| *fleet == name);
        let stored = stored.map(|(_, modes)| modes).unwrap_or_default();
        Ok(mapper::localization::with_maps(
            &store, &maps, &name, &stored,
        ))
    })
    .await??;
    let (reply, modes_set) = tokio::sync::oneshot::channel();
    let set = Work::SetModes {
        fleet: site.clone(),
        modes,
        maps,
        reply,
    };
    // The log first: the worker's journal takes it in as it adopts the site.
    let (handed, fence_alarm) = super::journal::HandedLog::new(&site, log);
    host.logs
        .send(handed)
        .map_err(|_| anyhow::anyhow!("the mapping worker stopped"))?;
    let (reply, adopted) = tokio::sync::oneshot::channel();
    let adopt = Work::Adopt {
        site,
        map: Box::new(map),
        covered,
        reply,
    };
    let work = host.work.clone();
    tokio::task::spawn_blocking(move || work.send(set).and_then(|()| work.send(adopt)))
        .await?
        .map_err(|_| anyhow::anyhow!("the mapping worker stopped"))?;
    let _ = modes_set.await;
    adopted
        .await
        .map_err(|_| anyhow::anyhow!("the mapping worker stopped"))?;
    Ok((records, fence_alarm))
}
