//! Each site's newest map snapshot, shared through the object store (`sitelog::Snapshots`),
//! and its nodes' clouds, through the clouds' stream (`sitelog::Clouds`).
//! The owner's worker shelves every snapshot it stores and goes on; one task puts them, one
//! at a time (a snapshot that finds the shelf full is not shared: the next one, as many nodes
//! later, is). Clouds go the same way once their nodes are committed, on a shelf of their
//! own ([`CLOUD_SHELF`]): a cloud that finds it full is not shared (counted), as a cloud is
//! not the record. The site's standby takes the newest one into its own store as it follows the
//! log, and a host taking a site over does so before it restores the map: the restore then
//! starts from the snapshot and replays only the nodes after it.

use super::Host;
use anyhow::Result;
use sitelog::SnapshotTag;
use std::sync::Arc;
use std::time::Instant;
use tokio::sync::mpsc;

/// The object store of the sites' snapshots.
pub const SNAPSHOTS_BUCKET: &str = "levelmap_site_snapshots";

/// Snapshots waiting to be put, at most: each is a whole map (megabytes for a big site).
const SHELF: usize = 2;

/// Clouds waiting to be put, at most (about 60 KB each): a few seconds of a fleet's nodes.
pub const CLOUD_SHELF: usize = 512;

/// A node's cloud on its way to the clouds' stream.
struct ShelvedCloud {
    site: String,
    node: u64,
    cloud: bytes::Bytes,
}

/// A snapshot on its way to the object store.
pub struct Shelved {
    /// The site it maps.
    pub site: String,
    /// What it covers.
    pub tag: SnapshotTag,
    /// The snapshot, as `fleetmap` wrote it.
    pub bytes: Vec<u8>,
}

/// The worker's end of the shelf.
pub struct Shelf {
    snapshots: mpsc::Sender<Shelved>,
    clouds: mpsc::Sender<ShelvedCloud>,
}

/// The sharing task's end of the shelf.
pub struct Shelving {
    snapshots: mpsc::Receiver<Shelved>,
    clouds: mpsc::Receiver<ShelvedCloud>,
}

/// A shelf, empty.
pub fn shelf() -> (Shelf, Shelving) {
    let (snapshots, snapshots_in) = mpsc::channel(SHELF);
    let (clouds, clouds_in) = mpsc::channel(CLOUD_SHELF);
    let shelf = Shelf { snapshots, clouds };
    let shelving = Shelving {
        snapshots: snapshots_in,
        clouds: clouds_in,
    };
    (shelf, shelving)
}

impl Shelf {
    /// Hands node `node`'s cloud of `site` to the sharing task without waiting; false when
    /// the shelf is full (the cloud is not shared).
    pub fn shelve_cloud(&self, site: &str, node: u64, cloud: &[u8]) -> bool {
        let shelved = ShelvedCloud {
            site: site.to_owned(),
            node,
            cloud: bytes::Bytes::copy_from_slice(cloud),
        };
        self.clouds.try_send(shelved).is_ok()
    }

    /// Hands `shelved` to the sharing task without waiting.
    pub fn shelve(&self, shelved: Shelved) {
        if let Err(mpsc::error::TrySendError::Full(s)) = self.snapshots.try_send(shelved) {
            tracing::warn!(
                site = s.site,
                nodes = s.tag.nodes,
                "snapshot not shared: the ones before it are still being put"
            );
        }
    }
}

/// Puts the shelved snapshots in the object store, and the clouds in their stream, until
/// the worker stops shelving.
pub(super) async fn share(host: Arc<Host>, shelving: Shelving) {
    let Shelving {
        mut snapshots,
        clouds,
    } = shelving;
    let clouds = tokio::spawn(share_clouds(host.clone(), clouds));
    while let Some(s) = snapshots.recv().await {
        let started = Instant::now();
        match host.snapshots.put(&s.site, &s.tag, &s.bytes).await {
            Ok(()) => {
                host.shared.instruments.snapshots_shared.inc();
                tracing::info!(
                    site = s.site,
                    nodes = s.tag.nodes,
                    log_sequence = s.tag.log_sequence,
                    bytes = s.bytes.len(),
                    "snapshot shared in {:.0} ms",
                    started.elapsed().as_secs_f64() * 1e3
                );
            }
            // The one before it stays usable; the next one comes as many nodes later.
            Err(e) => tracing::warn!(site = s.site, "snapshot not shared: {e}"),
        }
    }
    let _ = clouds.await;
}

/// Puts the shelved clouds in the clouds' stream, one at a time.
async fn share_clouds(host: Arc<Host>, mut clouds: mpsc::Receiver<ShelvedCloud>) {
    let instruments = &host.shared.instruments;
    while let Some(c) = clouds.recv().await {
        match host.clouds.put(&c.site, c.node, c.cloud).await {
            Ok(()) => {
                instruments.clouds_shared.inc();
            }
            Err(e) => {
                instruments.clouds_unshared.inc();
                tracing::debug!(site = c.site, node = c.node, "cloud not shared: {e}");
            }
        }
    }
}

/// Takes `site`'s shared snapshot into this host's store if it is of the running mapping
/// version, covers more nodes and solves than the store's own, and the store holds every
/// record it covers (else it is looked at again next time). A snapshot that does not fit the stored
/// nodes after all is refused by the restore, which then replays them.
pub(super) async fn take_in(host: &Arc<Host>, site: &str) -> Result<()> {
    let Some(tag) = host.snapshots.tag(site).await? else {
        return Ok(());
    };
    let seen = host.snapshots_seen.lock().expect("seen lock").get(site) == Some(&tag.log_sequence);
    if seen {
        return Ok(());
    }
    let (store, name) = (host.store.clone(), site.to_owned());
    let (have, local_work) = tokio::task::spawn_blocking(move || -> Result<(u64, u64)> {
        let local = store.snapshot(&name)?;
        let covers = local.and_then(|b| fleetmap::FleetMap::snapshot_covers(&b).ok());
        let work = covers.map_or(0, |c| c.nodes + c.solves);
        Ok((store.site_log_sequence(&name)?, work))
    })
    .await??;
    if have < tag.log_sequence {
        return Ok(());
    }
    // Newer: more of what a restore would otherwise replay (nodes and solves).
    let running = mapper::mapping::mapping_version(&host.config).to_string();
    if tag.mapping_version == running && tag.nodes + tag.solves > local_work {
        let Some((tag, bytes)) = host.snapshots.get(site).await? else {
            return Ok(());
        };
        if have < tag.log_sequence || tag.mapping_version != running {
            // Replaced since its tag was read: looked at again next time.
            return Ok(());
        }
        let (store, name, size) = (host.store.clone(), site.to_owned(), bytes.len());
        tokio::task::spawn_blocking(move || store.put_snapshot(&name, &bytes)).await??;
        host.shared.instruments.snapshots_taken_in.inc();
        tracing::info!(
            site,
            nodes = tag.nodes,
            log_sequence = tag.log_sequence,
            bytes = size,
            "cluster: the site's shared snapshot taken into this host's store"
        );
    }
    host.snapshots_seen
        .lock()
        .expect("seen lock")
        .insert(site.to_owned(), tag.log_sequence);
    Ok(())
}
