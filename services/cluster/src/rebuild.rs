//! A site's log written anew from a host's store (`levelmap site-log rebuild`), for a log
//! that is lost: its stream deleted, or every server's copy of it gone. The store is the
//! host's cache of the log (every record it owned or followed), so it holds what a log must:
//! the nodes as received, the edges, the solves and their GPS fixes, the spans, the versions
//! and the modes. The records are written as the owner writes them ([`super::record`]), in
//! a new stream that starts [`REBUILT_GAP`] past every record the old one can have held:
//! each host's store then finds a gap before the log's first record, drops what it held of
//! the site and reads the log from its start (`replay::catch_up`), so every store agrees with
//! the new log whatever it held of the old one. The tool holds the site's lease while it
//! writes, so that no host takes the site over from half a log.

use super::record::{MAX_RECORD_NODE_BYTES, SiteRecord, encode_change};
use anyhow::{Context, Result, bail};
use mapper::config::ClusterConfig;
use mapper::store::{SiteChange, SolvePoint, Store, StoredFleet};
use serde::Serialize;
use sitelog::{Lease, Leases, RecordId, RetryPolicy, SiteLog, Snapshots, VersionFiles};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

/// How far past the old log's last record (as the store knows it) a rebuilt log starts: past
/// whatever any other host's store can hold of the old log, however far ahead of this store
/// it was.
pub const REBUILT_GAP: u64 = 1 << 32;

/// The records of a site's log that a store holds, in their order, and the version files
/// their changes name.
#[derive(Debug, Default)]
pub struct StoreRecords {
    /// (id, the record's bytes).
    pub records: Vec<(RecordId, Vec<u8>)>,
    /// (number, file) of each kept version, to put in the version files under the
    /// rebuild's name before the records are appended.
    pub files: Vec<(u64, Vec<u8>)>,
    /// What they hold.
    pub counts: Counts,
}

/// What a rebuilt log holds.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// Nodes, in arrival order.
    pub nodes: u64,
    /// Edges.
    pub edges: u64,
    /// Solves, with their passes' GPS fixes.
    pub solves: u64,
    /// Spans of localized or passed nodes.
    pub spans: u64,
    /// Versions kept (with their files).
    pub versions: u64,
    /// Changes of the robots' modes.
    pub modes: u64,
}

/// `site`'s records as `store` holds them, its versions' files named as put by `by`.
pub fn records_from_store(store: &Store, site: &str, by: &str) -> Result<StoreRecords> {
    let stored = store.load_fleet(site)?;
    if !stored.legacy_solves.is_empty() {
        bail!(
            "site {site}: its store has solves of a release before background solves, which no \
             log holds"
        );
    }
    let mut out = StoreRecords::default();
    let change = |out: &mut StoreRecords, name: String, change: SiteChange| {
        out.records
            .push((RecordId::named(name), encode_change(&change)));
    };
    // Versions first: the modes name them.
    let summaries = store.version_summaries(site)?;
    for (number, summary) in &summaries {
        let file = store
            .version_file(site, *number)?
            .with_context(|| format!("site {site}: version {number} has a summary but no file"))?;
        out.files.push((*number, file));
        let added = SiteChange::VersionAdded {
            number: *number,
            summary: summary.clone(),
            host: by.to_owned(),
        };
        change(&mut out, format!("rebuilt/version/{number}"), added);
        out.counts.versions += 1;
    }
    let last_number = store.last_version_number(site)?;
    if last_number > summaries.last().map_or(0, |(n, _)| *n) {
        // The last number given was deleted: a reader keeps the number (no file under it),
        // so that it is never given again.
        let added = SiteChange::VersionAdded {
            number: last_number,
            summary: Vec::new(),
            host: by.to_owned(),
        };
        change(&mut out, format!("rebuilt/version/{last_number}"), added);
        let deleted = SiteChange::VersionDeleted {
            number: last_number,
        };
        change(&mut out, format!("rebuilt/deleted/{last_number}"), deleted);
    }
    let modes = store.modes()?.into_iter().find(|(fleet, _)| fleet == site);
    if let Some((_, modes)) = modes {
        if let Some(version) = modes.fleet {
            let set = SiteChange::ModesSet {
                robots: None,
                version,
            };
            change(&mut out, "rebuilt/modes/fleet".into(), set);
            out.counts.modes += 1;
        }
        let mut by_version: BTreeMap<u64, Vec<String>> = BTreeMap::new();
        for (robot, version) in modes.robots {
            by_version.entry(version).or_default().push(robot);
        }
        for (version, robots) in by_version {
            let set = SiteChange::ModesSet {
                robots: Some(robots),
                version,
            };
            change(&mut out, format!("rebuilt/modes/{version}"), set);
            out.counts.modes += 1;
        }
    }
    batch_records(&stored, &mut out);
    if out.records.is_empty() {
        bail!("site {site}: this store holds nothing of it");
    }
    Ok(out)
}

/// The fleet's nodes in records of at most [`MAX_RECORD_NODE_BYTES`], each solve in the record
/// of the node it was applied after (or a record of its own), then the edges in records of
/// as many bytes, the spans in the last.
fn batch_records(stored: &StoredFleet, out: &mut StoreRecords) {
    let mut solves = stored.solve_points.iter().peekable();
    let mut records: Vec<SiteRecord> = Vec::new();
    let mut record = SiteRecord::default();
    let mut bytes = 0;
    let with_solve = |record: &mut SiteRecord, point: &SolvePoint| {
        record.solved = Some((point.seq, point.taken_after, point.applied_after));
        record.pass_fixes = stored
            .pass_fixes
            .get(&point.seq)
            .into_iter()
            .flatten()
            .map(|f| serde_json::to_vec(f).expect("a GPS edge serializes"))
            .collect();
    };
    for (arrival, node) in stored.nodes.iter().enumerate() {
        let arrival = arrival as u64;
        if !record.nodes.is_empty() && bytes + node.len() > MAX_RECORD_NODE_BYTES {
            records.push(std::mem::take(&mut record));
            bytes = 0;
        }
        record.nodes.push((arrival, node.clone()));
        bytes += node.len();
        while let Some(point) = solves.next_if(|p| p.applied_after <= arrival) {
            if record.solved.is_some() {
                records.push(std::mem::take(&mut record));
                bytes = 0;
            }
            with_solve(&mut record, point);
        }
        if record.solved.is_some() {
            records.push(std::mem::take(&mut record));
            bytes = 0;
        }
    }
    for point in solves {
        if record.solved.is_some() {
            records.push(std::mem::take(&mut record));
        }
        with_solve(&mut record, point);
    }
    if !record.nodes.is_empty() || record.solved.is_some() {
        records.push(std::mem::take(&mut record));
    }
    let (mut first_edge, mut bytes) = (0, 0);
    for (k, edge) in stored.edges.iter().enumerate() {
        if !record.edges.is_empty() && bytes + edge.len() > MAX_RECORD_NODE_BYTES {
            records.push(std::mem::take(&mut record));
            bytes = 0;
        }
        if record.edges.is_empty() {
            first_edge = k as u64;
        }
        record.first_edge = first_edge;
        record.edges.push(edge.clone());
        bytes += edge.len();
    }
    record.localized = stored.localized.iter().map(Into::into).collect();
    if !record.edges.is_empty() || !record.localized.is_empty() {
        records.push(record);
    }
    out.counts.nodes = stored.nodes.len() as u64;
    out.counts.edges = stored.edges.len() as u64;
    out.counts.solves = stored.solve_points.len() as u64;
    out.counts.spans = stored.localized.len() as u64;
    let first = out.records.len();
    for (k, r) in records.iter().enumerate() {
        let id = RecordId::named(format!("rebuilt/batch/{}", first + k));
        out.records.push((id, r.encode()));
    }
}

/// What a rebuild did.
#[derive(Debug, Serialize)]
pub struct RebuildReport {
    /// The site.
    pub site: String,
    /// The last record of the old log that the store held.
    pub store_sequence: u64,
    /// The old log as found: (first, last, records), `None` if it had none.
    pub old_log: Option<(u64, u64, u64)>,
    /// The new log's first and last sequence.
    pub first_sequence: u64,
    /// Its last.
    pub last_sequence: u64,
    /// Records appended.
    pub records: u64,
    /// What they hold.
    pub holds: Counts,
    /// The lease's holder found (the rebuild took the lease from it).
    pub lease_taken_from: Option<String>,
    /// Seconds, start to end.
    pub seconds: f64,
}

/// Writes `site`'s log anew from `store` on the cluster of `cluster` (this host's
/// `[cluster]`): refused while the site's log holds records, unless `replace`. `progress`
/// hears what is done as it goes.
pub async fn rebuild(
    cluster: &ClusterConfig,
    store: &Store,
    site: &str,
    replace: bool,
    progress: &dyn Fn(&str),
) -> Result<RebuildReport> {
    let started = Instant::now();
    let by = format!("{}-rebuild", cluster.host);
    let built = records_from_store(store, site, &by)?;
    let store_sequence = store.site_log_sequence(site)?;
    let js = super::connect(cluster).await?;
    let old_log = sitelog::log_state(&js, site).await?;
    if let Some((first, last, records)) = old_log.filter(|(_, _, n)| *n > 0)
        && !replace
    {
        bail!(
            "site {site}'s log holds {records} records ({first}–{last}); this store holds its \
             records up to {store_sequence}. Pass --replace to delete that log and write this \
             store's records in its place"
        );
    }
    let leases =
        Arc::new(Leases::open(&js, sitelog::LEASES_BUCKET, cluster.ttl(), cluster.replicas).await?);
    let (lease, taken_from) = take_lease(&leases, site, &by).await?;
    progress(&format!(
        "holding {site}'s lease as {by}{}",
        taken_from
            .as_deref()
            .map(|h| format!(" (taken from {h})"))
            .unwrap_or_default()
    ));
    let (stop, renewing) = tokio::sync::oneshot::channel();
    let renewer = tokio::spawn(renew_until(leases.clone(), lease, renewing));
    let old_last = old_log.map_or(0, |(_, last, _)| last);
    let first_sequence = store_sequence.max(old_last) + REBUILT_GAP;
    let written = write_log(cluster, &js, site, &by, &built, first_sequence, progress).await;
    let _ = stop.send(());
    let held = renewer.await.context("the lease's renewer")?;
    // On a failure the lease is not released: it lapses, and the hosts claim after that.
    let failed = |e: anyhow::Error| {
        anyhow::anyhow!(
            "site {site}: {e:#}. The log may hold part of the rebuild only: run `levelmap \
             site-log rebuild --replace` again"
        )
    };
    let (first_sequence, last_sequence) = written.map_err(failed)?;
    leases.release(held.map_err(failed)?).await?;
    Ok(RebuildReport {
        site: site.to_owned(),
        store_sequence,
        old_log,
        first_sequence,
        last_sequence,
        records: built.records.len() as u64,
        holds: built.counts,
        lease_taken_from: taken_from,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Takes `site`'s lease for `by`: claimed if free, else taken from its holder (whose log is
/// lost: it cannot map the site meanwhile). Tried again while the holder changes under it.
async fn take_lease(leases: &Leases, site: &str, by: &str) -> Result<(Lease, Option<String>)> {
    for _ in 0..10 {
        let holder = leases.holder(site).await?;
        let lease = match &holder {
            None => leases.claim(site, by).await?,
            Some(h) => leases.claim_from(site, by, h).await?,
        };
        if let Some(lease) = lease {
            return Ok((lease, holder));
        }
        tokio::time::sleep(leases.ttl() / 10).await;
    }
    bail!("site {site}'s lease changed hands ten times while it was taken: try again")
}

/// Renews `lease` every third of its time until `stop`; the lease, or the renewal's failure.
async fn renew_until(
    leases: Arc<Leases>,
    mut lease: Lease,
    mut stop: tokio::sync::oneshot::Receiver<()>,
) -> Result<Lease> {
    loop {
        tokio::select! {
            _ = &mut stop => return Ok(lease),
            () = tokio::time::sleep(leases.ttl() / 3) => {
                let bound = leases.ttl() / 3;
                match sitelog::within(bound, leases.renew(&mut lease)).await {
                    Ok(true) => {}
                    Ok(false) => bail!("the site's lease was lost while its log was written"),
                    Err(e) => bail!("the site's lease could not be renewed: {e}"),
                }
            }
        }
    }
}

/// The old log's snapshot and stream gone, the version files put, the records appended to a
/// new stream from `first_sequence`; its first and last sequence.
async fn write_log(
    cluster: &ClusterConfig,
    js: &sitelog::JetStream,
    site: &str,
    by: &str,
    built: &StoreRecords,
    first_sequence: u64,
    progress: &dyn Fn(&str),
) -> Result<(u64, u64)> {
    let replicas = cluster.replicas;
    let snapshots = Snapshots::open(js, super::shelf::SNAPSHOTS_BUCKET, replicas).await?;
    snapshots.delete(site).await?;
    let files = VersionFiles::open(js, super::VERSION_FILES_BUCKET, replicas).await?;
    for (number, file) in &built.files {
        files.put(site, *number, by, file).await?;
    }
    let mut log = new_stream(js, site, replicas, first_sequence).await?;
    progress(&format!(
        "{site}'s log made anew from sequence {first_sequence}: {} records to append",
        built.records.len()
    ));
    let mut expected = first_sequence;
    for (k, (id, bytes)) in built.records.iter().enumerate() {
        let appended = log.append(id, bytes.clone().into()).await?;
        if appended.sequence() != expected {
            bail!(
                "record {id} appended at {} where {expected} was due: another writer appended",
                appended.sequence()
            );
        }
        expected += 1;
        if (k + 1) % 1000 == 0 {
            progress(&format!(
                "{} of {} records appended",
                k + 1,
                built.records.len()
            ));
        }
    }
    // A snapshot shared by the old owner after the first delete is tagged with the old
    // numbers too.
    snapshots.delete(site).await?;
    Ok((first_sequence, expected - 1))
}

/// The site's stream deleted (it held the old log, or was made empty by a host since) and
/// made anew from `first_sequence`; tried again while a host's open makes it in between.
async fn new_stream(
    js: &sitelog::JetStream,
    site: &str,
    replicas: usize,
    first_sequence: u64,
) -> Result<SiteLog> {
    let mut last_error = String::new();
    for _ in 0..10 {
        sitelog::delete_log(js, site).await?;
        let made = SiteLog::create_rebuilt(
            js.clone(),
            site,
            replicas,
            RetryPolicy::default(),
            first_sequence,
        )
        .await;
        match made {
            Ok(log) => {
                let (first, _) = log.bounds().await?;
                if first == first_sequence {
                    return Ok(log);
                }
                last_error = format!("it starts at {first}");
            }
            Err(e) => last_error = e.to_string(),
        }
    }
    bail!("site {site}'s stream could not be made anew from {first_sequence}: {last_error}")
}

#[cfg(test)]
mod tests;
