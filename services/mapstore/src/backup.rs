//! A backup of a running store: every table read in one read transaction, so the copy is
//! the store as one commit left it while the writer goes on (redb's readers see a fixed
//! state and do not block it), written to a new file that is synced and then renamed into
//! place. A copy is a store like any other: the mapper opens it as it opens its own.

use super::{Store, StoreError};
use redb::{
    Database, Key, ReadTransaction, ReadableDatabase, ReadableTable, TableDefinition, TableError,
    TableHandle, Value, WriteTransaction,
};
use std::path::Path;

/// What a backup holds.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct BackupReport {
    /// Rows copied, every table (0 for a restore, which copies the file).
    pub rows: u64,
    /// The copy's size (bytes).
    pub bytes: u64,
    /// (fleet, nodes) of each fleet, sorted.
    pub fleets: Vec<(String, u64)>,
}

impl StoreError {
    /// A backup's file that could not be written or read.
    pub fn backup_file(path: &Path, e: &std::io::Error) -> StoreError {
        StoreError::Backup(format!("{}: {e}", path.display()))
    }
}

impl Store {
    /// Writes a consistent copy of the store to `path` (which must not exist), while it
    /// stays open for the writer. The copy is made as `path` + `.partial` and renamed once
    /// it is synced: a failed backup leaves no file that looks whole.
    pub fn backup_to(&self, path: &Path) -> Result<BackupReport, StoreError> {
        if path.exists() {
            return Err(StoreError::Backup(format!(
                "{} exists: a backup does not overwrite a file",
                path.display()
            )));
        }
        let snapshot = {
            let db = self.db.read().expect("store lock");
            db.as_ref().ok_or(StoreError::Closed)?.begin_read()?
        };
        let mut partial = path.as_os_str().to_owned();
        partial.push(".partial");
        let partial = std::path::PathBuf::from(partial);
        let _ = std::fs::remove_file(&partial);
        let result = copy_into(&snapshot, &partial);
        let report = match result {
            Ok(report) => report,
            Err(e) => {
                let _ = std::fs::remove_file(&partial);
                return Err(e);
            }
        };
        let io = |e| StoreError::backup_file(&partial, &e);
        std::fs::File::open(&partial)
            .and_then(|f| f.sync_all())
            .map_err(io)?;
        std::fs::rename(&partial, path).map_err(io)?;
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            // The rename made durable too.
            std::fs::File::open(dir)
                .and_then(|d| d.sync_all())
                .map_err(io)?;
        }
        let bytes = std::fs::metadata(path).map_err(io)?.len();
        Ok(BackupReport { bytes, ..report })
    }
}

/// Puts a backup in place as the store at `store_path` (which must not exist: a store is
/// never overwritten), checked first: it is copied beside `store_path`, opened as a store
/// (its format read, an older one migrated, a later one refused), synced and renamed.
/// Returns what it holds.
pub fn restore_backup(backup: &Path, store_path: &Path) -> Result<BackupReport, StoreError> {
    if store_path.exists() {
        return Err(StoreError::Backup(format!(
            "{} exists: move it away to restore a backup over it",
            store_path.display()
        )));
    }
    let mut partial = store_path.as_os_str().to_owned();
    partial.push(".restoring");
    let partial = std::path::PathBuf::from(partial);
    let io = |what: &Path, e| StoreError::backup_file(what, &e);
    std::fs::copy(backup, &partial).map_err(|e| io(backup, e))?;
    let checked = Store::open(&partial).and_then(|store| {
        let db = store.db.read().expect("store lock");
        let snapshot = db.as_ref().ok_or(StoreError::Closed)?.begin_read()?;
        Ok(BackupReport {
            rows: 0,
            bytes: 0,
            fleets: fleet_nodes(&snapshot)?,
        })
    });
    let report = match checked {
        Ok(report) => report,
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            return Err(StoreError::Backup(format!(
                "{} is not a store this mapper opens: {e}",
                backup.display()
            )));
        }
    };
    std::fs::File::open(&partial)
        .and_then(|f| f.sync_all())
        .map_err(|e| io(&partial, e))?;
    std::fs::rename(&partial, store_path).map_err(|e| io(store_path, e))?;
    let bytes = std::fs::metadata(store_path)
        .map_err(|e| io(store_path, e))?
        .len();
    Ok(BackupReport { bytes, ..report })
}

/// Every table of `snapshot` into a new store at `path`, in one transaction.
fn copy_into(snapshot: &ReadTransaction, path: &Path) -> Result<BackupReport, StoreError> {
    let copy = Database::create(path)?;
    let txn = copy.begin_write()?;
    use super::{localization as l, meta as m, versions as v};
    let mut copied: Vec<String> = Vec::new();
    let mut rows = 0;
    macro_rules! copy {
        ($($definition:expr),* $(,)?) => {$(
            rows += table(snapshot, &txn, $definition)?;
            copied.push($definition.name().to_owned());
        )*};
    }
    copy!(
        super::NODES,
        super::EDGES,
        super::SOLVES,
        super::SOLVE_POINTS,
        super::PASS_FIXES,
        super::CLOUDS,
        super::SITE_LOG,
        super::SNAPSHOTS,
        l::LOCALIZED,
        l::PASS_POSES,
        l::MODES,
        m::STORE_META,
        m::FLEET_MAPPING,
        v::VERSIONS,
        v::VERSION_SUMMARIES,
        v::VERSION_NUMBERS,
    );
    // A table this list does not name would be left out of every backup: refuse instead.
    let missed: Vec<String> = snapshot
        .list_tables()?
        .map(|t| t.name().to_owned())
        .filter(|name| !copied.contains(name))
        .collect();
    if !missed.is_empty() {
        return Err(StoreError::Backup(format!(
            "the store has tables a backup does not copy: {missed:?}"
        )));
    }
    let fleets = fleet_nodes(snapshot)?;
    txn.commit()?;
    Ok(BackupReport {
        rows,
        bytes: 0,
        fleets,
    })
}

/// Copies one table's rows; a table the store never made copies none.
fn table<K: Key + 'static, V: Value + 'static>(
    snapshot: &ReadTransaction,
    copy: &WriteTransaction,
    definition: TableDefinition<K, V>,
) -> Result<u64, StoreError> {
    let from = match snapshot.open_table(definition) {
        Ok(table) => table,
        Err(TableError::TableDoesNotExist(_)) => return Ok(0),
        Err(e) => return Err(e.into()),
    };
    let mut to = copy.open_table(definition)?;
    let mut n = 0;
    for row in from.iter()? {
        let (key, value) = row?;
        to.insert(key.value(), value.value())?;
        n += 1;
    }
    Ok(n)
}

/// Each fleet's node count in `snapshot`.
fn fleet_nodes(snapshot: &ReadTransaction) -> Result<Vec<(String, u64)>, StoreError> {
    let nodes = snapshot.open_table(super::NODES)?;
    let mut fleets: Vec<(String, u64)> = Vec::new();
    for row in nodes.iter()? {
        let (key, _) = row?;
        let fleet = key.value().0;
        match fleets.last_mut() {
            Some((last, n)) if last == fleet => *n += 1,
            _ => fleets.push((fleet.to_owned(), 1)),
        }
    }
    Ok(fleets)
}

#[cfg(test)]
mod tests {
    use super::super::{FleetBatch, localization as l, meta as m, temp_store, versions as v};
    use super::*;

    /// Each row of a table as (key bytes, value bytes).
    type Rows = Vec<(Vec<u8>, Vec<u8>)>;

    fn rows<K: Key + 'static, V: Value + 'static>(
        txn: &ReadTransaction,
        definition: TableDefinition<K, V>,
    ) -> Rows {
        let table = txn.open_table(definition).unwrap();
        table
            .iter()
            .unwrap()
            .map(|row| {
                let (k, v) = row.unwrap();
                let key = K::as_bytes(&k.value()).as_ref().to_vec();
                let value = V::as_bytes(&v.value()).as_ref().to_vec();
                (key, value)
            })
            .collect()
    }

    /// Every table's rows, by name.
    fn every_table(db: &Database) -> Vec<(&'static str, Rows)> {
        let t = db.begin_read().unwrap();
        vec![
            ("nodes", rows(&t, super::super::NODES)),
            ("edges", rows(&t, super::super::EDGES)),
            ("solves", rows(&t, super::super::SOLVES)),
            ("solve_points", rows(&t, super::super::SOLVE_POINTS)),
            ("pass_fixes", rows(&t, super::super::PASS_FIXES)),
            ("clouds", rows(&t, super::super::CLOUDS)),
            ("site_log", rows(&t, super::super::SITE_LOG)),
            ("snapshots", rows(&t, super::super::SNAPSHOTS)),
            ("localized_spans", rows(&t, l::LOCALIZED)),
            ("pass_poses", rows(&t, l::PASS_POSES)),
            ("robot_modes", rows(&t, l::MODES)),
            ("store_meta", rows(&t, m::STORE_META)),
            ("fleet_mapping", rows(&t, m::FLEET_MAPPING)),
            ("versions", rows(&t, v::VERSIONS)),
            ("version_summaries", rows(&t, v::VERSION_SUMMARIES)),
            ("version_numbers", rows(&t, v::VERSION_NUMBERS)),
        ]
    }

    fn database(store: &Store) -> std::sync::RwLockReadGuard<'_, Option<Database>> {
        store.db.read().unwrap()
    }

    #[test]
    fn a_backup_holds_every_row_of_every_table() {
        let (dir, store) = temp_store("backup-every-table");
        {
            let db = database(&store);
            let txn = db.as_ref().unwrap().begin_write().unwrap();
            use super::super::*;
            txn.open_table(NODES)
                .unwrap()
                .insert(("park", 0), &b"node"[..])
                .unwrap();
            txn.open_table(EDGES)
                .unwrap()
                .insert(("park", 0), &b"edge"[..])
                .unwrap();
            txn.open_table(SOLVES)
                .unwrap()
                .insert(("park", 0), ())
                .unwrap();
            txn.open_table(SOLVE_POINTS)
                .unwrap()
                .insert(("park", 0), (1, 2))
                .unwrap();
            let fix = &b"fix"[..];
            txn.open_table(PASS_FIXES)
                .unwrap()
                .insert(("park", 0, 0), fix)
                .unwrap();
            txn.open_table(CLOUDS)
                .unwrap()
                .insert(("park", 0), &b"cloud"[..])
                .unwrap();
            txn.open_table(SITE_LOG).unwrap().insert("park", 7).unwrap();
            txn.open_table(SNAPSHOTS)
                .unwrap()
                .insert("park", &b"snap"[..])
                .unwrap();
            let span = (3, 1, 2.0, 0.5, 0.25, 0.125);
            let key = ("park", "robot0", 9, 1);
            txn.open_table(l::LOCALIZED)
                .unwrap()
                .insert(key, span)
                .unwrap();
            txn.open_table(l::PASS_POSES)
                .unwrap()
                .insert(key, (1.5, -2.0, 0.25, 3.0))
                .unwrap();
            txn.open_table(l::MODES)
                .unwrap()
                .insert(("park", "robot0"), 1)
                .unwrap();
            let mapping = &b"{}"[..];
            txn.open_table(m::FLEET_MAPPING)
                .unwrap()
                .insert("park", mapping)
                .unwrap();
            txn.open_table(v::VERSIONS)
                .unwrap()
                .insert(("park", 1), &b"v1"[..])
                .unwrap();
            let summary = &b"s1"[..];
            txn.open_table(v::VERSION_SUMMARIES)
                .unwrap()
                .insert(("park", 1), summary)
                .unwrap();
            txn.open_table(v::VERSION_NUMBERS)
                .unwrap()
                .insert("park", 2)
                .unwrap();
            txn.commit().unwrap();
        }
        let path = dir.join("backup.redb");
        let report = store.backup_to(&path).unwrap();
        assert_eq!(report.bytes, std::fs::metadata(&path).unwrap().len());
        let source = every_table(database(&store).as_ref().unwrap());
        let copy = every_table(&Database::open(&path).unwrap());
        for ((name, from), (_, to)) in source.iter().zip(&copy) {
            assert!(!from.is_empty(), "{name}: the test wrote a row");
            assert_eq!(from, to, "{name}");
        }
        let total: usize = source.iter().map(|(_, r)| r.len()).sum();
        assert_eq!(report.rows, total as u64);
        assert_eq!(report.fleets, [("park".to_owned(), 1)]);
        // Put in place as a store, never over one.
        let at = dir.join("restored.redb");
        let put = restore_backup(&path, &at).unwrap();
        assert_eq!(put.fleets, report.fleets);
        assert_eq!(Store::open(&at).unwrap().fleet_ids().unwrap(), ["park"]);
        let e = restore_backup(&path, &at).unwrap_err();
        assert!(e.to_string().contains("move it away"), "{e}");
        let junk = dir.join("junk.redb");
        std::fs::write(&junk, b"not a store").unwrap();
        let e = restore_backup(&junk, &dir.join("second.redb")).unwrap_err();
        assert!(e.to_string().contains("is not a store"), "{e}");
        assert!(!dir.join("second.redb").exists());
        assert!(!dir.join("second.redb.restoring").exists());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Nodes and their edges are committed together; a backup taken while commits go on
    /// holds as many of one as of the other, and the nodes without a gap: one commit's state.
    #[test]
    fn a_backup_taken_while_the_writer_commits_is_one_commits_state() {
        let (dir, store) = temp_store("backup-while-writing");
        let store = std::sync::Arc::new(store);
        let writer = std::thread::spawn({
            let store = store.clone();
            move || {
                for i in 0..400u64 {
                    let node = format!("node{i}");
                    store
                        .commit(&[FleetBatch {
                            fleet: "park",
                            nodes: vec![(i, node.as_bytes())],
                            first_edge: i,
                            edges: vec![format!("edge{i}").into_bytes()],
                            ..Default::default()
                        }])
                        .unwrap();
                }
            }
        });
        let mut counts = Vec::new();
        for k in 0..20 {
            let path = dir.join(format!("backup{k}.redb"));
            store.backup_to(&path).unwrap();
            let copy = Store::open(&path).unwrap();
            let park = copy.load_fleet("park").unwrap_or_default();
            assert_eq!(park.nodes.len(), park.edges.len(), "backup {k}");
            for (i, node) in park.nodes.iter().enumerate() {
                assert_eq!(node, format!("node{i}").as_bytes(), "backup {k}");
            }
            counts.push(park.nodes.len());
        }
        writer.join().unwrap();
        assert!(counts.windows(2).all(|w| w[0] <= w[1]), "{counts:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_backup_overwrites_nothing_and_refuses_a_table_it_does_not_know() {
        let (dir, store) = temp_store("backup-refusals");
        let taken = dir.join("taken.redb");
        std::fs::write(&taken, b"a user's file").unwrap();
        let e = store.backup_to(&taken).unwrap_err();
        assert!(e.to_string().contains("does not overwrite"), "{e}");
        assert_eq!(std::fs::read(&taken).unwrap(), b"a user's file");
        {
            let db = database(&store);
            let txn = db.as_ref().unwrap().begin_write().unwrap();
            let new: TableDefinition<u64, u64> = TableDefinition::new("a_new_table");
            txn.open_table(new).unwrap().insert(1, 1).unwrap();
            txn.commit().unwrap();
        }
        let path = dir.join("backup.redb");
        let e = store.backup_to(&path).unwrap_err();
        assert!(e.to_string().contains("a_new_table"), "{e}");
        assert!(!path.exists());
        let mut partial = path.into_os_string();
        partial.push(".partial");
        assert!(
            !std::path::Path::new(&partial).exists(),
            "the partial copy is removed"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
