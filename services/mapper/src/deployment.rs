//! How a mapper is deployed: one write path and one worker either way, and the deployment
//! decides where the journal writes, which fleets are restored at start, and what runs beside
//! the worker. [`Alone`], one machine holding every fleet, is the default; the `cluster`
//! crate deploys the same mapper as one host of a cluster, its sites coming and going with
//! their leases.

use crate::blobs::{Blobs, NotShared};
use crate::bus::feeds::Feeds;
use crate::config::MapperConfig;
use crate::inbox::Work;
use crate::journal::{Journal, StoreJournal};
use crate::localization::MapCache;
use crate::store::Store;
use crate::views::Shared;
use futures_util::future::BoxFuture;
use std::sync::{Arc, mpsc};

/// A mapper's deployment.
pub trait Deployment: Send {
    /// Whether this host holds every fleet from the start: restored from the store, its
    /// feeds declared together. A cluster host holds a site only with its lease, and
    /// declares each site's feeds once it took the site over.
    fn holds_every_fleet(&self) -> bool;

    /// The journal the worker writes through and the blobs the API shares, once the store
    /// is open (called on the mapper's async runtime).
    fn journal(
        &mut self,
        config: &MapperConfig,
        store: &Arc<Store>,
        shared: &Arc<Shared>,
    ) -> (Box<dyn Journal>, Arc<dyn Blobs>);

    /// Starts what runs beside the worker, once it runs.
    fn start(
        self: Box<Self>,
        ends: WorkerEnds,
    ) -> BoxFuture<'static, anyhow::Result<Box<dyn Beside>>>;
}

/// What runs beside the worker (a cluster host's keepers).
pub trait Beside: Send {
    /// Ends it, after the worker stopped: nothing is acked any more.
    fn stop(self: Box<Self>) -> BoxFuture<'static, ()>;
}

/// What a deployment gets of the running mapper.
pub struct WorkerEnds {
    /// The configuration.
    pub config: MapperConfig,
    /// The store (the worker writes it; others read).
    pub store: Arc<Store>,
    /// The views, metrics and instruments.
    pub shared: Arc<Shared>,
    /// The worker's inbox.
    pub work: mpsc::SyncSender<Work>,
    /// Declares a fleet's feeds, which go to the worker.
    pub feeds: Feeds,
    /// The versions' localization maps (shared with the worker and the API).
    pub maps: Arc<MapCache>,
}

/// One machine: every fleet restored at start and journaled to the store; nothing beside
/// the worker.
pub struct Alone;

impl Deployment for Alone {
    fn holds_every_fleet(&self) -> bool {
        true
    }

    fn journal(
        &mut self,
        _config: &MapperConfig,
        store: &Arc<Store>,
        _shared: &Arc<Shared>,
    ) -> (Box<dyn Journal>, Arc<dyn Blobs>) {
        (
            Box::new(StoreJournal::new(store.clone())),
            Arc::new(NotShared),
        )
    }

    fn start(
        self: Box<Self>,
        _ends: WorkerEnds,
    ) -> BoxFuture<'static, anyhow::Result<Box<dyn Beside>>> {
        Box::pin(async { Ok(Box::new(Nothing) as Box<dyn Beside>) })
    }
}

/// Nothing beside the worker.
struct Nothing;

impl Beside for Nothing {
    fn stop(self: Box<Self>) -> BoxFuture<'static, ()> {
        Box::pin(async {})
    }
}
