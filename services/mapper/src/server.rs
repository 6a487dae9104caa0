//! The mapping server's wiring: the store restored, the Zenoh subscriptions and queryable,
//! the mapping worker's thread, the HTTP listener.
//!
//! A node goes: Zenoh callback → channel → [`crate::worker`] (check, map, commit, ack,
//! publish). Live odometry is handled in its Zenoh callback ([`crate::bus::odometry`]), with no
//! mapping work, so teleoperation sees it at once.

use crate::bus::Bus;
use crate::bus::feeds::{Declared, EVERY_FLEET, Feeds};
use crate::bus::recording::FeedReport;
use crate::config::MapperConfig;
use crate::deployment::{Alone, Beside, Deployment, WorkerEnds};
use crate::inbox::Work;
use crate::localization::MapCache;
use crate::store::Store;
use crate::views::Shared;
use crate::worker::Worker;
use anyhow::{Context, Result};
use runtime::session::now_ns;
use std::sync::Arc;
use std::sync::mpsc;
use std::time::Duration;

/// How long [`Running::stop`] lets open HTTP requests finish.
pub const HTTP_DRAIN: Duration = Duration::from_secs(5);

/// A running mapper: its HTTP address and the handle to stop it.
pub struct Running {
    /// Where the HTTP API listens.
    pub http_addr: std::net::SocketAddr,
    /// What the HTTP side reads: views, live odometry, counters.
    pub shared: Arc<Shared>,
    /// The nodes' clouds, which no view holds (read from the store).
    pub clouds: crate::views::clouds::Clouds,
    session: zenoh::Session,
    http: tokio::task::JoinHandle<()>,
    worker: Option<std::thread::JoinHandle<()>>,
    work: mpsc::SyncSender<Work>,
    fleets: Vec<String>,
    /// What runs beside the worker (a cluster host's keepers), ended after it.
    beside: Option<Box<dyn Beside>>,
}

impl Running {
    /// Re-optimizes a fleet's network now; the optimizer's report as JSON.
    pub async fn optimize(&self, fleet: &str) -> Result<serde_json::Value> {
        Work::optimize(&self.work, fleet)
            .await
            .map_err(|e| anyhow::anyhow!("optimizing fleet {fleet}: {e}"))
    }

    /// Hands a node to the worker as the bus would (`key` its Zenoh key, `payload` its bytes
    /// as sent), waiting while the worker's queue is full: a bench driving the mapper in
    /// compressed time waits, as a file's feed does. Errs once the worker has stopped.
    pub fn feed_node(&self, key: &str, payload: Vec<u8>) -> Result<()> {
        self.work
            .send(Work::node(key, payload))
            .map_err(|_| anyhow::anyhow!("the mapping worker has stopped"))
    }

    /// Feeds the recording at `path` to the worker ([`crate::bus::recording`]) and waits until it
    /// has mapped it, solving where the recorded mapper solved and after the last node.
    pub async fn feed_recording(&self, path: &std::path::Path) -> Result<FeedReport> {
        let (path, work) = (path.to_owned(), self.work.clone());
        let (shared, fleets) = (self.shared.clone(), self.fleets.clone());
        tokio::task::spawn_blocking(move || {
            crate::bus::recording::feed(&path, &work, &shared, &fleets)
        })
        .await?
    }

    /// Stops accepting, ends the event streams, lets the worker finish what it holds, closes
    /// the session. Open HTTP connections get [`HTTP_DRAIN`] to finish.
    pub async fn stop(mut self) -> Result<()> {
        self.shared.stopping.send_replace(true);
        if tokio::time::timeout(HTTP_DRAIN, &mut self.http)
            .await
            .is_err()
        {
            tracing::warn!("HTTP connections still open after {HTTP_DRAIN:?}: closed");
            self.http.abort();
        }
        // The worker stops on this message, not when every sender is gone: requests still
        // in flight on the HTTP side hold senders.
        let _ = self.work.send(Work::Stop);
        drop(self.work);
        let worker = self.worker.take();
        self.session
            .close()
            .await
            .map_err(anyhow::Error::from_boxed)?;
        if let Some(w) = worker {
            tokio::task::spawn_blocking(move || w.join())
                .await?
                .map_err(|_| anyhow::anyhow!("the mapping worker panicked"))?;
        }
        // Nothing is acked any more: a cluster's next hosts may take the sites at once.
        if let Some(beside) = self.beside.take() {
            beside.stop().await;
        }
        Ok(())
    }
}

/// Starts the mapper alone ([`Alone`]): restores the store, opens Zenoh and the HTTP
/// listener. A `[cluster]` configuration is the `cluster` crate's to start.
pub async fn start(config: MapperConfig) -> Result<Running> {
    anyhow::ensure!(
        config.cluster.is_none(),
        "[cluster] is set: a cluster host starts through the cluster deployment (levelmap mapper does so)"
    );
    // Boxed: the start's state is large, and is awaited once.
    Box::pin(start_deployed(config, Box::new(Alone))).await
}

/// Starts the mapper as `deployment` deploys it.
pub async fn start_deployed(
    config: MapperConfig,
    mut deployment: Box<dyn Deployment>,
) -> Result<Running> {
    for fleet in &config.fleets {
        wire::validate_id("fleet", fleet)?;
    }
    let store = Store::open(&config.store_path)
        .with_context(|| format!("{}: cannot open the store", config.store_path.display()))?;
    // The worker writes; the HTTP side reads clouds (redb: readers never wait on the writer).
    let store = Arc::new(store);
    let shared = Arc::new(Shared::new(config.token.clone(), now_ns()));
    // A cluster host's sites come only with their leases, each restored then.
    let every_fleet = deployment.holds_every_fleet();
    let (fleets, snapshots) = match every_fleet {
        true => crate::restore::restore(&config, &store, &shared)?,
        false => Default::default(),
    };
    let maps = Arc::new(MapCache::new(&config.localization, config.max_range_m));
    let localizing = crate::localization::restore(&store, &maps)?;

    let session = config.zenoh.open(runtime::session::Role::Router).await?;
    let (work_tx, work_rx) = mpsc::sync_channel::<Work>(crate::inbox::INGEST_QUEUE);
    // The single writer's journal, and what the API shares beyond the store.
    let (journal, blobs) = deployment.journal(&config, &store, &shared);
    let feeds = Feeds::new(
        session.clone(),
        shared.clone(),
        &config.fleets,
        work_tx.clone(),
    );
    let subscriptions = subscribe(&session, &feeds, every_fleet, &shared).await?;
    let worker = {
        let worker = Worker::new(
            config.clone(),
            fleets,
            localizing,
            shared.clone(),
            Box::new(Bus::new(session.clone())),
            journal,
        )
        .with_snapshots(snapshots);
        std::thread::Builder::new()
            .name("levelmap-mapping".into())
            .spawn(move || {
                // The subscriptions live as long as the worker.
                let _subscriptions = subscriptions;
                worker.run(&work_rx)
            })?
    };

    prune_clouds(config.clouds.clone(), store.clone(), shared.clone());
    if let Some(ros) = &config.ros2_out {
        crate::bus::ros_out::start_when_reachable(
            ros.clone(),
            shared.clone(),
            config.fleets.clone(),
        );
    }
    let ends = WorkerEnds {
        config: config.clone(),
        store: store.clone(),
        shared: shared.clone(),
        work: work_tx.clone(),
        feeds,
        maps: maps.clone(),
    };
    let beside = deployment.start(ends).await?;
    let listener = tokio::net::TcpListener::bind(&config.http_listen)
        .await
        .with_context(|| format!("HTTP: cannot listen on {}", config.http_listen))?;
    let http_addr = listener.local_addr()?;
    let clouds = crate::views::clouds::Clouds::new(store.clone());
    let app = crate::api::router(shared.clone(), work_tx.clone(), store, maps, blobs, &config);
    let http = serve_until_stopped(listener, app, shared.stopping.subscribe());
    Ok(Running {
        http_addr,
        shared,
        clouds,
        session,
        http,
        worker: Some(worker),
        work: work_tx,
        fleets: config.fleets.clone(),
        beside: Some(beside),
    })
}

/// Serves `app` on `listener` until `stopping` turns true, then lets open requests finish.
pub fn serve_until_stopped(
    listener: tokio::net::TcpListener,
    app: axum::Router,
    mut stopping: tokio::sync::watch::Receiver<bool>,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let stopped = async move {
            let _ = stopping.wait_for(|s| *s).await;
        };
        if let Err(e) = axum::serve(listener, app)
            .with_graceful_shutdown(stopped)
            .await
        {
            tracing::error!("HTTP server: {e}");
        }
    })
}

/// What the mapper declares on the bus for as long as the worker runs: every fleet's feeds
/// (when it holds every fleet; a cluster host declares each site's own), the map queryable.
type Subscriptions = (Option<Declared>, zenoh::query::Queryable<()>);

/// Every fleet's feeds when `every_fleet`, and `levelmap/{fleet}/map/*` queries to the
/// current views.
async fn subscribe(
    session: &zenoh::Session,
    feeds: &Feeds,
    every_fleet: bool,
    shared: &Arc<Shared>,
) -> Result<Subscriptions> {
    let declared = match every_fleet {
        true => Some(feeds.declare(EVERY_FLEET).await?),
        false => None,
    };
    let views = shared.clone();
    let queries = session
        .declare_queryable(format!("{}/*/map/*", wire::KEY_ROOT))
        .callback(move |query| crate::bus::answer_map_query(&views, &query))
        .await
        .map_err(anyhow::Error::from_boxed)?;
    Ok((declared, queries))
}

/// Applies the cloud retention policy (`[clouds]`) to every fleet every `prune_every_s`, on
/// the blocking pool, until the mapper stops.
fn prune_clouds(config: crate::config::CloudsConfig, store: Arc<Store>, shared: Arc<Shared>) {
    if config.max_age_s == 0 && config.max_bytes == 0 {
        return;
    }
    let mut stopping = shared.stopping.subscribe();
    tokio::spawn(async move {
        let every = Duration::from_secs(config.prune_every_s.get());
        loop {
            tokio::select! {
                _ = stopping.wait_for(|s| *s) => return,
                _ = tokio::time::sleep(every) => {}
            }
            let (store, shared, config) = (store.clone(), shared.clone(), config.clone());
            let pruned = tokio::task::spawn_blocking(move || {
                let views = shared.views();
                let oldest_ns =
                    now_ns().saturating_sub(config.max_age_s.saturating_mul(1_000_000_000));
                for view in views {
                    let too_old = |node: u64| {
                        config.max_age_s > 0
                            && view
                                .nodes
                                .get(node as usize)
                                .is_some_and(|n| n.stamp_ns < oldest_ns)
                    };
                    match store.prune_clouds(&view.id, too_old, config.max_bytes) {
                        Ok(p) if p.clouds > 0 => {
                            shared
                                .metrics
                                .clouds_pruned
                                .fetch_add(p.clouds as u64, std::sync::atomic::Ordering::Relaxed);
                            tracing::info!(fleet = %view.id, clouds = p.clouds, bytes = p.bytes, kept_bytes = p.kept_bytes, "clouds dropped by [clouds] retention");
                        }
                        Ok(_) => {}
                        Err(e) => tracing::warn!(fleet = %view.id, "cloud retention: {e}"),
                    }
                }
            });
            let _ = pruned.await;
        }
    });
}
