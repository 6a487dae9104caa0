//! The store: clouds apart, a disk that fills and empties, fleets read one by one, a passed
//! run's pose.

use super::*;

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
    assert_eq!(store.fleet_ids().unwrap(), ["park"]);
    let park = store.load_fleet("park").unwrap();
    assert_eq!(park.nodes, [b"node0".to_vec(), b"node1".to_vec()]);
    drop(store);
    std::fs::remove_dir_all(&dir).ok();
}

/// A disk that can be filled: writes and growth fail with ENOSPC while `full`; what it
/// holds outlives each database opened on it (as a file does).
#[derive(Debug, Clone)]
struct Disk {
    data: std::sync::Arc<redb::backends::InMemoryBackend>,
    full: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl Disk {
    fn space(&self) -> std::io::Result<()> {
        if self.full.load(std::sync::atomic::Ordering::SeqCst) {
            return Err(std::io::Error::from_raw_os_error(28)); // ENOSPC
        }
        Ok(())
    }
}

impl redb::StorageBackend for Disk {
    fn len(&self) -> std::io::Result<u64> {
        self.data.len()
    }
    fn read(&self, offset: u64, out: &mut [u8]) -> std::io::Result<()> {
        self.data.read(offset, out)
    }
    fn set_len(&self, len: u64) -> std::io::Result<()> {
        self.space()?;
        self.data.set_len(len)
    }
    fn sync_data(&self) -> std::io::Result<()> {
        self.data.sync_data()
    }
    fn write(&self, offset: u64, data: &[u8]) -> std::io::Result<()> {
        self.space()?;
        self.data.write(offset, data)
    }
}

fn nodes<'a>(fleet: &'a str, rows: &[(u64, &'a [u8])]) -> FleetBatch<'a> {
    FleetBatch {
        fleet,
        nodes: rows.to_vec(),
        ..Default::default()
    }
}

#[test]
fn a_failed_commit_closes_the_store_and_a_later_one_stores_its_rows_once() {
    use redb::StorageBackend as _;
    let disk = Disk {
        data: Default::default(),
        full: Default::default(),
    };
    let opened = disk.clone();
    let store = Store::with_opener(Box::new(move || {
        Database::builder().create_with_backend(opened.clone())
    }))
    .unwrap();
    store.commit(&[nodes("park", &[(0, b"n0")])]).unwrap();
    disk.full.store(true, std::sync::atomic::Ordering::SeqCst);
    let batch = [nodes("park", &[(1, b"n1"), (2, b"n2")])];
    let e = store.commit(&batch).unwrap_err();
    assert!(e.to_string().contains("No space left"), "{e}");
    // Closed until a commit opens it again; while the disk is full that fails too.
    assert!(matches!(store.cloud("park", 0), Err(StoreError::Closed)));
    assert!(store.commit(&batch).is_err());
    disk.full.store(false, std::sync::atomic::Ordering::SeqCst);
    store.commit(&batch).unwrap();
    // The same rows again (a commit that reached the disk but reported a failure).
    store.commit(&batch).unwrap();
    assert_eq!(store.fleet_ids().unwrap(), ["park"]);
    let park = store.load_fleet("park").unwrap();
    assert_eq!(park.nodes, [b"n0".to_vec(), b"n1".to_vec(), b"n2".to_vec()]);
    assert!(disk.data.len().unwrap() > 0);
}

#[test]
fn a_gap_in_one_fleets_rows_leaves_the_others_readable() {
    let dir = std::env::temp_dir().join(format!("levelmap-gap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("gap.redb");
    let _ = std::fs::remove_file(&path);
    let store = Store::open(&path).unwrap();
    store
        .commit(&[
            nodes("campus", &[(0, b"c0"), (2, b"c2")]),
            nodes("park", &[(0, b"p0"), (1, b"p1")]),
        ])
        .unwrap();
    assert_eq!(store.fleet_ids().unwrap(), ["campus", "park"]);
    let e = store.load_fleet("campus").unwrap_err();
    assert_eq!(
        e.to_string(),
        "store: fleet campus: nodes row 2 where 1 was due"
    );
    assert_eq!(store.load_fleet("park").unwrap().nodes.len(), 2);
    drop(store);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn solve_points_read_back_in_order_and_a_missing_one_is_damage() {
    let dir = std::env::temp_dir().join(format!("levelmap-solves-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("solves.redb");
    let _ = std::fs::remove_file(&path);
    let store = Store::open(&path).unwrap();
    let point = |seq, taken_after, applied_after| SolvePoint {
        seq,
        taken_after,
        applied_after,
    };
    let solved = |fleet, point| FleetBatch {
        fleet,
        solved: Some(point),
        ..Default::default()
    };
    store
        .commit(&[
            nodes("park", &[(0, b"p0"), (1, b"p1"), (2, b"p2")]),
            solved("park", point(1, 1, 2)),
            solved("park", point(0, 0, 1)),
            nodes("campus", &[(0, b"c0")]),
            solved("campus", point(1, 0, 0)),
        ])
        .unwrap();
    let park = store.load_fleet("park").unwrap();
    assert_eq!(park.solve_points, [point(0, 0, 1), point(1, 1, 2)]);
    assert!(park.legacy_solves.is_empty());
    let e = store.load_fleet("campus").unwrap_err();
    assert_eq!(
        e.to_string(),
        "store: fleet campus: solve 1 where 0 was due"
    );
    drop(store);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn clouds_are_dropped_oldest_first_by_age_then_by_bytes_per_fleet() {
    let dir = std::env::temp_dir().join(format!("levelmap-prune-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("prune.redb");
    let _ = std::fs::remove_file(&path);
    let store = Store::open(&path).unwrap();
    let cloud = [7u8; 100];
    let clouds: Vec<(u64, &[u8])> = (0..10).map(|n| (n, &cloud[..])).collect();
    for fleet in ["park", "campus"] {
        store
            .commit(&[FleetBatch {
                fleet,
                clouds: clouds.clone(),
                ..Default::default()
            }])
            .unwrap();
    }
    // Nodes 0 and 1 too old; then at most 500 bytes: 2 and 3 go too.
    let pruned = store.prune_clouds("park", |node| node < 2, 500).unwrap();
    assert_eq!(
        pruned,
        Pruned {
            clouds: 5,
            bytes: 500,
            kept_bytes: 500
        }
    );
    let kept: Vec<u64> = (0..10)
        .filter(|&n| store.cloud("park", n).unwrap().is_some())
        .collect();
    assert_eq!(kept, [5, 6, 7, 8, 9]);
    // Another fleet's are its own; nothing more to drop is a no-op.
    assert!((0..10).all(|n| store.cloud("campus", n).unwrap().is_some()));
    assert_eq!(
        store.prune_clouds("park", |_| false, 500).unwrap().clouds,
        0
    );
    assert_eq!(
        store.prune_clouds("park", |_| false, 0).unwrap().kept_bytes,
        500
    );
    drop(store);
    std::fs::remove_dir_all(&dir).ok();
}

/// A run of passes rewritten as it grows keeps its last pass's map pose; extended by a row
/// without one (an earlier release's record), it keeps none rather than an older pass's.
#[test]
fn a_passed_run_keeps_its_last_pose_and_no_stale_one() {
    let (dir, store) = crate::temp_store("pass-poses");
    let span = |last_seq, pose: Option<slam::Pose2>| fleetmap::LocalizedSpan {
        robot: "r1".into(),
        chain_id: 0,
        first_seq: 4,
        last_seq,
        passed: Some(slam::Passed {
            nodes: (last_seq - 3) as usize,
            path_m: 1.0,
            odometry: Some(slam::Pose2::new(1.0, 0.0, 0.0)),
            pose,
            unlocated_m: 0.5 * f64::from(pose.is_some()),
        }),
    };
    let commit = |s: fleetmap::LocalizedSpan| {
        let batch = FleetBatch {
            fleet: "park",
            localized: vec![s],
            ..Default::default()
        };
        store.commit(&[batch]).unwrap();
    };
    commit(span(5, Some(slam::Pose2::new(-3.0, 4.0, 0.25))));
    commit(span(6, Some(slam::Pose2::new(-2.5, 4.0, 0.25))));
    let stored = store.load_fleet("park").unwrap().localized;
    assert_eq!(stored, [span(6, Some(slam::Pose2::new(-2.5, 4.0, 0.25)))]);
    commit(span(7, None));
    let stored = store.load_fleet("park").unwrap().localized;
    assert_eq!(stored, [span(7, None)], "no stale pose");
    drop(store);
    std::fs::remove_dir_all(&dir).ok();
}
