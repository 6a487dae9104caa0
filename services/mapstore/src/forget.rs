//! A site's rows dropped from a cluster host's store: the store is the host's cache of the
//! site's log, and a log rebuilt from another host's store (`levelmap site-log rebuild`)
//! numbers its records anew. A host that finds a gap before the log's first record drops
//! what it held of the site and reads the log from its start.

use super::{
    CLOUDS, EDGES, NODES, PASS_FIXES, SITE_LOG, SNAPSHOTS, SOLVE_POINTS, SOLVES, Store, StoreError,
    localization, versions,
};
use redb::{TableDefinition, WriteTransaction};

impl Store {
    /// Drops every row of `fleet`: its nodes, edges, solves, clouds, spans, versions,
    /// modes, snapshot and log sequence, in one transaction. Its mapping version stays: the
    /// hosts of a cluster map with one configuration.
    pub fn forget_site(&self, fleet: &str) -> Result<(), StoreError> {
        let _one_at_a_time = self.versions.lock().expect("versions lock");
        self.writing(|db| {
            let txn = db.begin_write()?;
            for table in [
                NODES,
                EDGES,
                CLOUDS,
                versions::VERSIONS,
                versions::VERSION_SUMMARIES,
            ] {
                drop_indexed(&txn, table, fleet)?;
            }
            txn.open_table(SOLVES)?
                .retain_in((fleet, 0)..=(fleet, u64::MAX), |_, _| false)?;
            txn.open_table(SOLVE_POINTS)?
                .retain_in((fleet, 0)..=(fleet, u64::MAX), |_, _| false)?;
            txn.open_table(PASS_FIXES)?
                .retain_in((fleet, 0, 0)..=(fleet, u64::MAX, u64::MAX), |_, _| false)?;
            // Robot names are wire ids (ASCII): every one sorts below U+10FFFF.
            let last_robot = "\u{10ffff}";
            let spans = (fleet, "", 0, 0)..=(fleet, last_robot, u64::MAX, u64::MAX);
            txn.open_table(localization::LOCALIZED)?
                .retain_in(spans.clone(), |_, _| false)?;
            txn.open_table(localization::PASS_POSES)?
                .retain_in(spans, |_, _| false)?;
            txn.open_table(localization::MODES)?
                .retain_in((fleet, "")..=(fleet, last_robot), |_, _| false)?;
            txn.open_table(SITE_LOG)?.remove(fleet)?;
            txn.open_table(SNAPSHOTS)?.remove(fleet)?;
            txn.open_table(versions::VERSION_NUMBERS)?.remove(fleet)?;
            txn.commit()?;
            Ok(())
        })
    }
}

/// Drops `fleet`'s rows of a table keyed by (fleet, index).
fn drop_indexed(
    txn: &WriteTransaction,
    table: TableDefinition<(&str, u64), &[u8]>,
    fleet: &str,
) -> Result<(), StoreError> {
    txn.open_table(table)?
        .retain_in((fleet, 0)..=(fleet, u64::MAX), |_, _| false)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FleetBatch, SiteChange};
    use redb::ReadableTable;

    /// Two fleets with a row in every table that is keyed by fleet.
    fn two_fleets(store: &Store) {
        for fleet in ["park", "park2"] {
            let spans = vec![
                fleetmap::LocalizedSpan {
                    robot: "r1".into(),
                    chain_id: 0,
                    first_seq: 1,
                    last_seq: 2,
                    passed: None,
                },
                passed_span(),
            ];
            let fixes = [slam::GpsEdge {
                node: 0,
                position_m: slam::nalgebra::Vector2::zeros(),
                information: slam::nalgebra::Matrix2::identity(),
                lever_arm_m: slam::nalgebra::Vector2::zeros(),
                robust: slam::Robust::None,
            }];
            let batch = FleetBatch {
                fleet,
                nodes: vec![(0, b"n0"), (1, b"n1")],
                clouds: vec![(1, b"c1")],
                first_edge: 0,
                edges: vec![b"{}".to_vec()],
                solved: Some(crate::SolvePoint {
                    seq: 0,
                    taken_after: 0,
                    applied_after: 1,
                }),
                pass_fixes: &fixes,
                localized: spans,
                log_sequence: Some(9),
                ..Default::default()
            };
            store.commit(&[batch]).unwrap();
            store.put_snapshot(fleet, b"snapshot").unwrap();
            let added = SiteChange::VersionAdded {
                number: 1,
                summary: b"{}".to_vec(),
                host: "h1".into(),
            };
            store
                .apply_site_change(fleet, None, &added, Some(b"file".to_vec()))
                .unwrap();
            let modes = SiteChange::ModesSet {
                robots: Some(vec!["r1".into()]),
                version: 1,
            };
            store.apply_site_change(fleet, None, &modes, None).unwrap();
        }
    }

    /// A run of passes with its last pass's map pose.
    fn passed_span() -> fleetmap::LocalizedSpan {
        fleetmap::LocalizedSpan {
            robot: "r2".into(),
            chain_id: 1,
            first_seq: 4,
            last_seq: 9,
            passed: Some(slam::Passed {
                nodes: 6,
                path_m: 2.5,
                odometry: Some(slam::Pose2::new(1.0, 2.0, 0.5)),
                pose: Some(slam::Pose2::new(-3.0, 4.0, 0.25)),
                unlocated_m: 1.5,
            }),
        }
    }

    #[test]
    fn a_forgotten_site_has_no_row_left_and_the_others_keep_theirs() {
        let (dir, store) = crate::temp_store("forget");
        two_fleets(&store);
        store.forget_site("park").unwrap();
        // "park2" sorts right after "park": a range too wide would take it too.
        assert_eq!(store.fleet_ids().unwrap(), ["park2"]);
        let gone = store.load_fleet("park").unwrap();
        assert!(gone.nodes.is_empty() && gone.edges.is_empty());
        assert!(gone.solve_points.is_empty() && gone.pass_fixes.is_empty());
        assert!(gone.localized.is_empty());
        assert_eq!(store.cloud("park", 1).unwrap(), None);
        assert_eq!(store.snapshot("park").unwrap(), None);
        assert_eq!(store.site_log_sequence("park").unwrap(), 0);
        assert!(store.version_summaries("park").unwrap().is_empty());
        assert_eq!(store.last_version_number("park").unwrap(), 0);
        let modes = store.modes().unwrap();
        assert_eq!(modes.len(), 1, "{modes:?}");
        assert_eq!(modes[0].0, "park2");

        let kept = store.load_fleet("park2").unwrap();
        assert_eq!((kept.nodes.len(), kept.edges.len()), (2, 1));
        assert_eq!((kept.solve_points.len(), kept.pass_fixes.len()), (1, 1));
        assert_eq!(kept.localized.len(), 2);
        assert_eq!(
            kept.localized[1],
            passed_span(),
            "a pass's map pose is kept"
        );
        let poses = store.read_txn().unwrap();
        let poses = poses.open_table(crate::localization::PASS_POSES).unwrap();
        assert_eq!(poses.iter().unwrap().count(), 1, "park's pass pose is gone");
        assert!(store.cloud("park2", 1).unwrap().is_some());
        assert!(store.snapshot("park2").unwrap().is_some());
        assert_eq!(store.site_log_sequence("park2").unwrap(), 9);
        assert_eq!(store.last_version_number("park2").unwrap(), 1);
        drop(store);
        std::fs::remove_dir_all(&dir).ok();
    }
}
