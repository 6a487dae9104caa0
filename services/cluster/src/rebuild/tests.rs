use super::*;
use crate::record::LogRecord;
use crate::replay::{Read, commit_records};
use mapper::store::{FleetBatch, encode_edges, temp_store};

fn edge(from: usize, to: usize) -> slam::RelativeEdge {
    slam::RelativeEdge {
        from,
        to,
        measurement: slam::Pose2::new(1.0, 0.0, 0.1),
        information: nalgebra::Matrix3::identity() * 100.0,
        kind: slam::EdgeKind::Odometry,
        robust: slam::Robust::None,
    }
}

fn fix(node: usize) -> slam::GpsEdge {
    slam::GpsEdge {
        node,
        position_m: nalgebra::Vector2::new(node as f64, 2.0),
        information: nalgebra::Matrix2::identity(),
        lever_arm_m: nalgebra::Vector2::zeros(),
        robust: slam::Robust::Cauchy { c: 2.0 },
    }
}

/// A site as a host's store holds it after a while: 40 nodes of 30 KiB (more than one
/// record's worth), edges, solves (two applied after one node, one with GPS fixes), spans,
/// two versions kept and the last one deleted, the fleet's mode and two robots' own.
fn a_site(store: &Store) {
    let nodes: Vec<Vec<u8>> = (0..40u8).map(|k| vec![k; 30 * 1024]).collect();
    let edges: Vec<slam::RelativeEdge> = (0..39).map(|k| edge(k, k + 1)).collect();
    let fixes = [fix(9), fix(10)];
    for k in 0..40u64 {
        let solved = match k {
            9 => Some(SolvePoint {
                seq: 0,
                taken_after: 7,
                applied_after: 9,
            }),
            20 => Some(SolvePoint {
                seq: 1,
                taken_after: 15,
                applied_after: 20,
            }),
            _ => None,
        };
        let batch = FleetBatch {
            fleet: "park",
            nodes: vec![(k, nodes[k as usize].as_slice())],
            first_edge: k.saturating_sub(1),
            edges: if k == 0 {
                Vec::new()
            } else {
                encode_edges(&edges[k as usize - 1..k as usize])
            },
            solved,
            pass_fixes: if k == 9 { &fixes } else { &[] },
            localized: if k == 30 {
                vec![fleetmap::LocalizedSpan {
                    robot: "r2".into(),
                    chain_id: 1,
                    first_seq: 4,
                    last_seq: 9,
                    passed: None,
                }]
            } else {
                Vec::new()
            },
            log_sequence: Some(k + 1),
            ..Default::default()
        };
        store.commit(&[batch]).unwrap();
    }
    // A second solve applied after node 20, in a batch without nodes.
    let late = FleetBatch {
        fleet: "park",
        solved: Some(SolvePoint {
            seq: 2,
            taken_after: 18,
            applied_after: 20,
        }),
        ..Default::default()
    };
    store.commit(&[late]).unwrap();
    for number in 1..=3u64 {
        let added = SiteChange::VersionAdded {
            number,
            summary: format!("{{\"version\":{number}}}").into_bytes(),
            host: "h1".into(),
        };
        store
            .apply_site_change("park", None, &added, Some(vec![number as u8; 100]))
            .unwrap();
    }
    let deleted = SiteChange::VersionDeleted { number: 3 };
    store
        .apply_site_change("park", None, &deleted, None)
        .unwrap();
    let modes = [
        SiteChange::ModesSet {
            robots: None,
            version: 1,
        },
        SiteChange::ModesSet {
            robots: Some(vec!["r1".into(), "r3".into()]),
            version: 2,
        },
    ];
    for set in &modes {
        store.apply_site_change("park", None, set, None).unwrap();
    }
}

/// The records as a host reads them from the log (`replay::catch_up`), the files from the
/// version files by the name the rebuild put them under.
fn as_read(built: &StoreRecords, by: &str) -> Vec<Read> {
    built
        .records
        .iter()
        .enumerate()
        .map(|(k, (_, bytes))| {
            let sequence = REBUILT_GAP + k as u64;
            match LogRecord::decode(bytes).expect("a record") {
                LogRecord::Batch(record) => {
                    let fixes = record.pass_fixes().unwrap();
                    Read::Batch(sequence, record, fixes)
                }
                LogRecord::Change(change) => {
                    let file = match &change {
                        SiteChange::VersionAdded { number, host, .. } => {
                            assert_eq!(host, by);
                            built
                                .files
                                .iter()
                                .find(|(n, _)| n == number)
                                .map(|(_, f)| f.clone())
                        }
                        _ => None,
                    };
                    Read::Change(sequence, change, file)
                }
            }
        })
        .collect()
}

#[test]
fn a_log_rebuilt_from_a_store_and_read_into_an_empty_store_is_that_store() {
    let (dir_a, a) = temp_store("rebuild-from");
    a_site(&a);
    let built = records_from_store(&a, "park", "h1-rebuild").unwrap();
    assert_eq!(
        built.counts,
        Counts {
            nodes: 40,
            edges: 39,
            solves: 3,
            spans: 1,
            versions: 2,
            modes: 2
        }
    );
    // Well under JetStream's 1 MiB message: 256 KiB of nodes, or of edges, a record.
    for (id, bytes) in &built.records {
        assert!(bytes.len() < 300 * 1024, "{id}: {} bytes", bytes.len());
    }
    let ids: std::collections::HashSet<&str> =
        built.records.iter().map(|(id, _)| id.as_str()).collect();
    assert_eq!(
        ids.len(),
        built.records.len(),
        "every record's id is its own"
    );

    let (dir_b, b) = temp_store("rebuild-into");
    commit_records(&b, "park", &as_read(&built, "h1-rebuild")).unwrap();
    let (was, is) = (a.load_fleet("park").unwrap(), b.load_fleet("park").unwrap());
    assert_eq!(is.nodes, was.nodes);
    assert_eq!(is.edges, was.edges);
    assert_eq!(is.solve_points, was.solve_points);
    assert_eq!(is.pass_fixes, was.pass_fixes);
    assert_eq!(is.localized, was.localized);
    assert_eq!(
        b.version_summaries("park").unwrap(),
        a.version_summaries("park").unwrap()
    );
    for number in 1..=3 {
        assert_eq!(
            b.version_file("park", number).unwrap(),
            a.version_file("park", number).unwrap()
        );
    }
    // The deleted version's number stays given.
    assert_eq!(b.last_version_number("park").unwrap(), 3);
    assert_eq!(b.modes().unwrap(), a.modes().unwrap());
    assert_eq!(
        b.site_log_sequence("park").unwrap(),
        REBUILT_GAP + built.records.len() as u64 - 1
    );
    drop((a, b));
    std::fs::remove_dir_all(&dir_a).ok();
    std::fs::remove_dir_all(&dir_b).ok();
}

#[test]
fn a_store_without_the_site_has_nothing_to_rebuild() {
    let (dir, store) = temp_store("rebuild-empty");
    let e = records_from_store(&store, "park", "h1-rebuild").unwrap_err();
    assert!(e.to_string().contains("holds nothing"), "{e}");
    drop(store);
    std::fs::remove_dir_all(&dir).ok();
}
