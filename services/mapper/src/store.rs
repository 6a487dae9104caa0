//! The durable store (redb, embedded): every accepted node, as received but for its segmented
//! cloud, with the edges it added, committed in one transaction before the node is acked. A
//! restart replays the nodes in their arrival order through the same deterministic mapper,
//! which restores the graph exactly; the stored edges check that it did. Clouds (tens of KB a
//! node, for viewing only) are kept in a table of their own, in the node's transaction, and
//! read one at a time on request: a replay never reads them.

use redb::{Database, ReadableDatabase, ReadableTable, TableDefinition};
use std::path::Path;
use wire::{Message, v1};

/// (fleet, arrival index) → encoded `v1::Node`, without `Node.cloud`.
const NODES: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("nodes");
/// (fleet, edge index) → the edge as JSON (`slam::RelativeEdge`).
const EDGES: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("edges");
/// (fleet, arrival index) of each node after which the network was optimized: a replay
/// optimizes at the same points, so it finds the same loop closures.
const SOLVES: TableDefinition<(&str, u64), ()> = TableDefinition::new("solves");
/// (fleet, node index) → the node's encoded `v1::SegmentedCloud` (`Node.cloud`).
const CLOUDS: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("clouds");

/// A failure of the store (redb): the disk, the file, a transaction.
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

/// The mapper's durable store: one redb file.
pub struct Store {
    db: Database,
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
    /// Arrival indices after which the network was optimized, ascending.
    pub solves: Vec<u64>,
}

/// What one batch of work adds to a fleet.
#[derive(Debug, Default)]
pub struct FleetBatch<'a> {
    /// The fleet.
    pub fleet: &'a str,
    /// (arrival index, encoded node without its cloud).
    pub nodes: Vec<(u64, &'a [u8])>,
    /// (node index, encoded cloud) of the nodes that came with one.
    pub clouds: Vec<(u64, &'a [u8])>,
    /// Index of the first new edge.
    pub first_edge: u64,
    /// The new edges, as JSON ([`encode_edges`]).
    pub edges: Vec<Vec<u8>>,
    /// The network was optimized after the node of this arrival index.
    pub solved_after: Option<u64>,
}

/// Edges as the store keeps them: one JSON document each.
pub fn encode_edges(edges: &[slam::RelativeEdge]) -> Vec<Vec<u8>> {
    edges
        .iter()
        .map(|e| serde_json::to_vec(e).expect("edges serialize"))
        .collect()
}

/// What is stored of a received node (`payload`, decoded as `node`): the node without its
/// cloud (the payload itself when it has none) and the encoded cloud, taken out of `node`.
pub fn split_cloud(node: &mut v1::Node, payload: Vec<u8>) -> (Vec<u8>, Option<Vec<u8>>) {
    match node.cloud.take() {
        Some(cloud) => (node.encode_to_vec(), Some(cloud.encode_to_vec())),
        None => (payload, None),
    }
}

impl Store {
    /// Opens the store at `path`, made when missing.
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        let db = Database::create(path)?;
        let txn = db.begin_write()?;
        txn.open_table(NODES)?;
        txn.open_table(EDGES)?;
        txn.open_table(SOLVES)?;
        txn.open_table(CLOUDS)?;
        txn.commit()?;
        Ok(Store { db })
    }

    /// Commits a batch (nodes, their clouds, the edges they added, the solve after them) in
    /// one transaction: durable when this returns.
    pub fn commit(&self, batches: &[FleetBatch<'_>]) -> Result<(), StoreError> {
        let txn = self.db.begin_write()?;
        {
            let mut nodes = txn.open_table(NODES)?;
            let mut edges = txn.open_table(EDGES)?;
            let mut solves = txn.open_table(SOLVES)?;
            let mut clouds = txn.open_table(CLOUDS)?;
            for batch in batches {
                for &(arrival, bytes) in &batch.nodes {
                    nodes.insert((batch.fleet, arrival), bytes)?;
                }
                for &(node, bytes) in &batch.clouds {
                    clouds.insert((batch.fleet, node), bytes)?;
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

    /// The encoded cloud of a fleet's node, if it came with one.
    pub fn cloud(&self, fleet: &str, node: u64) -> Result<Option<Vec<u8>>, StoreError> {
        let txn = self.db.begin_read()?;
        let table = txn.open_table(CLOUDS)?;
        Ok(table.get((fleet, node))?.map(|v| v.value().to_vec()))
    }

    /// Every fleet, its nodes in arrival order (clouds are not read).
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_node_is_stored_without_its_cloud() {
        let cloud = v1::SegmentedCloud {
            xyz_cm: vec![100, -200, 30],
            classes: vec![2],
            source_points: 10,
            voxel_m: 0.1,
            max_points: 6000,
        };
        let mut node = v1::Node {
            node_seq: 7,
            cloud: Some(cloud.clone()),
            ..Default::default()
        };
        let payload = node.encode_to_vec();
        let (stored, apart) = split_cloud(&mut node, payload.clone());
        assert!(node.cloud.is_none());
        let back = v1::Node::decode(stored.as_slice()).unwrap();
        assert_eq!((back.node_seq, back.cloud), (7, None));
        assert!(stored.len() < payload.len());
        let apart = v1::SegmentedCloud::decode(apart.unwrap().as_slice()).unwrap();
        assert_eq!(apart, cloud);
        // Without a cloud: the payload as received.
        assert_eq!(split_cloud(&mut node, stored.clone()), (stored, None));
    }

    #[test]
    fn clouds_are_kept_apart_and_survive_reopening() {
        let dir = std::env::temp_dir().join(format!("levelmap-store-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("clouds.redb");
        let _ = std::fs::remove_file(&path);
        {
            let store = Store::open(&path).unwrap();
            store
                .commit(&[FleetBatch {
                    fleet: "park",
                    nodes: vec![(0, b"node0"), (1, b"node1")],
                    clouds: vec![(1, b"cloud1")],
                    ..Default::default()
                }])
                .unwrap();
        }
        let store = Store::open(&path).unwrap();
        assert_eq!(
            store.cloud("park", 1).unwrap().as_deref(),
            Some(&b"cloud1"[..])
        );
        assert_eq!(store.cloud("park", 0).unwrap(), None);
        assert_eq!(store.cloud("campus", 1).unwrap(), None);
        // The replay reads the nodes alone.
        let fleets = store.load().unwrap();
        assert_eq!(fleets.len(), 1);
        assert_eq!(fleets[0].nodes, [b"node0".to_vec(), b"node1".to_vec()]);
        drop(store);
        std::fs::remove_dir_all(&dir).ok();
    }
}
