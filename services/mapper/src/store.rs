//! The durable store (redb, embedded): every accepted node, exactly as received, with the
//! edges it added, committed in one transaction before the node is acked. A restart replays
//! the nodes in their arrival order through the same deterministic mapper, which restores the
//! graph exactly; the stored edges check that it did.

use redb::{Database, ReadableDatabase, ReadableTable, TableDefinition};
use std::path::Path;

/// (fleet, arrival index) → encoded `v1::Node`.
const NODES: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("nodes");
/// (fleet, edge index) → the edge as JSON (`slam::RelativeEdge`).
const EDGES: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("edges");
/// (fleet, arrival index) of each node after which the network was optimized: a replay
/// optimizes at the same points, so it finds the same loop closures.
const SOLVES: TableDefinition<(&str, u64), ()> = TableDefinition::new("solves");

#[derive(Debug, thiserror::Error)]
#[error("store: {0}")]
pub struct StoreError(#[from] redb::Error);

macro_rules! from_redb {
    ($($t:ty),*) => {$(
        impl From<$t> for StoreError {
            fn from(e: $t) -> Self {
                StoreError(e.into())
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

pub struct Store {
    db: Database,
}

/// One fleet as stored.
#[derive(Debug, Default)]
pub struct StoredFleet {
    pub id: String,
    /// Encoded nodes in arrival order.
    pub nodes: Vec<Vec<u8>>,
    /// Edges as JSON, in order.
    pub edges: Vec<Vec<u8>>,
    /// Arrival indices after which the network was optimized, ascending.
    pub solves: Vec<u64>,
}

/// What one batch of work adds to a fleet.
#[derive(Debug, Default)]
pub struct FleetBatch<'a> {
    pub fleet: &'a str,
    /// (arrival index, encoded node).
    pub nodes: Vec<(u64, &'a [u8])>,
    /// Index of the first new edge, and the new edges as JSON.
    pub first_edge: u64,
    pub edges: Vec<Vec<u8>>,
    /// The network was optimized after the node of this arrival index.
    pub solved_after: Option<u64>,
}

impl Store {
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        let db = Database::create(path)?;
        let txn = db.begin_write()?;
        txn.open_table(NODES)?;
        txn.open_table(EDGES)?;
        txn.open_table(SOLVES)?;
        txn.commit()?;
        Ok(Store { db })
    }

    /// Commits a batch (nodes, the edges they added, the solve after them) in one
    /// transaction: durable when this returns.
    pub fn commit(&self, batches: &[FleetBatch<'_>]) -> Result<(), StoreError> {
        let txn = self.db.begin_write()?;
        {
            let mut nodes = txn.open_table(NODES)?;
            let mut edges = txn.open_table(EDGES)?;
            let mut solves = txn.open_table(SOLVES)?;
            for batch in batches {
                for &(arrival, bytes) in &batch.nodes {
                    nodes.insert((batch.fleet, arrival), bytes)?;
                }
                for (k, edge) in batch.edges.iter().enumerate() {
                    edges.insert((batch.fleet, batch.first_edge + k as u64), edge.as_slice())?;
                }
                if let Some(arrival) = batch.solved_after {
                    solves.insert((batch.fleet, arrival), ())?;
                }
            }
        }
        txn.commit()?;
        Ok(())
    }

    /// Every fleet, its nodes in arrival order.
    pub fn load(&self) -> Result<Vec<StoredFleet>, StoreError> {
        let txn = self.db.begin_read()?;
        let mut fleets: Vec<StoredFleet> = Vec::new();
        let fleet_of = |id: &str, fleets: &mut Vec<StoredFleet>| -> usize {
            match fleets.iter().position(|f| f.id == id) {
                Some(i) => i,
                None => {
                    fleets.push(StoredFleet {
                        id: id.to_owned(),
                        ..Default::default()
                    });
                    fleets.len() - 1
                }
            }
        };
        for entry in txn.open_table(NODES)?.iter()? {
            let (k, v) = entry?;
            let i = fleet_of(k.value().0, &mut fleets);
            fleets[i].nodes.push(v.value().to_vec());
        }
        for entry in txn.open_table(EDGES)?.iter()? {
            let (k, v) = entry?;
            let i = fleet_of(k.value().0, &mut fleets);
            fleets[i].edges.push(v.value().to_vec());
        }
        for entry in txn.open_table(SOLVES)?.iter()? {
            let (k, _) = entry?;
            let (fleet, arrival) = k.value();
            let i = fleet_of(fleet, &mut fleets);
            fleets[i].solves.push(arrival);
        }
        Ok(fleets)
    }
}
