//! Cluster mode (`[cluster]`, docs/cluster.md): a deployment of the mapper
//! ([`mapper::deployment::Deployment`]) in which the sites (fleets) are spread over mapper
//! hosts, each site's record in a JetStream stream of its own (`sitelog`), one host owning a
//! site at a time through a lease. The mapper is the same one write path and worker; this
//! crate gives it its journal ([`LogJournal`]), its blobs ([`ClusterBlobs`]) and the keepers
//! that bring and take its sites ([`start`]). The mapper does not depend on this crate.
//!
//! Each site has a keeper task on every host (the driver of the state machine in
//! [`ownership`]): while the site's lease
//! is free it claims it (the hosts in the site's rendezvous order, each waiting its rank's
//! stagger), and the site's standby takes it from a holder whose Zenoh liveliness token went
//! (its process is gone); then it takes the site over: the log after what this host's store holds is read
//! into the store (the store is the host's cache of the logs), the newest shared snapshot
//! taken in ([`shelf`]), the map restored from them as a start restores a fleet,
//! the log handed to the host's journal ([`LogJournal`]) and the map to the worker
//! ([`Work::Adopt`]), which from then on journals each of the site's entries to the log
//! before its commit and ack; the keeper then declares the site's feeds
//! (`mapper::bus::feeds`), held while it owns the site. The keeper renews the
//! lease every third of its time to live; a lease claimed by another host (or not renewed
//! for the lease and `renewal_grace_ms`) drops the site at once ([`Work::Drop`]), as does a
//! fenced append in the journal. A lease that lapsed while the bucket did not answer, and
//! that nobody claimed, is claimed again and the site kept.

pub mod record;

mod blobs;
mod copies;
pub mod journal;
mod keeper;
pub mod ownership;
mod presence;
pub mod rebuild;
mod replay;
mod shelf;
mod tokens;

pub use blobs::ClusterBlobs;
pub use journal::{LogInbox, LogJournal};
pub use mapper::config::ClusterConfig;
pub use shelf::{Shelf, Shelved, Shelving, shelf};

use anyhow::{Context, Result};
use futures_util::future::BoxFuture;
use mapper::blobs::Blobs;
use mapper::config::MapperConfig;
use mapper::deployment::{Beside, Deployment};
use mapper::inbox::Work;
use mapper::journal::Journal;
use mapper::store::Store;
use mapper::views::Shared;
use sitelog::{CloudRetention, Clouds, LEASES_BUCKET, Lease, Leases, Snapshots, VersionFiles};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

/// The `[store] snapshot_every_nodes` a cluster host is deployed with
/// (deploy/cluster/mapper-host.toml): a takeover restores from the newest shared snapshot and
/// replays the nodes and solves after it, up to this many (docs/cluster.md).
pub const SNAPSHOT_EVERY_NODES: u64 = 100;

/// The object store of the sites' map version files (`sitelog::VersionFiles`).
pub const VERSION_FILES_BUCKET: &str = "levelmap_site_versions";

/// The cluster side of a running mapper: the keepers and the leases they hold.
pub struct Cluster {
    leases: Arc<Leases>,
    held: Held,
    keepers: Vec<tokio::task::JoinHandle<()>>,
    sharing: tokio::task::JoinHandle<()>,
}

/// How long a graceful stop waits for the last snapshots to be shared before it releases
/// the leases (the next owners restore from them).
const LAST_SNAPSHOTS: Duration = Duration::from_secs(3);

/// A bucket or stream that stays out of reach is logged again this often (it is tried every
/// second).
const REPEAT_WARNING: Duration = Duration::from_secs(30);

/// The leases this host holds, by site.
type Held = Arc<Mutex<HashMap<String, Lease>>>;

/// What the keepers of one host share.
struct Host {
    cluster: ClusterConfig,
    config: MapperConfig,
    js: sitelog::JetStream,
    leases: Arc<Leases>,
    held: Held,
    /// Where a site's log goes to the journal on a takeover.
    logs: journal::LogInbox,
    store: Arc<Store>,
    shared: Arc<Shared>,
    work: mpsc::SyncSender<Work>,
    presence: presence::Presence,
    /// The hosts' Zenoh liveliness tokens: which hosts' processes are gone.
    tokens: tokens::Tokens,
    snapshots: Snapshots,
    /// The files of the versions the sites' logs name.
    version_files: VersionFiles,
    /// The nodes' clouds.
    clouds: Clouds,
    /// The versions' localization maps (shared with the worker and the API).
    maps: Arc<mapper::localization::MapCache>,
    /// Declares the feeds of each site this host owns.
    feeds: mapper::bus::feeds::Feeds,
    /// The log sequence of each site's shared snapshot last looked at (`shelf::take_in`).
    snapshots_seen: Mutex<HashMap<String, u64>>,
}

/// The clouds' stream keeps what `[clouds]` asks a host's store to keep (its byte bound
/// for every site together).
pub fn cloud_retention(clouds: &mapper::config::CloudsConfig) -> CloudRetention {
    CloudRetention {
        max_age: (clouds.max_age_s > 0).then(|| Duration::from_secs(clouds.max_age_s)),
        max_bytes: (clouds.max_bytes > 0).then_some(clouds.max_bytes),
    }
}

/// Starts a mapper host of the cluster `config.cluster` names: connects to NATS (retried in
/// the background until the servers answer), then the mapper with this deployment.
pub async fn start(config: MapperConfig) -> Result<mapper::Running> {
    let cluster = config
        .cluster
        .clone()
        .context("no [cluster] in the configuration")?;
    let js = connect(&cluster).await?;
    // Boxed: the start's state is large, and is awaited once.
    Box::pin(mapper::start_deployed(
        config,
        Box::new(HostDeployment::new(js)),
    ))
    .await
}

/// A mapper host's deployment: its sites' logs as its journal, the cluster's blobs, and the
/// keepers beside the worker.
struct HostDeployment {
    js: sitelog::JetStream,
    /// Made with the journal, handed to the keepers when they start.
    for_keepers: Option<(LogInbox, Shelving)>,
}

impl HostDeployment {
    fn new(js: sitelog::JetStream) -> HostDeployment {
        HostDeployment {
            js,
            for_keepers: None,
        }
    }
}

impl Deployment for HostDeployment {
    fn holds_every_fleet(&self) -> bool {
        false
    }

    fn journal(
        &mut self,
        config: &MapperConfig,
        store: &Arc<Store>,
        shared: &Arc<Shared>,
    ) -> (Box<dyn Journal>, Arc<dyn Blobs>) {
        let cluster = config.cluster.clone().unwrap_or_default();
        let (shelf, shelving) = shelf();
        let runtime = tokio::runtime::Handle::current();
        let mapping_version = mapper::mapping::mapping_version(config).to_string();
        let (journal, logs) = LogJournal::new(
            runtime,
            store.clone(),
            shared.clone(),
            shelf,
            mapping_version,
        );
        self.for_keepers = Some((logs, shelving));
        let retention = cloud_retention(&config.clouds);
        let blobs = ClusterBlobs::new(&cluster.host, self.js.clone(), cluster.replicas, retention);
        (Box::new(journal), Arc::new(blobs))
    }

    fn start(
        self: Box<Self>,
        ends: mapper::deployment::WorkerEnds,
    ) -> BoxFuture<'static, Result<Box<dyn Beside>>> {
        Box::pin(async move {
            let (logs, shelving) = self.for_keepers.context("the journal was not made")?;
            let worker = WorkerEnds {
                work: ends.work,
                logs,
                shelving,
                feeds: ends.feeds,
                maps: ends.maps,
            };
            let cluster =
                Cluster::start(&ends.config, self.js, ends.store, ends.shared, worker).await?;
            Ok(Box::new(cluster) as Box<dyn Beside>)
        })
    }
}

impl Beside for Cluster {
    fn stop(self: Box<Self>) -> BoxFuture<'static, ()> {
        Box::pin(self.release_all())
    }
}

/// Connects to NATS (retried in the background until the servers answer).
pub async fn connect(cluster: &ClusterConfig) -> Result<sitelog::JetStream> {
    cluster.check()?;
    let name = format!("levelmap-mapper-{}", cluster.host);
    Ok(cluster.nats.jetstream(&name).await?)
}

/// The cluster's ends of what it shares with the mapper's worker.
struct WorkerEnds {
    /// The worker's queue (takeovers, drops).
    work: mpsc::SyncSender<Work>,
    /// Where a site's log goes to the worker's journal.
    logs: LogInbox,
    /// The snapshots the worker stored, to share.
    shelving: Shelving,
    /// Declares a site's feeds, which go to the worker.
    feeds: mapper::bus::feeds::Feeds,
    /// The versions' localization maps: a site taken over is handed its modes with them.
    maps: Arc<mapper::localization::MapCache>,
}

impl Cluster {
    /// Starts a keeper for each site of `config.fleets` (each declares its site's feeds
    /// while it owns the site), and the task that shares the snapshots the worker puts on
    /// the shelf.
    async fn start(
        config: &MapperConfig,
        js: sitelog::JetStream,
        store: Arc<Store>,
        shared: Arc<Shared>,
        worker: WorkerEnds,
    ) -> Result<Cluster> {
        let WorkerEnds {
            work,
            logs,
            shelving,
            feeds,
            maps,
        } = worker;
        let cluster = config.cluster.clone().context("no [cluster]")?;
        // The servers may still be starting, or electing: the keepers need both buckets.
        let leases = Arc::new(
            when_reachable("the leases bucket", || {
                Leases::open(&js, LEASES_BUCKET, cluster.ttl(), cluster.replicas)
            })
            .await,
        );
        let snapshots = when_reachable("the snapshots bucket", || {
            Snapshots::open(&js, shelf::SNAPSHOTS_BUCKET, cluster.replicas)
        })
        .await;
        let version_files = when_reachable("the version files bucket", || {
            VersionFiles::open(&js, VERSION_FILES_BUCKET, cluster.replicas)
        })
        .await;
        let retention = cloud_retention(&config.clouds);
        let clouds = when_reachable("the clouds' stream", || {
            Clouds::open(js.clone(), cluster.replicas, retention)
        })
        .await;
        let tokens = tokens::Tokens::declare(feeds.session(), &cluster.host).await?;
        let held = Held::default();
        let host = Arc::new(Host {
            cluster,
            config: config.clone(),
            js,
            leases: leases.clone(),
            held: held.clone(),
            logs,
            store,
            shared,
            work,
            presence: presence::Presence::default(),
            tokens,
            snapshots,
            version_files,
            clouds,
            maps,
            feeds,
            snapshots_seen: Mutex::default(),
        });
        let mut keepers: Vec<_> = config
            .fleets
            .iter()
            .map(|site| tokio::spawn(keeper::keep(host.clone(), site.clone())))
            .collect();
        keepers.push(tokio::spawn(presence::keep_presence(host.clone())));
        keepers.push(tokio::spawn(copies::watch(host.clone())));
        let sharing = tokio::spawn(shelf::share(host, shelving));
        Ok(Cluster {
            leases,
            held,
            keepers,
            sharing,
        })
    }

    /// After the worker stopped: shares its last snapshots (waiting `LAST_SNAPSHOTS` at
    /// most), then gives up every lease held, this host's presence with them, so the next
    /// hosts take the sites over at once rather than after the leases lapse.
    pub async fn release_all(self) {
        for keeper in &self.keepers {
            keeper.abort();
        }
        if tokio::time::timeout(LAST_SNAPSHOTS, self.sharing)
            .await
            .is_err()
        {
            tracing::warn!("cluster: the last snapshots were not all shared in time");
        }
        let held: Vec<Lease> = self
            .held
            .lock()
            .expect("leases lock")
            .drain()
            .map(|(_, l)| l)
            .collect();
        for lease in held {
            let site = lease.site.clone();
            match self.leases.release(lease).await {
                Ok(()) => tracing::info!(site, "lease released"),
                Err(e) => tracing::warn!(site, "lease not released (it lapses): {e}"),
            }
        }
    }
}

/// `open` tried every second until NATS answers; a failure logged when it changes, and
/// every [`REPEAT_WARNING`] while it lasts.
async fn when_reachable<T, F, Opening>(what: &str, open: F) -> T
where
    F: Fn() -> Opening,
    Opening: std::future::Future<Output = Result<T, sitelog::LogError>>,
{
    let mut warned: Option<(String, Instant)> = None;
    loop {
        match open().await {
            Ok(opened) => return opened,
            Err(e) => {
                let why = e.to_string();
                if warned
                    .as_ref()
                    .is_none_or(|(last, at)| *last != why || at.elapsed() >= REPEAT_WARNING)
                {
                    tracing::warn!("cluster: {what} is not reachable yet: {why}");
                    warned = Some((why, Instant::now()));
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}
