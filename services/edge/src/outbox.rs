//! The on-disk outbox: every node stays in it, committed, from the moment it is made until the
//! mapper's ack covers it, so neither a radio outage nor a crash of either side loses one.
//! The newest acked nodes stay too, up to a count ([`Outbox::keeping_acked`]): a mapper
//! started from a backup asks for the nodes it acked after the backup, and gets them.

use redb::{Database, ReadableDatabase, ReadableTable, ReadableTableMetadata, TableDefinition};
use std::path::Path;

/// Nodes by node_seq, encoded once, here ([`wire::NodeParts::encode`]).
const NODES: TableDefinition<u64, &[u8]> = TableDefinition::new("nodes");
/// `format` ([`OUTBOX_FORMAT`]), `next_node_seq` (the next number to give), `acked`
/// (highest node_seq acked + 1) and `chain_id` (drawn when the outbox is made:
/// `Node.chain_id`).
const META: TableDefinition<&str, u64> = TableDefinition::new("meta");
/// Nodes the robot made but must not send (they fail the wire's checks), with why, by
/// arrival; they take no node_seq, so they never block the nodes after them.
const QUARANTINE: TableDefinition<u64, (&str, &[u8])> = TableDefinition::new("quarantine");

/// The outbox's format, kept in `meta` as `format`: what a later release reads to know how
/// the nodes were written. An outbox without one is format 0 (the releases before the
/// number; the same tables and encoding), which this release reads and marks as 1.
pub const OUTBOX_FORMAT: u64 = 1;

/// A failure of the outbox's file (redb), or an outbox this release cannot read.
#[derive(Debug, thiserror::Error)]
pub enum OutboxError {
    /// The file or its tables.
    #[error("outbox: {0}")]
    Store(#[from] redb::Error),
    /// Written by a later release: left as it is, for that release to send.
    #[error(
        "outbox: format {found}, written by a later release (this one reads up to \
         {OUTBOX_FORMAT}); its nodes are kept: run the release that wrote it"
    )]
    Newer {
        /// The outbox's format.
        found: u64,
    },
}

macro_rules! from_redb {
    ($($t:ty),*) => {$(
        impl From<$t> for OutboxError {
            fn from(e: $t) -> Self {
                OutboxError::Store(e.into())
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

/// The robot's nodes not acked yet (and the newest acked ones), on disk (redb), and the node
/// numbering.
pub struct Outbox {
    db: Database,
    /// Acked nodes kept, newest first, for a mapper that asks for them again.
    keep_acked: u64,
}

impl Outbox {
    /// Opens the outbox at `path`, creating it (and its tables) if needed.
    pub fn open(path: &Path) -> Result<Outbox, OutboxError> {
        let db = Database::create(path)?;
        let txn = db.begin_write()?;
        txn.open_table(NODES)?;
        txn.open_table(QUARANTINE)?;
        {
            let mut meta = txn.open_table(META)?;
            let format = meta.get("format")?.map(|v| v.value());
            match format {
                Some(found) if found > OUTBOX_FORMAT => return Err(OutboxError::Newer { found }),
                Some(OUTBOX_FORMAT) => {}
                // New, or format 0: the same tables, now numbered.
                _ => {
                    meta.insert("format", OUTBOX_FORMAT)?;
                }
            }
            if meta.get("chain_id")?.is_none() {
                // An outbox from before chains that already numbered nodes keeps chain 0 (the
                // mapper's legacy chain), so its numbering still fits what the mapper took.
                let numbered = meta.get("next_node_seq")?.is_some_and(|v| v.value() > 0);
                let chain_id = if numbered { 0 } else { new_chain_id() };
                meta.insert("chain_id", chain_id)?;
            }
        }
        txn.commit()?;
        Ok(Outbox { db, keep_acked: 0 })
    }

    /// Keeps the newest `nodes` acked nodes (the older ones go at the next ack).
    pub fn keeping_acked(self, nodes: u64) -> Outbox {
        Outbox {
            keep_acked: nodes,
            ..self
        }
    }

    /// The outbox's format ([`OUTBOX_FORMAT`] once opened by this release).
    pub fn format(&self) -> Result<u64, OutboxError> {
        self.meta("format")
    }

    /// The chain this outbox's nodes belong to (`Node.chain_id`).
    pub fn chain_id(&self) -> Result<u64, OutboxError> {
        self.meta("chain_id")
    }

    /// Keeps a node that must not be sent, with why (it takes no node_seq).
    pub fn quarantine(&self, reason: &str, node: &wire::NodeParts) -> Result<(), OutboxError> {
        self.quarantine_encoded(reason, &node.encode())
    }

    fn quarantine_encoded(&self, reason: &str, encoded: &[u8]) -> Result<(), OutboxError> {
        let txn = self.db.begin_write()?;
        {
            let mut table = txn.open_table(QUARANTINE)?;
            let next = table.last()?.map_or(0, |(k, _)| k.value() + 1);
            table.insert(next, (reason, encoded))?;
        }
        txn.commit()?;
        Ok(())
    }

    /// Nodes in quarantine.
    pub fn quarantined(&self) -> Result<u64, OutboxError> {
        let txn = self.db.begin_read()?;
        Ok(txn.open_table(QUARANTINE)?.len()?)
    }

    fn meta(&self, key: &str) -> Result<u64, OutboxError> {
        let txn = self.db.begin_read()?;
        let table = txn.open_table(META)?;
        Ok(table.get(key)?.map_or(0, |v| v.value()))
    }

    /// The node_seq the next node gets: numbering survives restarts, acked nodes included.
    pub fn next_node_seq(&self) -> Result<u64, OutboxError> {
        self.meta("next_node_seq")
    }

    /// Nodes below this are acked.
    pub fn acked_below(&self) -> Result<u64, OutboxError> {
        self.meta("acked")
    }

    /// Commits `node` (its node_seq must be [`Self::next_node_seq`]), encoded: the one
    /// encoding of a node, which every send of it appends its send fields to.
    pub fn push(&self, node: &wire::Node) -> Result<(), OutboxError> {
        self.push_encoded(node.node_seq, &node.encode())
    }

    fn push_encoded(&self, node_seq: u64, encoded: &[u8]) -> Result<(), OutboxError> {
        let txn = self.db.begin_write()?;
        {
            let mut nodes = txn.open_table(NODES)?;
            nodes.insert(node_seq, encoded)?;
            let mut meta = txn.open_table(META)?;
            meta.insert("next_node_seq", node_seq + 1)?;
        }
        txn.commit()?;
        Ok(())
    }

    /// Marks every node up to and including `acked_node_seq` acked and drops the acked ones
    /// beyond those kept; returns how many went. An ack below the mark changes nothing.
    pub fn ack(&self, acked_node_seq: u64) -> Result<usize, OutboxError> {
        if acked_node_seq < self.acked_below()? {
            return Ok(0);
        }
        let acked = acked_node_seq + 1;
        let txn = self.db.begin_write()?;
        let removed;
        {
            let mut nodes = txn.open_table(NODES)?;
            let kept_from = acked.saturating_sub(self.keep_acked);
            let mut gone = nodes.extract_from_if(..kept_from, |_, _| true)?;
            let mut n = 0;
            for entry in gone.by_ref() {
                entry?;
                n += 1;
            }
            drop(gone);
            removed = n;
            let mut meta = txn.open_table(META)?;
            meta.insert("acked", acked)?;
        }
        txn.commit()?;
        Ok(removed)
    }

    /// The oldest node the outbox still holds, acked or not (`Node.held_from_seq`): what a
    /// mapper may ask for again.
    pub fn held_from(&self) -> Result<u64, OutboxError> {
        let acked = self.acked_below()?;
        let txn = self.db.begin_read()?;
        let first = txn.open_table(NODES)?.first()?.map(|(k, _)| k.value());
        Ok(first.map_or(acked, |f| f.min(acked)))
    }

    /// Up to `limit` nodes from `from_seq` on, in order (acked ones kept included, when
    /// `from_seq` is below [`Self::acked_below`]).
    pub fn pending(&self, from_seq: u64, limit: usize) -> Result<Vec<(u64, Vec<u8>)>, OutboxError> {
        let txn = self.db.begin_read()?;
        let nodes = txn.open_table(NODES)?;
        let mut out = Vec::new();
        for entry in nodes.range(from_seq..)?.take(limit) {
            let (k, v) = entry?;
            out.push((k.value(), v.value().to_vec()));
        }
        Ok(out)
    }

    /// Nodes waiting for their ack.
    pub fn len(&self) -> Result<u64, OutboxError> {
        let acked = self.acked_below()?;
        let txn = self.db.begin_read()?;
        let nodes = txn.open_table(NODES)?;
        let mut n = 0;
        for entry in nodes.range(acked..)? {
            entry?;
            n += 1;
        }
        Ok(n)
    }

    /// Whether every node is acked.
    pub fn is_empty(&self) -> Result<bool, OutboxError> {
        Ok(self.len()? == 0)
    }
}

/// A chain id no other outbox of the robot has drawn: std's `RandomState` is seeded from the
/// OS's random source, mixed with the time and process. 53 bits, so that JSON readers (the
/// dashboard's JavaScript) keep it exact; never 0 (the legacy chain).
fn new_chain_id() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u64(runtime::session::now_ns());
    hasher.write_u32(std::process::id());
    (hasher.finish() >> 11).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scratch folder for `name`'s test and the path of a fresh outbox in it.
    fn scratch(name: &str) -> (std::path::PathBuf, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("levelmap-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("outbox.redb");
        let _ = std::fs::remove_file(&path);
        (dir, path)
    }

    #[test]
    fn nodes_stay_until_acked_and_survive_reopening() {
        let (dir, path) = scratch("outbox");
        let chain_id;
        {
            let outbox = Outbox::open(&path).unwrap();
            chain_id = outbox.chain_id().unwrap();
            assert_ne!(chain_id, 0);
            assert_eq!(outbox.next_node_seq().unwrap(), 0);
            outbox
                .quarantine_encoded("implausible_range", b"bad")
                .unwrap();
            for seq in 0..5 {
                outbox.push_encoded(seq, &[seq as u8; 3]).unwrap();
            }
            assert_eq!(outbox.ack(1).unwrap(), 2);
            // An old ack changes nothing.
            assert_eq!(outbox.ack(0).unwrap(), 0);
        }
        let outbox = Outbox::open(&path).unwrap();
        assert_eq!(
            outbox.chain_id().unwrap(),
            chain_id,
            "the chain survives a restart"
        );
        assert_eq!(outbox.quarantined().unwrap(), 1);
        assert_eq!(outbox.next_node_seq().unwrap(), 5);
        assert_eq!(outbox.acked_below().unwrap(), 2);
        let pending = outbox.pending(0, 10).unwrap();
        let seqs: Vec<u64> = pending.iter().map(|p| p.0).collect();
        assert_eq!(seqs, [2, 3, 4]);
        assert_eq!(pending[0].1, [2, 2, 2]);
        assert_eq!(outbox.pending(3, 1).unwrap()[0].0, 3);
        assert_eq!(outbox.ack(4).unwrap(), 3);
        assert!(outbox.is_empty().unwrap());
        // A new outbox (a wiped one) is a new chain.
        drop(outbox);
        std::fs::remove_file(&path).unwrap();
        let fresh = Outbox::open(&path).unwrap();
        assert_ne!(fresh.chain_id().unwrap(), chain_id);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A mapper started from a backup asks again for nodes it acked after the backup: the
    /// newest acked ones are kept for it, and older ones go.
    #[test]
    fn the_newest_acked_nodes_are_kept_for_a_mapper_that_asks_again() {
        let (dir, path) = scratch("outbox-keep");
        let outbox = Outbox::open(&path).unwrap().keeping_acked(2);
        for seq in 0..6 {
            outbox.push_encoded(seq, &[seq as u8]).unwrap();
        }
        assert_eq!(outbox.held_from().unwrap(), 0);
        assert_eq!(outbox.ack(3).unwrap(), 2, "0 and 1 go; 2 and 3 are kept");
        assert_eq!(outbox.held_from().unwrap(), 2);
        assert_eq!(outbox.acked_below().unwrap(), 4);
        assert_eq!(outbox.len().unwrap(), 2, "only 4 and 5 wait for an ack");
        let seqs: Vec<u64> = outbox.pending(2, 10).unwrap().iter().map(|p| p.0).collect();
        assert_eq!(seqs, [2, 3, 4, 5]);
        assert_eq!(outbox.ack(1).unwrap(), 0, "an older ack changes nothing");
        assert_eq!(outbox.acked_below().unwrap(), 4);
        assert_eq!(outbox.ack(5).unwrap(), 2);
        assert_eq!(outbox.held_from().unwrap(), 4);
        assert!(outbox.is_empty().unwrap());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_outbox_of_a_later_format_is_refused_and_left_as_it_is() {
        let (dir, path) = scratch("outbox-new");
        {
            let outbox = Outbox::open(&path).unwrap();
            outbox.push_encoded(0, b"node").unwrap();
            let txn = outbox.db.begin_write().unwrap();
            txn.open_table(META)
                .unwrap()
                .insert("format", OUTBOX_FORMAT + 1)
                .unwrap();
            txn.commit().unwrap();
        }
        let e = Outbox::open(&path)
            .err()
            .expect("a later format is refused");
        assert!(
            matches!(e, OutboxError::Newer { found } if found == OUTBOX_FORMAT + 1),
            "{e}"
        );
        assert!(e.to_string().contains("later release"), "{e}");
        // Nothing was changed: the node is still there for the release that wrote it.
        let db = Database::create(&path).unwrap();
        let txn = db.begin_read().unwrap();
        assert_eq!(txn.open_table(NODES).unwrap().len().unwrap(), 1);
        drop(txn);
        drop(db);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
