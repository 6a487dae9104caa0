//! The mapper's durable store (redb, embedded), a crate of its own: no Tokio, no Zenoh, no
//! HTTP (the mapper re-exports it as `mapper::store`).
//!
//! The store keeps every accepted node, as received but for its segmented cloud, with the
//! edges it added, committed in one transaction before the node is acked. A
//! full replay maps the nodes in their arrival order through the same deterministic mapper,
//! which restores the graph exactly; the stored edges check that it did. Clouds (tens of KB a
//! node, for viewing only) are kept in a table of their own, in the node's transaction, and
//! read one at a time on request: a replay never reads them.
//!
//! A failed commit (a full disk) closes the file: redb wants a database that met an I/O error
//! opened again, which the next commit does. Each fleet is read on its own, so a fleet whose
//! rows are damaged does not keep the others from being restored.
//!
//! A snapshot of each fleet's map (`snapshots`) spares a restart most of the replay: the map
//! is restored from it and the nodes after it are replayed (`mapper::restore`).
//!
//! Map versions and robots' modes are kept in tables of their own. Like every change of a
//! site's record they are written by the mapper's one writer, its worker, through its
//! journal (`mapper::journal`); the HTTP side only reads.

pub use fleetmap::SolvePoint;
use redb::{Database, ReadableDatabase, ReadableTable, TableDefinition, TableHandle};
use std::ops::Bound;
use std::path::Path;
use std::sync::{Mutex, RwLock};

mod backup;
mod changes;
mod forget;
mod localization;
mod meta;
mod retention;
mod versions;
pub use backup::{BackupReport, restore_backup};
pub use changes::SiteChange;
pub use localization::{ModeError, StoredModes};
pub use meta::{MappingVersion, STORE_FORMAT};
pub use retention::Pruned;
pub use versions::{AddVersionError, VersionRows};

/// (fleet, arrival index) → the node as the robot encoded it, without `Node.cloud`
/// ([`wire::split_node_cloud`]).
const NODES: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("nodes");
/// (fleet, edge index) → the edge as JSON (`slam::RelativeEdge`).
const EDGES: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("edges");
/// (fleet, arrival index) of each node after which the network was optimized, by stores
/// before solves ran in the background: read, no longer written.
const SOLVES: TableDefinition<(&str, u64), ()> = TableDefinition::new("solves");
/// (fleet, solve number) → (arrival index of the last node when the solve was taken, of the
/// last node when it was applied): a replay takes and applies each solve at the same points,
/// so it finds the same loop closures.
const SOLVE_POINTS: TableDefinition<(&str, u64), (u64, u64)> = TableDefinition::new("solve_points");
/// (fleet, solve number, k) → the k-th GPS fix of passes over covered ground (JSON,
/// `slam::GpsEdge`) that went into the network when that solve was applied: a replay puts it
/// back there. Stores before it have none.
const PASS_FIXES: TableDefinition<(&str, u64, u64), &[u8]> = TableDefinition::new("pass_fixes");
/// (fleet, node index) → the node's encoded cloud (`Node.cloud`, a `SegmentedCloud`).
const CLOUDS: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("clouds");
/// fleet → the sequence of the last record of its cluster log (the `cluster` crate) this store
/// holds: in cluster mode the store is the host's cache of the log, and a takeover reads
/// the log after it. Written in the transaction of the rows it covers.
const SITE_LOG: TableDefinition<&str, u64> = TableDefinition::new("site_log");
/// fleet → its newest snapshot (`fleetmap::snapshot`): the map after its first nodes,
/// written after they and the solves it holds were committed. Only the newest is kept.
const SNAPSHOTS: TableDefinition<&str, &[u8]> = TableDefinition::new("snapshots");

/// A failure of the store.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// redb's: the disk, the file, a transaction.
    #[error("store: {0}")]
    Redb(#[from] redb::Error),
    /// Closed after a failed commit, until the next commit opens it again.
    #[error("store: closed after a failed commit; the next commit opens it again")]
    Closed,
    /// Rows that do not make a fleet's history (a gap in the indices).
    #[error("store: {0}")]
    Damaged(String),
    /// A store format this build cannot read (`store::STORE_FORMAT`).
    #[error("store: {0}")]
    Format(String),
    /// A backup that could not be written (its file, or a table it does not know).
    #[error("backup: {0}")]
    Backup(String),
}

macro_rules! from_redb {
    ($($t:ty),*) => {$(
        impl From<$t> for StoreError {
            fn from(e: $t) -> Self {
                StoreError::Redb(e.into())
            }
        }
    )*};
}
from_redb!(
    redb::DatabaseError,
    redb::TransactionError,
    redb::TableError,
    redb::StorageError,
    redb::CommitError
);

/// Opens the database (again, after a failed commit).
type Opener = Box<dyn Fn() -> Result<Database, redb::DatabaseError> + Send + Sync>;

/// The mapper's durable store: one redb file.
pub struct Store {
    open: Opener,
    /// `None` after a failed commit, until the next one opens the file again.
    db: RwLock<Option<Database>>,
    /// Held while a version is numbered and written, or deleted: one at a time, so a
    /// number is given once and a fleet's count is what the next one sees.
    versions: Mutex<()>,
}

/// One fleet as stored.
#[derive(Debug, Default)]
pub struct StoredFleet {
    /// The fleet's id.
    pub id: String,
    /// Encoded nodes in arrival order.
    pub nodes: Vec<Vec<u8>>,
    /// Edges as JSON, in order.
    pub edges: Vec<Vec<u8>>,
    /// Arrival indices after which the network was optimized at once (stores before
    /// background solves), ascending.
    pub legacy_solves: Vec<u64>,
    /// The solves, in order.
    pub solve_points: Vec<SolvePoint>,
    /// Passes' GPS fixes by the number of the solve that moved them into the network.
    pub pass_fixes: std::collections::BTreeMap<u64, Vec<slam::GpsEdge>>,
    /// Runs of nodes localized instead of mapped.
    pub localized: Vec<fleetmap::LocalizedSpan>,
}

/// What one batch of work adds to a fleet.
#[derive(Debug, Default)]
pub struct FleetBatch<'a> {
    /// The fleet.
    pub fleet: &'a str,
    /// (arrival index, encoded node without its cloud).
    pub nodes: Vec<(u64, &'a [u8])>,
    /// Who sent each of `nodes`, in their order: (robot, chain, node_seq). The cluster
    /// log names its records by them; the store does not keep them (they are in the nodes).
    pub senders: Vec<(&'a str, u64, u64)>,
    /// (node index, encoded cloud) of the nodes that came with one.
    pub clouds: Vec<(u64, &'a [u8])>,
    /// Index of the first new edge.
    pub first_edge: u64,
    /// The new edges, as JSON ([`encode_edges`]).
    pub edges: Vec<Vec<u8>>,
    /// A solve applied with this batch.
    pub solved: Option<SolvePoint>,
    /// The passes' GPS fixes that solve moved into the network.
    pub pass_fixes: &'a [slam::GpsEdge],
    /// Runs of localized nodes that this batch started or extended.
    pub localized: Vec<fleetmap::LocalizedSpan>,
    /// In cluster mode, the sequence of the batch's last record in the site's log.
    pub log_sequence: Option<u64>,
}

/// Edges as the store keeps them: one JSON document each.
pub fn encode_edges(edges: &[slam::RelativeEdge]) -> Vec<Vec<u8>> {
    edges
        .iter()
        .map(|e| serde_json::to_vec(e).expect("edges serialize"))
        .collect()
}

impl Store {
    /// Opens the store at `path`, made when missing.
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        let path = path.to_owned();
        Store::with_opener(Box::new(move || Database::create(&path)))
    }

    fn with_opener(open: Opener) -> Result<Store, StoreError> {
        let db = RwLock::new(Some(with_tables(open()?)?));
        Ok(Store {
            open,
            db,
            versions: Mutex::new(()),
        })
    }

    /// Commits a batch (nodes, their clouds, the edges they added, the solve after them) in
    /// one transaction: durable when this returns. After a failed commit the file is closed;
    /// the next commit opens it again (redb repairs it then) and may be the same one again:
    /// every row is keyed, so writing it twice stores it once.
    pub fn commit(&self, batches: &[FleetBatch<'_>]) -> Result<(), StoreError> {
        self.writing(|db| write(db, batches))
    }

    /// Runs a write on the database, opened again first if a failed write closed it; a
    /// failed write closes it.
    fn writing(
        &self,
        write: impl FnOnce(&Database) -> Result<(), StoreError>,
    ) -> Result<(), StoreError> {
        if self.db.read().expect("store lock").is_none() {
            *self.db.write().expect("store lock") = Some(with_tables((self.open)()?)?);
        }
        let result = match &*self.db.read().expect("store lock") {
            Some(db) => write(db),
            None => Err(StoreError::Closed),
        };
        if result.is_err() {
            // redb fails every later operation after an I/O error until it is reopened.
            *self.db.write().expect("store lock") = None;
        }
        result
    }

    /// The encoded cloud of a fleet's node, if it came with one.
    pub fn cloud(&self, fleet: &str, node: u64) -> Result<Option<Vec<u8>>, StoreError> {
        let db = self.db.read().expect("store lock");
        let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        let table = txn.open_table(CLOUDS)?;
        Ok(table.get((fleet, node))?.map(|v| v.value().to_vec()))
    }

    /// Replaces a fleet's snapshot (one transaction: the old one stays until it commits).
    pub fn put_snapshot(&self, fleet: &str, snapshot: &[u8]) -> Result<(), StoreError> {
        self.writing(|db| {
            let txn = db.begin_write()?;
            txn.open_table(SNAPSHOTS)?.insert(fleet, snapshot)?;
            txn.commit()?;
            Ok(())
        })
    }

    /// A fleet's newest snapshot, if it has one.
    pub fn snapshot(&self, fleet: &str) -> Result<Option<Vec<u8>>, StoreError> {
        let db = self.db.read().expect("store lock");
        let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        let table = txn.open_table(SNAPSHOTS)?;
        Ok(table.get(fleet)?.map(|v| v.value().to_vec()))
    }

    /// The sequence of the last record of `fleet`'s cluster log this store holds (0: none).
    pub fn site_log_sequence(&self, fleet: &str) -> Result<u64, StoreError> {
        let db = self.db.read().expect("store lock");
        let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        let table = txn.open_table(SITE_LOG)?;
        Ok(table.get(fleet)?.map_or(0, |v| v.value()))
    }

    /// The fleets that have nodes, sorted.
    pub fn fleet_ids(&self) -> Result<Vec<String>, StoreError> {
        let db = self.db.read().expect("store lock");
        let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        let table = txn.open_table(NODES)?;
        let mut ids: Vec<String> = Vec::new();
        let mut next = table.first()?.map(|(k, _)| k.value().0.to_owned());
        while let Some(id) = next {
            // Past this fleet's last possible key: the next fleet's first node.
            let after = (Bound::Excluded((id.as_str(), u64::MAX)), Bound::Unbounded);
            next = match table.range::<(&str, u64)>(after)?.next() {
                Some(entry) => Some(entry?.0.value().0.to_owned()),
                None => None,
            };
            ids.push(id);
        }
        // A fleet whose robots only localized has spans and no node.
        ids.extend(localization::span_fleets(&txn)?);
        ids.sort_unstable();
        ids.dedup();
        Ok(ids)
    }

    /// One fleet, its nodes in arrival order (clouds are not read). Indices must run from 0
    /// without a gap.
    pub fn load_fleet(&self, id: &str) -> Result<StoredFleet, StoreError> {
        let db = self.db.read().expect("store lock");
        let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        let fleet = (id, 0u64)..=(id, u64::MAX);
        let mut stored = StoredFleet {
            id: id.to_owned(),
            ..Default::default()
        };
        for (table, rows) in [(NODES, &mut stored.nodes), (EDGES, &mut stored.edges)] {
            for (i, entry) in txn.open_table(table)?.range(fleet.clone())?.enumerate() {
                let (k, v) = entry?;
                let index = k.value().1;
                if index != i as u64 {
                    return Err(StoreError::Damaged(format!(
                        "fleet {id}: {} row {index} where {i} was due",
                        table.name()
                    )));
                }
                rows.push(v.value().to_vec());
            }
        }
        for entry in txn.open_table(SOLVES)?.range(fleet.clone())? {
            stored.legacy_solves.push(entry?.0.value().1);
        }
        for entry in txn.open_table(SOLVE_POINTS)?.range(fleet)? {
            let (k, v) = entry?;
            let ((_, seq), (taken_after, applied_after)) = (k.value(), v.value());
            if seq != stored.solve_points.len() as u64 {
                return Err(StoreError::Damaged(format!(
                    "fleet {id}: solve {seq} where {} was due",
                    stored.solve_points.len()
                )));
            }
            stored.solve_points.push(SolvePoint {
                seq,
                taken_after,
                applied_after,
            });
        }
        let pass_fixes = match txn.open_table(PASS_FIXES) {
            Ok(table) => Some(table),
            Err(redb::TableError::TableDoesNotExist(_)) => None,
            Err(e) => return Err(e.into()),
        };
        for entry in pass_fixes
            .iter()
            .flat_map(|t| t.range((id, 0u64, 0u64)..=(id, u64::MAX, u64::MAX)))
            .flatten()
        {
            let (k, v) = entry?;
            let (_, seq, k) = k.value();
            let fix: slam::GpsEdge = serde_json::from_slice(v.value()).map_err(|e| {
                StoreError::Damaged(format!("fleet {id}: pass fix {k} of solve {seq}: {e}"))
            })?;
            stored.pass_fixes.entry(seq).or_default().push(fix);
        }
        stored.localized = localization::read_spans(&txn, id)?;
        Ok(stored)
    }
}

/// The database, its tables made when missing.
fn with_tables(db: Database) -> Result<Database, StoreError> {
    let txn = db.begin_write()?;
    meta::check_format(&txn)?;
    txn.open_table(NODES)?;
    txn.open_table(EDGES)?;
    txn.open_table(SOLVES)?;
    txn.open_table(SOLVE_POINTS)?;
    txn.open_table(PASS_FIXES)?;
    txn.open_table(CLOUDS)?;
    txn.open_table(SNAPSHOTS)?;
    txn.open_table(SITE_LOG)?;
    versions::open_tables(&txn)?;
    localization::open_tables(&txn)?;
    txn.commit()?;
    Ok(db)
}

fn write(db: &Database, batches: &[FleetBatch<'_>]) -> Result<(), StoreError> {
    let txn = db.begin_write()?;
    {
        let mut nodes = txn.open_table(NODES)?;
        let mut edges = txn.open_table(EDGES)?;
        let mut solves = txn.open_table(SOLVE_POINTS)?;
        let mut clouds = txn.open_table(CLOUDS)?;
        let mut pass_fixes = txn.open_table(PASS_FIXES)?;
        let mut site_log = txn.open_table(SITE_LOG)?;
        for batch in batches {
            if let Some(sequence) = batch.log_sequence {
                site_log.insert(batch.fleet, sequence)?;
            }
            for &(arrival, bytes) in &batch.nodes {
                nodes.insert((batch.fleet, arrival), bytes)?;
            }
            for &(node, bytes) in &batch.clouds {
                clouds.insert((batch.fleet, node), bytes)?;
            }
            for (k, edge) in batch.edges.iter().enumerate() {
                edges.insert((batch.fleet, batch.first_edge + k as u64), edge.as_slice())?;
            }
            if let Some(point) = batch.solved {
                let at = (point.taken_after, point.applied_after);
                solves.insert((batch.fleet, point.seq), at)?;
                for (k, fix) in batch.pass_fixes.iter().enumerate() {
                    let json = serde_json::to_vec(fix).expect("a GPS edge serializes");
                    pass_fixes.insert((batch.fleet, point.seq, k as u64), json.as_slice())?;
                }
            }
        }
    }
    for batch in batches.iter().filter(|b| !b.localized.is_empty()) {
        localization::write_spans(&txn, batch.fleet, &batch.localized)?;
    }
    txn.commit()?;
    Ok(())
}

/// A store in a fresh folder of its own under the temp dir (the folder, the store): for
/// tests, here and in the crates over the store (feature `testing`).
#[cfg(any(test, feature = "testing"))]
pub fn temp_store(name: &str) -> (std::path::PathBuf, Store) {
    let dir = std::env::temp_dir().join(format!("levelmap-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let store = Store::open(&dir.join("mapper.redb")).expect("a store");
    (dir, store)
}

#[cfg(test)]
mod tests;
