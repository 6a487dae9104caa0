//! Map versions in the store: each version's file exactly as it is exported, its summary
//! apart (a listing reads no file), and per fleet the last number given, so a number is never
//! given twice, even after its version is deleted. A version is never changed once written.

use super::{Store, StoreError};
use redb::{Database, ReadTransaction, ReadableDatabase, ReadableTable, TableDefinition};

/// (fleet, number) → the version's file (a `MapVersionFile`, encoded).
pub(super) const VERSIONS: TableDefinition<(&str, u64), &[u8]> = TableDefinition::new("versions");
/// (fleet, number) → the version's summary, as JSON.
pub(super) const VERSION_SUMMARIES: TableDefinition<(&str, u64), &[u8]> =
    TableDefinition::new("version_summaries");
/// fleet → the last number given in it.
pub(super) const VERSION_NUMBERS: TableDefinition<&str, u64> =
    TableDefinition::new("version_numbers");

/// Makes the tables when missing (with the others, when the store opens).
pub(super) fn open_tables(txn: &redb::WriteTransaction) -> Result<(), StoreError> {
    txn.open_table(VERSIONS)?;
    txn.open_table(VERSION_SUMMARIES)?;
    txn.open_table(VERSION_NUMBERS)?;
    Ok(())
}

/// Writes version `number` of `fleet` (its rows if given: a version whose file is gone
/// keeps its number only) and makes it the last number given, unless a later one was.
pub(super) fn put_version(
    txn: &redb::WriteTransaction,
    fleet: &str,
    number: u64,
    rows: Option<&VersionRows>,
) -> Result<(), StoreError> {
    if let Some(rows) = rows {
        txn.open_table(VERSIONS)?
            .insert((fleet, number), rows.file.as_slice())?;
        txn.open_table(VERSION_SUMMARIES)?
            .insert((fleet, number), rows.summary.as_slice())?;
    }
    let mut numbers = txn.open_table(VERSION_NUMBERS)?;
    let last = numbers.get(fleet)?.map_or(0, |v| v.value());
    numbers.insert(fleet, last.max(number))?;
    Ok(())
}

/// Removes version `number` of `fleet`; whether it was there. Its number is not given again.
pub(super) fn remove_version(
    txn: &redb::WriteTransaction,
    fleet: &str,
    number: u64,
) -> Result<bool, StoreError> {
    let found = txn.open_table(VERSIONS)?.remove((fleet, number))?.is_some();
    txn.open_table(VERSION_SUMMARIES)?.remove((fleet, number))?;
    Ok(found)
}

/// What is stored of one version.
#[derive(Debug)]
pub struct VersionRows {
    /// The file, as exported.
    pub file: Vec<u8>,
    /// Its summary, as JSON.
    pub summary: Vec<u8>,
}

/// Why no version was added.
#[derive(Debug, thiserror::Error)]
pub enum AddVersionError<E> {
    /// The fleet keeps as many versions as it may.
    #[error("fleet {fleet} keeps {max} versions, the most this mapper allows: delete one first")]
    Full {
        /// The fleet.
        fleet: String,
        /// `[versions] max_versions`.
        max: usize,
    },
    /// Making the version's rows failed.
    #[error("{0}")]
    Make(E),
    /// The store failed.
    #[error(transparent)]
    Store(#[from] StoreError),
}

impl Store {
    /// Adds a version to `fleet` under the next number, unless it keeps `max` already:
    /// `make` gets the number and makes the rows (outside any transaction: it may take a
    /// while), then they are written in one transaction. Returns the number. For tests: the
    /// mapper numbers a version with [`Self::next_version_number`] and journals it.
    #[cfg(any(test, feature = "testing"))]
    pub fn add_version<E>(
        &self,
        fleet: &str,
        max: usize,
        make: impl FnOnce(u64) -> Result<VersionRows, E>,
    ) -> Result<u64, AddVersionError<E>> {
        let _one_at_a_time = self.versions.lock().expect("versions lock");
        let (kept, last) = self.version_count(fleet)?;
        if kept >= max {
            return Err(AddVersionError::Full {
                fleet: fleet.to_owned(),
                max,
            });
        }
        let number = last + 1;
        let rows = make(number).map_err(AddVersionError::Make)?;
        self.write(|db| {
            let txn = db.begin_write()?;
            put_version(&txn, fleet, number, Some(&rows))?;
            txn.commit()?;
            Ok(())
        })?;
        Ok(number)
    }

    /// The number `fleet`'s next version gets, unless it keeps `max` versions already.
    pub fn next_version_number<E>(
        &self,
        fleet: &str,
        max: usize,
    ) -> Result<u64, AddVersionError<E>> {
        let (kept, last) = self.version_count(fleet)?;
        if kept >= max {
            return Err(AddVersionError::Full {
                fleet: fleet.to_owned(),
                max,
            });
        }
        Ok(last + 1)
    }

    /// The last number given in `fleet` (0: none), whether its version is kept or deleted.
    pub fn last_version_number(&self, fleet: &str) -> Result<u64, StoreError> {
        Ok(self.version_count(fleet)?.1)
    }

    /// Whether version `number` of `fleet` exists and may be deleted: refused while robots
    /// localize on it.
    pub fn deletable(&self, fleet: &str, number: u64) -> Result<bool, super::ModeError> {
        let users = self.version_users(fleet, number)?;
        if users > 0 {
            return Err(super::ModeError::InUse {
                fleet: fleet.to_owned(),
                version: number,
                robots: users,
            });
        }
        Ok(self.version_summary(fleet, number)?.is_some())
    }

    /// Deletes a version; false when there is none. Its number is not given again. Refused
    /// while robots localize on it (`[super::ModeError::InUse]`). For tests: the mapper
    /// journals a deletion (`Store::apply_site_change`).
    #[cfg(any(test, feature = "testing"))]
    pub fn delete_version(&self, fleet: &str, number: u64) -> Result<bool, super::ModeError> {
        let _one_at_a_time = self.versions.lock().expect("versions lock");
        self.deletable(fleet, number)?;
        Ok(self.write(|db| {
            let txn = db.begin_write()?;
            let found = remove_version(&txn, fleet, number)?;
            txn.commit()?;
            Ok(found)
        })?)
    }

    /// A version's file, as exported.
    pub fn version_file(&self, fleet: &str, number: u64) -> Result<Option<Vec<u8>>, StoreError> {
        let table = self.read_txn()?.open_table(VERSIONS)?;
        Ok(table.get((fleet, number))?.map(|v| v.value().to_vec()))
    }

    /// A version's summary (JSON).
    pub fn version_summary(&self, fleet: &str, number: u64) -> Result<Option<Vec<u8>>, StoreError> {
        let table = self.read_txn()?.open_table(VERSION_SUMMARIES)?;
        Ok(table.get((fleet, number))?.map(|v| v.value().to_vec()))
    }

    /// Every version of a fleet: (number, summary as JSON), oldest first.
    pub fn version_summaries(&self, fleet: &str) -> Result<Vec<(u64, Vec<u8>)>, StoreError> {
        let table = self.read_txn()?.open_table(VERSION_SUMMARIES)?;
        let mut rows = Vec::new();
        for entry in table.range((fleet, 0u64)..=(fleet, u64::MAX))? {
            let (k, v) = entry?;
            rows.push((k.value().1, v.value().to_vec()));
        }
        Ok(rows)
    }

    /// How many versions `fleet` keeps, and the last number given in it.
    fn version_count(&self, fleet: &str) -> Result<(usize, u64), StoreError> {
        let txn = self.read_txn()?;
        let kept = txn
            .open_table(VERSION_SUMMARIES)?
            .range((fleet, 0u64)..=(fleet, u64::MAX))?
            .count();
        let last = txn
            .open_table(VERSION_NUMBERS)?
            .get(fleet)?
            .map_or(0, |v| v.value());
        Ok((kept, last))
    }

    pub(super) fn read_txn(&self) -> Result<ReadTransaction, StoreError> {
        let db = self.db.read().expect("store lock");
        Ok(db.as_ref().ok_or(StoreError::Closed)?.begin_read()?)
    }

    /// Runs a write on the open database (closed after a failed commit: the worker's next
    /// commit opens it again). A failure closes it, as a failed commit does.
    pub(super) fn write<T>(
        &self,
        f: impl FnOnce(&Database) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let result = match &*self.db.read().expect("store lock") {
            Some(db) => f(db),
            None => Err(StoreError::Closed),
        };
        if matches!(result, Err(StoreError::Redb(_))) {
            *self.db.write().expect("store lock") = None;
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(number: u64) -> Result<VersionRows, String> {
        Ok(VersionRows {
            file: vec![number as u8; 3],
            summary: format!("{{\"version\":{number}}}").into_bytes(),
        })
    }

    #[test]
    fn numbers_increase_per_fleet_and_are_never_given_again() {
        let dir = std::env::temp_dir().join(format!("levelmap-versions-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("versions.redb");
        let _ = std::fs::remove_file(&path);
        {
            let store = Store::open(&path).unwrap();
            assert_eq!(store.add_version("park", 3, rows).unwrap(), 1);
            assert_eq!(store.add_version("park", 3, rows).unwrap(), 2);
            assert_eq!(store.add_version("campus", 3, rows).unwrap(), 1);
            assert!(store.delete_version("park", 2).unwrap());
            assert!(!store.delete_version("park", 2).unwrap());
            assert_eq!(store.version_file("park", 2).unwrap(), None);
        }
        let store = Store::open(&path).unwrap();
        // After a delete and a restart, the next number is still new.
        assert_eq!(store.add_version("park", 3, rows).unwrap(), 3);
        assert_eq!(store.version_file("park", 3).unwrap(), Some(vec![3; 3]));
        let listed: Vec<u64> = store
            .version_summaries("park")
            .unwrap()
            .into_iter()
            .map(|(n, _)| n)
            .collect();
        assert_eq!(listed, [1, 3]);
        assert_eq!(
            store.version_summary("campus", 1).unwrap().as_deref(),
            Some(&b"{\"version\":1}"[..])
        );
        // Full: refused, nothing written, no number used.
        assert_eq!(store.add_version("park", 3, rows).unwrap(), 4);
        let full = store.add_version("park", 3, rows).unwrap_err();
        assert!(full.to_string().contains("keeps 3 versions"), "{full}");
        // A version that cannot be made writes nothing; its number is not taken either.
        let failed = store.add_version("campus", 3, |_| Err("no grid".to_owned()));
        assert!(matches!(failed, Err(AddVersionError::Make(e)) if e == "no grid"));
        assert_eq!(store.add_version("campus", 3, rows).unwrap(), 2);
        drop(store);
        std::fs::remove_dir_all(&dir).ok();
    }
}
