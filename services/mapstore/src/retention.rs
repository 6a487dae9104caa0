//! Cloud retention (`[clouds]`): a fleet's 3D clouds, for viewing only, are dropped oldest
//! first once older than `max_age_s` or beyond `max_bytes` in all. Pruning runs off the
//! worker, in small write transactions, so the worker's commits interleave with it.

use super::{CLOUDS, Store, StoreError};
use redb::ReadableDatabase;

/// Clouds deleted per write transaction: the worker's commits wait at most one of these.
const PRUNE_BATCH: usize = 256;

/// What one pruning of a fleet did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pruned {
    /// Clouds deleted.
    pub clouds: usize,
    /// Their bytes.
    pub bytes: u64,
    /// Bytes of the fleet's clouds left.
    pub kept_bytes: u64,
}

impl Store {
    /// Deletes `fleet`'s clouds of nodes that `too_old` says are too old, then the oldest
    /// (lowest node index) until the rest fit in `max_bytes` (0: no bound).
    pub fn prune_clouds(
        &self,
        fleet: &str,
        too_old: impl Fn(u64) -> bool,
        max_bytes: u64,
    ) -> Result<Pruned, StoreError> {
        let sizes: Vec<(u64, u64)> = {
            let db = self.db.read().expect("store lock");
            let txn = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
            let table = txn.open_table(CLOUDS)?;
            let mut sizes = Vec::new();
            for entry in table.range((fleet, 0u64)..=(fleet, u64::MAX))? {
                let (k, v) = entry?;
                sizes.push((k.value().1, v.value().len() as u64));
            }
            sizes
        };
        let mut kept_bytes: u64 = sizes.iter().map(|s| s.1).sum();
        let mut doomed = Vec::new();
        for &(node, bytes) in &sizes {
            let over = max_bytes > 0 && kept_bytes > max_bytes;
            if !(over || too_old(node)) {
                continue;
            }
            doomed.push(node);
            kept_bytes -= bytes;
        }
        let freed: u64 = sizes.iter().map(|s| s.1).sum::<u64>() - kept_bytes;
        for batch in doomed.chunks(PRUNE_BATCH) {
            self.write(|db| {
                let txn = db.begin_write()?;
                {
                    let mut table = txn.open_table(CLOUDS)?;
                    for &node in batch {
                        table.remove((fleet, node))?;
                    }
                }
                txn.commit()?;
                Ok(())
            })?;
        }
        Ok(Pruned {
            clouds: doomed.len(),
            bytes: freed,
            kept_bytes,
        })
    }
}
