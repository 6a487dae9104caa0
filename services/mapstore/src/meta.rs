//! The store's account of itself: its format number, and for each fleet the mapping version
//! that derived its edges and snapshot. The nodes (with spans, chains, modes, versions) are
//! the record; everything derived from them is derived again when the mapping version that
//! reads the store is not the one that wrote it (`mapper::restore`).
//!
//! Formats:
//! - 0: stores written before the format number (levelmap 0.1.0 up to commit 67c63cc): the
//!   same tables, no `store_meta`, no `fleet_mapping`. Migrated in place to 1 by adding
//!   them; every fleet then has no mapping version, so it is rebuilt from its nodes once.
//! - 1: `store_meta` and `fleet_mapping` added.

use super::{Store, StoreError};
use redb::{ReadableDatabase, ReadableTable, TableDefinition, TableHandle, WriteTransaction};
use serde::{Deserialize, Serialize};

/// The store format this build writes. Raise it (and add the step to `migrate`) when a
/// table's rows change their meaning; a store of a later format is refused.
pub const STORE_FORMAT: u64 = 1;

/// "format" → the store's format number.
pub(super) const STORE_META: TableDefinition<&str, u64> = TableDefinition::new("store_meta");
/// fleet → the [`MappingVersion`] that derived its edges and snapshot, as JSON.
pub(super) const FLEET_MAPPING: TableDefinition<&str, &[u8]> =
    TableDefinition::new("fleet_mapping");

/// What derives a fleet's edges, solves and snapshot from its nodes: the mapping code's
/// version and a digest of the parameters it ran with. Two equal versions map the same
/// nodes to the same network.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MappingVersion {
    /// The mapping code (`fleetmap::MAPPING_CODE`).
    pub code: String,
    /// CRC-32 (hex) of the mapping parameters as JSON (`[mapping]`, the datum, the range).
    pub parameters: String,
}

impl std::fmt::Display for MappingVersion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}, parameters {}", self.code, self.parameters)
    }
}

/// Checks the store's format at open, migrating an older one forward in this transaction;
/// a later format is refused. The tables are made by the caller after this.
pub(super) fn check_format(txn: &WriteTransaction) -> Result<(), StoreError> {
    let had_nodes = txn.list_tables()?.any(|t| t.name() == "nodes");
    let mut meta = txn.open_table(STORE_META)?;
    txn.open_table(FLEET_MAPPING)?;
    let found = meta.get("format")?.map(|v| v.value());
    match found {
        Some(STORE_FORMAT) => {}
        Some(newer) if newer > STORE_FORMAT => {
            return Err(StoreError::Format(format!(
                "store format {newer} was written by a later levelmap; this one reads formats \
                 up to {STORE_FORMAT}: run that release (or a later one) on it"
            )));
        }
        older => {
            let from = older.unwrap_or(0);
            if had_nodes || older.is_some() {
                migrate(from)?;
                tracing::warn!(
                    "store: migrated from format {from} to {STORE_FORMAT}; its fleets are \
                     rebuilt from their nodes"
                );
            }
            meta.insert("format", STORE_FORMAT)?;
        }
    }
    Ok(())
}

/// The steps from format `from` to [`STORE_FORMAT`]. 0 → 1 adds the two meta tables (made
/// by the caller); the rows of the other tables keep their meaning.
fn migrate(from: u64) -> Result<(), StoreError> {
    match from {
        0 => Ok(()),
        other => Err(StoreError::Format(format!(
            "store format {other} is not one levelmap ever wrote"
        ))),
    }
}

impl Store {
    /// The store's format number.
    pub fn format(&self) -> Result<u64, StoreError> {
        let db = self.db.read().expect("store lock");
        let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        let table = txn.open_table(STORE_META)?;
        Ok(table.get("format")?.map_or(0, |v| v.value()))
    }

    /// The mapping version that derived a fleet's edges and snapshot; `None`: not recorded
    /// (a fleet of a format-0 store, or one without rows yet).
    pub fn mapping_version(&self, fleet: &str) -> Result<Option<MappingVersion>, StoreError> {
        let db = self.db.read().expect("store lock");
        let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        let table = txn.open_table(FLEET_MAPPING)?;
        let Some(row) = table.get(fleet)? else {
            return Ok(None);
        };
        serde_json::from_slice(row.value())
            .map(Some)
            .map_err(|e| StoreError::Damaged(format!("fleet {fleet}: its mapping version: {e}")))
    }

    /// Records the mapping version of fleets whose rows it derived (or will derive).
    pub fn set_mapping_version(
        &self,
        fleets: &[&str],
        version: &MappingVersion,
    ) -> Result<(), StoreError> {
        let json = serde_json::to_vec(version).expect("a mapping version serializes");
        self.writing(|db| {
            let txn = db.begin_write()?;
            {
                let mut table = txn.open_table(FLEET_MAPPING)?;
                for fleet in fleets {
                    table.insert(*fleet, json.as_slice())?;
                }
            }
            txn.commit()?;
            Ok(())
        })
    }

    /// Replaces what a fleet's map derives from its nodes, in one transaction: its edges,
    /// its snapshot (removed when `None`) and the mapping version that derived them. Nodes,
    /// spans, solve points, clouds, modes and versions are the record: untouched.
    pub fn put_rebuilt(
        &self,
        fleet: &str,
        edges: &[Vec<u8>],
        snapshot: Option<&[u8]>,
        version: &MappingVersion,
    ) -> Result<(), StoreError> {
        let json = serde_json::to_vec(version).expect("a mapping version serializes");
        self.writing(|db| {
            let txn = db.begin_write()?;
            {
                let mut table = txn.open_table(super::EDGES)?;
                table.retain_in((fleet, 0u64)..=(fleet, u64::MAX), |_, _| false)?;
                for (i, edge) in edges.iter().enumerate() {
                    table.insert((fleet, i as u64), edge.as_slice())?;
                }
                let mut snapshots = txn.open_table(super::SNAPSHOTS)?;
                match snapshot {
                    Some(bytes) => {
                        snapshots.insert(fleet, bytes)?;
                    }
                    None => {
                        snapshots.remove(fleet)?;
                    }
                }
                txn.open_table(FLEET_MAPPING)?
                    .insert(fleet, json.as_slice())?;
            }
            txn.commit()?;
            Ok(())
        })
    }
}
