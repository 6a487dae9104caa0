//! A site's records in its cluster log: what one worker turn commits for a site (a
//! [`FleetBatch`]), split into records small enough for JetStream (1 MiB a message by
//! default), each named for deduplication by its first node's robot/chain/seq.
//!
//! Between batches, a record may be a change of the site's versions or modes
//! ([`SiteChange`]), appended by the owner when an operator makes it.
//!
//! A record is one format byte, then the record in postcard. Postcard is not
//! self-describing: a change of [`SiteRecord`]'s fields is a new format number, and every
//! later release reads every format it ever wrote (a log outlives the release that wrote it).

use mapper::store::{FleetBatch, SiteChange, SolvePoint};
use serde::{Deserialize, Serialize};
use sitelog::RecordId;

/// The format of a batch record this build writes: 3, a span's passes with their last
/// pass's map pose.
pub const RECORD_FORMAT: u8 = 3;
/// Batch records before the passes' map poses (read, no longer written).
const RECORD_FORMAT_1: u8 = 1;
/// The format of a change record ([`SiteChange`]).
pub const CHANGE_FORMAT: u8 = 2;

/// A record of a site's log, read back.
#[derive(Clone, Debug, PartialEq)]
pub enum LogRecord {
    /// A batch, or a part of one.
    Batch(SiteRecord),
    /// A change of the site's versions or modes.
    Change(SiteChange),
}

impl LogRecord {
    /// A record read back from the log.
    pub fn decode(bytes: &[u8]) -> Result<LogRecord, RecordError> {
        match bytes.split_first() {
            Some((&(RECORD_FORMAT | RECORD_FORMAT_1), _)) => {
                SiteRecord::decode(bytes).map(LogRecord::Batch)
            }
            Some((&CHANGE_FORMAT, rest)) => postcard::from_bytes(rest)
                .map(LogRecord::Change)
                .map_err(|e| RecordError::Damaged(e.to_string())),
            Some((&other, _)) => Err(RecordError::Format(other)),
            None => Err(RecordError::Damaged("empty".into())),
        }
    }
}

/// A change's bytes in the log.
pub fn encode_change(change: &SiteChange) -> Vec<u8> {
    let mut bytes = vec![CHANGE_FORMAT];
    bytes.extend(postcard::to_stdvec(change).expect("a change serializes"));
    bytes
}

/// A change's id in the log: a version's number is given once; a change of modes is named
/// by when the operator asked (`asked_ns`), so only its retries are one.
pub fn change_id(change: &SiteChange, asked_ns: u64) -> RecordId {
    RecordId::named(match change {
        SiteChange::VersionAdded { number, .. } => format!("version/{number}/added"),
        SiteChange::VersionDeleted { number } => format!("version/{number}/deleted"),
        SiteChange::ModesSet { .. } => format!("modes/{asked_ns}"),
    })
}

/// Most node bytes in one record: well under JetStream's 1 MiB message limit, with room for
/// the batch's edges, which ride in its last record.
pub const MAX_RECORD_NODE_BYTES: usize = 256 * 1024;

/// One record of a site's log: a batch, or a part of one.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SiteRecord {
    /// (arrival index, the node as received without its cloud).
    pub nodes: Vec<(u64, Vec<u8>)>,
    /// Index of the first of `edges` in the site's network.
    pub first_edge: u64,
    /// The batch's new edges, as the store keeps them (JSON).
    pub edges: Vec<Vec<u8>>,
    /// A solve applied with the batch: (number, taken after, applied after).
    pub solved: Option<(u64, u64, u64)>,
    /// The passes' GPS fixes that solve moved into the network (JSON `slam::GpsEdge`).
    pub pass_fixes: Vec<Vec<u8>>,
    /// Runs of localized or passed nodes the batch started or extended.
    pub localized: Vec<RecordSpan>,
}

/// A [`fleetmap::LocalizedSpan`] in the record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordSpan {
    robot: String,
    chain_id: u64,
    first_seq: u64,
    last_seq: u64,
    /// A pass's counts; `None`: localized on a version.
    passed: Option<RecordPassed>,
}

/// A pass ([`slam::Passed`]): (nodes, path m, the last one's odometry x, y, theta, its map
/// pose x, y, theta, the path since one was located m).
type RecordPassed = (u64, f64, Option<XyTheta>, Option<XyTheta>, f64);
type XyTheta = (f64, f64, f64);

impl From<&fleetmap::LocalizedSpan> for RecordSpan {
    fn from(s: &fleetmap::LocalizedSpan) -> Self {
        let xy_theta = |p: slam::Pose2| (p.x, p.y, p.theta);
        RecordSpan {
            robot: s.robot.clone(),
            chain_id: s.chain_id,
            first_seq: s.first_seq,
            last_seq: s.last_seq,
            passed: s.passed.map(|p| {
                let (odometry, pose) = (p.odometry.map(xy_theta), p.pose.map(xy_theta));
                (p.nodes as u64, p.path_m, odometry, pose, p.unlocated_m)
            }),
        }
    }
}

impl From<&RecordSpan> for fleetmap::LocalizedSpan {
    fn from(s: &RecordSpan) -> Self {
        let pose = |(x, y, theta): XyTheta| slam::Pose2::new(x, y, theta);
        fleetmap::LocalizedSpan {
            robot: s.robot.clone(),
            chain_id: s.chain_id,
            first_seq: s.first_seq,
            last_seq: s.last_seq,
            passed: s
                .passed
                .map(|(nodes, path_m, odometry, at, unlocated_m)| slam::Passed {
                    nodes: nodes as usize,
                    path_m,
                    odometry: odometry.map(pose),
                    pose: at.map(pose),
                    unlocated_m,
                }),
        }
    }
}

/// Batch records of format 1, read back as this build's: their passes have no map pose.
mod format1 {
    use serde::Deserialize;

    #[derive(Deserialize)]
    pub(super) struct SiteRecord {
        nodes: Vec<(u64, Vec<u8>)>,
        first_edge: u64,
        edges: Vec<Vec<u8>>,
        solved: Option<(u64, u64, u64)>,
        pass_fixes: Vec<Vec<u8>>,
        localized: Vec<RecordSpan>,
    }

    #[derive(Deserialize)]
    struct RecordSpan {
        robot: String,
        chain_id: u64,
        first_seq: u64,
        last_seq: u64,
        passed: Option<(u64, f64, Option<super::XyTheta>)>,
    }

    impl From<SiteRecord> for super::SiteRecord {
        fn from(r: SiteRecord) -> Self {
            let localized = r.localized.into_iter().map(|s| super::RecordSpan {
                robot: s.robot,
                chain_id: s.chain_id,
                first_seq: s.first_seq,
                last_seq: s.last_seq,
                passed: s
                    .passed
                    .map(|(nodes, path_m, odometry)| (nodes, path_m, odometry, None, 0.0)),
            });
            super::SiteRecord {
                nodes: r.nodes,
                first_edge: r.first_edge,
                edges: r.edges,
                solved: r.solved,
                pass_fixes: r.pass_fixes,
                localized: localized.collect(),
            }
        }
    }
}

/// Why a record could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Written by a later release.
    #[error("record format {0}: this build reads formats up to {RECORD_FORMAT}")]
    Format(u8),
    /// Bytes that are no record.
    #[error("record: {0}")]
    Damaged(String),
}

impl SiteRecord {
    /// The record's bytes in the log.
    pub fn encode(&self) -> Vec<u8> {
        let mut bytes = vec![RECORD_FORMAT];
        bytes.extend(postcard::to_stdvec(self).expect("a record serializes"));
        bytes
    }

    /// A record read back from the log.
    pub fn decode(bytes: &[u8]) -> Result<SiteRecord, RecordError> {
        match bytes.split_first() {
            Some((&RECORD_FORMAT, rest)) => {
                postcard::from_bytes(rest).map_err(|e| RecordError::Damaged(e.to_string()))
            }
            Some((&RECORD_FORMAT_1, rest)) => postcard::from_bytes::<format1::SiteRecord>(rest)
                .map(Into::into)
                .map_err(|e| RecordError::Damaged(e.to_string())),
            Some((&other, _)) => Err(RecordError::Format(other)),
            None => Err(RecordError::Damaged("empty".into())),
        }
    }

    /// The record as a batch of the store (`fleet`'s, `sequence` in its log), without its
    /// passes' GPS fixes ([`Self::pass_fixes`], which the caller decodes and lends).
    pub fn as_batch<'a>(&'a self, fleet: &'a str, sequence: u64) -> FleetBatch<'a> {
        FleetBatch {
            fleet,
            nodes: self.nodes.iter().map(|(a, b)| (*a, b.as_slice())).collect(),
            senders: Vec::new(),
            clouds: Vec::new(),
            first_edge: self.first_edge,
            edges: self.edges.clone(),
            solved: self
                .solved
                .map(|(seq, taken_after, applied_after)| SolvePoint {
                    seq,
                    taken_after,
                    applied_after,
                }),
            pass_fixes: &[],
            localized: self.localized.iter().map(Into::into).collect(),
            log_sequence: Some(sequence),
        }
    }

    /// The passes' GPS fixes of the record's solve.
    pub fn pass_fixes(&self) -> Result<Vec<slam::GpsEdge>, RecordError> {
        self.pass_fixes
            .iter()
            .map(|f| serde_json::from_slice(f).map_err(|e| RecordError::Damaged(e.to_string())))
            .collect()
    }
}

/// A batch as the records of its site's log, each with its id: nodes in runs of at most
/// [`MAX_RECORD_NODE_BYTES`], the edges, solve and spans in the last.
pub fn records_of(batch: &FleetBatch<'_>) -> Vec<(RecordId, SiteRecord)> {
    let mut records: Vec<(RecordId, SiteRecord)> = Vec::new();
    let mut bytes = 0;
    for (k, &(arrival, node)) in batch.nodes.iter().enumerate() {
        let full = bytes + node.len() > MAX_RECORD_NODE_BYTES;
        if records.is_empty() || full {
            let (robot, chain, seq) = batch.senders[k];
            records.push((RecordId::node(robot, chain, seq), SiteRecord::default()));
            bytes = 0;
        }
        bytes += node.len();
        let record = &mut records.last_mut().expect("pushed above").1;
        record.nodes.push((arrival, node.to_vec()));
    }
    if records.is_empty() {
        records.push((id_without_nodes(batch), SiteRecord::default()));
    }
    let last = &mut records.last_mut().expect("one at least").1;
    last.first_edge = batch.first_edge;
    last.edges = batch.edges.clone();
    last.solved = batch
        .solved
        .map(|p| (p.seq, p.taken_after, p.applied_after));
    last.pass_fixes = batch
        .pass_fixes
        .iter()
        .map(|f| serde_json::to_vec(f).expect("a GPS edge serializes"))
        .collect();
    last.localized = batch.localized.iter().map(Into::into).collect();
    records
}

/// The id of a record without nodes: its solve's number, else its last span's extent, else
/// its edges' first index.
fn id_without_nodes(batch: &FleetBatch<'_>) -> RecordId {
    if let Some(point) = batch.solved {
        return RecordId::named(format!("solve/{}", point.seq));
    }
    if let Some(s) = batch.localized.last() {
        let (robot, chain, first, last) = (&s.robot, s.chain_id, s.first_seq, s.last_seq);
        return RecordId::named(format!("span/{robot}/{chain}/{first}/{last}"));
    }
    RecordId::named(format!("edges/{}/{}", batch.first_edge, batch.edges.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch<'a>(nodes: &'a [Vec<u8>], senders: Vec<(&'a str, u64, u64)>) -> FleetBatch<'a> {
        FleetBatch {
            fleet: "park",
            nodes: nodes
                .iter()
                .enumerate()
                .map(|(k, n)| (10 + k as u64, n.as_slice()))
                .collect(),
            senders,
            first_edge: 7,
            edges: vec![b"{}".to_vec(), b"[]".to_vec()],
            solved: Some(SolvePoint {
                seq: 3,
                taken_after: 9,
                applied_after: 11,
            }),
            localized: vec![fleetmap::LocalizedSpan {
                robot: "r1".into(),
                chain_id: 2,
                first_seq: 4,
                last_seq: 6,
                passed: Some(slam::Passed {
                    nodes: 3,
                    path_m: 2.5,
                    odometry: Some(slam::Pose2::new(1.0, 2.0, 0.5)),
                    pose: Some(slam::Pose2::new(-3.0, 4.0, 0.25)),
                    unlocated_m: 1.5,
                }),
            }],
            ..Default::default()
        }
    }

    #[test]
    fn a_change_reads_back_as_written_and_a_later_format_is_refused() {
        let change = SiteChange::ModesSet {
            robots: Some(vec!["r1".into(), "r2".into()]),
            version: 3,
        };
        let bytes = encode_change(&change);
        assert_eq!(
            LogRecord::decode(&bytes).unwrap(),
            LogRecord::Change(change)
        );
        let batch = SiteRecord::default().encode();
        assert!(matches!(LogRecord::decode(&batch), Ok(LogRecord::Batch(_))));
        let mut later = bytes.clone();
        later[0] = RECORD_FORMAT + 1;
        assert!(matches!(
            LogRecord::decode(&later),
            Err(RecordError::Format(4))
        ));
        assert!(LogRecord::decode(&bytes[..bytes.len() - 1]).is_err());
    }

    #[test]
    fn a_big_batch_splits_into_records_named_by_their_first_node_and_reads_back_whole() {
        let nodes: Vec<Vec<u8>> = (0..5).map(|k| vec![k as u8; 100 * 1024]).collect();
        let senders = (0..5).map(|k| ("r1", 2, 20 + k)).collect();
        let batch = batch(&nodes, senders);
        let records = records_of(&batch);
        // 100 KiB nodes, at most 256 KiB a record: 2 + 2 + 1.
        let ids: Vec<&str> = records.iter().map(|(id, _)| id.as_str()).collect();
        assert_eq!(ids, ["node/r1/2/20", "node/r1/2/22", "node/r1/2/24"]);
        let read: Vec<SiteRecord> = records
            .iter()
            .map(|(_, r)| SiteRecord::decode(&r.encode()).expect("decodes"))
            .collect();
        assert_eq!(
            read,
            records.iter().map(|(_, r)| r.clone()).collect::<Vec<_>>()
        );
        let arrivals: Vec<u64> = read
            .iter()
            .flat_map(|r| r.nodes.iter().map(|n| n.0))
            .collect();
        assert_eq!(arrivals, [10, 11, 12, 13, 14]);
        // The batch's edges, solve and spans come with its last record only.
        assert!(
            read[..2]
                .iter()
                .all(|r| r.edges.is_empty() && r.solved.is_none())
        );
        let back = read[2].as_batch("park", 42);
        assert_eq!((back.first_edge, back.edges.len()), (7, 2));
        assert_eq!(back.solved, batch.solved);
        assert_eq!(back.localized, batch.localized);
        assert_eq!(back.log_sequence, Some(42));
    }

    #[test]
    fn a_batch_without_nodes_is_named_by_its_solve() {
        let records = records_of(&batch(&[], Vec::new()));
        assert_eq!(records.len(), 1);
        assert_eq!(records[0].0.as_str(), "solve/3");
    }

    /// The fixture's GPS fix and edge, and its records by file name.
    fn fixture() -> (
        slam::GpsEdge,
        slam::RelativeEdge,
        Vec<(&'static str, LogRecord)>,
    ) {
        let edge = slam::RelativeEdge {
            from: 4,
            to: 5,
            measurement: slam::Pose2::new(1.25, -0.5, 0.125),
            information: nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(
                100.0, 100.0, 400.0,
            )),
            kind: slam::EdgeKind::ScanMatch,
            robust: slam::Robust::Huber { delta: 1.5 },
        };
        let fix = slam::GpsEdge {
            node: 5,
            position_m: nalgebra::Vector2::new(10.5, -3.25),
            information: nalgebra::Matrix2::from_diagonal(&nalgebra::Vector2::new(4.0, 4.0)),
            lever_arm_m: nalgebra::Vector2::new(0.2, 0.0),
            robust: slam::Robust::Cauchy { c: 2.0 },
        };
        let batch = SiteRecord {
            nodes: vec![
                (10, vec![0x0a, 0x02, b'r', b'1', 0x10, 0x05]),
                (11, vec![0x08, 0x01]),
            ],
            first_edge: 7,
            edges: mapper::store::encode_edges(std::slice::from_ref(&edge)),
            solved: Some((3, 9, 11)),
            pass_fixes: vec![serde_json::to_vec(&fix).unwrap()],
            localized: vec![
                RecordSpan {
                    robot: "r1".into(),
                    chain_id: 2,
                    first_seq: 4,
                    last_seq: 6,
                    passed: Some((3, 2.5, Some((1.0, 2.0, 0.5)), None, 0.0)),
                },
                RecordSpan {
                    robot: "r2".into(),
                    chain_id: 0,
                    first_seq: 1,
                    last_seq: 9,
                    passed: None,
                },
            ],
        };
        let changes = [
            (
                "version-added",
                SiteChange::VersionAdded {
                    number: 2,
                    summary: br#"{"nodes":12}"#.to_vec(),
                    host: "h1".into(),
                },
            ),
            ("version-deleted", SiteChange::VersionDeleted { number: 1 }),
            (
                "modes-set",
                SiteChange::ModesSet {
                    robots: Some(vec!["r1".into()]),
                    version: 2,
                },
            ),
        ];
        // Format 3: the same batch, its pass with the last pass's map pose.
        let mut batch3 = batch.clone();
        batch3.localized[0].passed =
            Some((3, 2.5, Some((1.0, 2.0, 0.5)), Some((-3.0, 4.0, 0.25)), 1.5));
        let mut records = vec![
            ("batch", LogRecord::Batch(batch)),
            ("batch-3", LogRecord::Batch(batch3)),
        ];
        records.extend(changes.map(|(name, c)| (name, LogRecord::Change(c))));
        (fix, edge, records)
    }

    /// Records written by earlier builds (`tests/fixtures/log-records/README.md`) read back
    /// as written, and those of the formats this build writes written alike. A log outlives
    /// the release that wrote it and postcard is not self-describing: a changed field of a
    /// record fails here rather than in the logs of a running cluster (a change is a new
    /// format number).
    #[test]
    fn records_written_by_an_earlier_release_read_back_as_written() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/log-records");
        let (fix, edge, records) = fixture();
        for (name, record) in records {
            let stored = std::fs::read(format!("{dir}/{name}.rec"))
                .unwrap_or_else(|e| panic!("{dir}/{name}.rec: {e}"));
            let read = LogRecord::decode(&stored).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(read, record, "{name}");
            let written = match &record {
                LogRecord::Batch(batch) => batch.encode(),
                LogRecord::Change(change) => encode_change(change),
            };
            if stored[0] == RECORD_FORMAT_1 {
                assert_eq!(
                    written[0], RECORD_FORMAT,
                    "{name}: written in this build's format"
                );
            } else {
                assert!(written == stored, "{name}: this build writes it otherwise");
            }
            if let LogRecord::Batch(batch) = read {
                assert_eq!(batch.pass_fixes().unwrap(), std::slice::from_ref(&fix));
                let edges: Vec<slam::RelativeEdge> = batch
                    .edges
                    .iter()
                    .map(|e| serde_json::from_slice(e).expect("an edge as the store keeps it"))
                    .collect();
                assert_eq!(edges, std::slice::from_ref(&edge));
            }
        }
    }

    #[test]
    fn a_record_of_a_later_format_or_no_record_is_refused() {
        let mut bytes = SiteRecord::default().encode();
        bytes[0] = RECORD_FORMAT + 1;
        assert!(matches!(
            SiteRecord::decode(&bytes),
            Err(RecordError::Format(_))
        ));
        assert!(SiteRecord::decode(&[]).is_err());
        assert!(SiteRecord::decode(&[RECORD_FORMAT, 0xff, 0xff]).is_err());
    }
}
