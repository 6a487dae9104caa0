//! Changes of a site's versions and modes, as the writer journals them
//! (`mapper::journal`): stored here on a single machine; in cluster mode the owner appends
//! one to the site's log (the `cluster` crate's `record`) and then stores it here, and a standby
//! or a new owner reads it from the log and stores it the same way. Storing one twice
//! stores it once, and the site's log sequence only ever moves forward.

use super::{SITE_LOG, Store, StoreError, VersionRows, localization, versions};
use redb::ReadableTable;
use serde::{Deserialize, Serialize};

/// A change of a site's versions or modes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum SiteChange {
    /// Version `number` added; its file is in the cluster's version files.
    VersionAdded {
        /// Its number in the site.
        number: u64,
        /// Its summary, as JSON.
        summary: Vec<u8>,
        /// The host that put its file (`sitelog::VersionFiles` names files by it).
        host: String,
    },
    /// Version `number` deleted.
    VersionDeleted {
        /// Its number.
        number: u64,
    },
    /// Robots set to localize on a version, or to map.
    ModesSet {
        /// The robots, or `None` for the fleet's setting.
        robots: Option<Vec<String>>,
        /// The version (0: map).
        version: u64,
    },
}

impl Store {
    /// Stores `change` of `fleet` (in cluster mode the record at `sequence` of its log, in
    /// one transaction with that sequence). `file` is an added version's file (`None`:
    /// deleted since; the number is kept, so it is never given again).
    pub fn apply_site_change(
        &self,
        fleet: &str,
        sequence: Option<u64>,
        change: &SiteChange,
        file: Option<Vec<u8>>,
    ) -> Result<(), StoreError> {
        let _one_at_a_time = self.versions.lock().expect("versions lock");
        self.writing(|db| {
            let txn = db.begin_write()?;
            match change {
                SiteChange::VersionAdded {
                    number, summary, ..
                } => {
                    let rows = file.map(|file| VersionRows {
                        file,
                        summary: summary.clone(),
                    });
                    versions::put_version(&txn, fleet, *number, rows.as_ref())?;
                }
                SiteChange::VersionDeleted { number } => {
                    versions::remove_version(&txn, fleet, *number)?;
                }
                SiteChange::ModesSet { robots, version } => {
                    localization::write_modes(&txn, fleet, robots.as_deref(), *version)?;
                }
            }
            if let Some(sequence) = sequence {
                let mut site_log = txn.open_table(SITE_LOG)?;
                let held = site_log.get(fleet)?.map_or(0, |v| v.value());
                site_log.insert(fleet, held.max(sequence))?;
            }
            txn.commit()?;
            Ok(())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changes_stored_twice_are_stored_once_and_a_deleted_versions_number_stays_given() {
        let (dir, store) = crate::temp_store("changes");
        let added = SiteChange::VersionAdded {
            number: 1,
            summary: b"{\"version\":1}".to_vec(),
            host: "h1".into(),
        };
        for _ in 0..2 {
            store
                .apply_site_change("park", Some(4), &added, Some(vec![7; 3]))
                .unwrap();
        }
        assert_eq!(store.version_file("park", 1).unwrap(), Some(vec![7; 3]));
        assert_eq!(store.site_log_sequence("park").unwrap(), 4);
        let localize = SiteChange::ModesSet {
            robots: Some(vec!["r1".into()]),
            version: 1,
        };
        store
            .apply_site_change("park", Some(5), &localize, None)
            .unwrap();
        assert!(store.deletable("park", 1).is_err(), "r1 localizes on it");
        let map = SiteChange::ModesSet {
            robots: None,
            version: 0,
        };
        store
            .apply_site_change("park", Some(6), &map, None)
            .unwrap();
        assert!(store.deletable("park", 1).unwrap());
        let deleted = SiteChange::VersionDeleted { number: 1 };
        store
            .apply_site_change("park", Some(7), &deleted, None)
            .unwrap();
        // An older record read again never moves the sequence back.
        store
            .apply_site_change("park", Some(3), &deleted, None)
            .unwrap();
        assert_eq!(store.site_log_sequence("park").unwrap(), 7);
        assert_eq!(store.version_summary("park", 1).unwrap(), None);
        // A version whose file was deleted before it was read keeps its number only.
        let gone = SiteChange::VersionAdded {
            number: 2,
            summary: b"{\"version\":2}".to_vec(),
            host: "h1".into(),
        };
        store
            .apply_site_change("park", Some(8), &gone, None)
            .unwrap();
        assert_eq!(store.version_summary("park", 2).unwrap(), None);
        assert_eq!(store.next_version_number::<()>("park", 5).unwrap(), 3);
        drop(store);
        std::fs::remove_dir_all(&dir).ok();
    }
}
