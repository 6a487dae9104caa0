//! A fleet's map saved as a snapshot, and restored from one: everything of [`FleetMap`] and
//! its `slam::Mapper2d` but the nodes themselves, which the store's `nodes` table holds
//! already (restoring reads them from there: decoding a node costs far less than mapping it).
//!
//! A snapshot is `format (u32 LE) | CRC-32 of the rest (u32 LE) | postcard`. One of another
//! format, a wrong checksum, or one that does not fit the stored nodes is refused: the fleet
//! is then replayed from its nodes, as a store without snapshots is.

use super::{ChainRecord, FleetMap, RobotRecord, SpanReplay};
use serde::{Deserialize, Serialize};
use slam::geodesy::GeoDatum;
use std::sync::Arc;

/// The snapshot format written; others are ignored (the fleet is replayed in full). Raise
/// it whenever what is saved changes shape (a field of `Mapper2d`, its parameters or stats):
/// postcard has no field names, so an old layout may read as wrong values rather than fail.
/// 2: the global search's state, `MapperStats` and `CoverageParams` gained fields.
/// 3: first contact searches whole submaps (`FirstContactParams` changed, hypotheses keep
/// their submaps, pairs get a second look).
/// 4: a chain's passes (`slam::Passed`) keep the last pass's map pose.
pub const SNAPSHOT_FORMAT: u32 = 4;

/// Why a snapshot was not used.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// Too short, another format, a wrong checksum, or postcard could not read it.
    #[error("snapshot unreadable: {0}")]
    Unreadable(String),
    /// It does not fit the stored nodes or the configuration.
    #[error("snapshot does not fit: {0}")]
    Mismatch(String),
}

/// What a snapshot covers: a restore from it replays the nodes and solves after these.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SnapshotCovers {
    /// The first stored nodes it holds.
    pub nodes: u64,
    /// The solves applied in it.
    pub solves: u64,
}

/// One chain of a robot: `ChainRecord` with the fields the API does not show.
#[derive(Serialize, Deserialize)]
struct SavedChain {
    chain_id: u64,
    first_node_seq: u64,
    last_node_seq: u64,
    network_chain: usize,
    last_node: usize,
}

#[derive(Serialize, Deserialize)]
struct SavedRobot {
    id: String,
    last_node_seq: u64,
    chains: Vec<SavedChain>,
}

/// What is written (the mapper by reference).
#[derive(Serialize)]
struct Writing<M: Serialize> {
    nodes: u64,
    datum: Option<GeoDatum>,
    robots: Vec<SavedRobot>,
    network_chains: usize,
    solve_points: u64,
    mapper: M,
}

/// What is read: the same fields, in the same order.
#[derive(Deserialize)]
struct Reading {
    nodes: u64,
    datum: Option<GeoDatum>,
    robots: Vec<SavedRobot>,
    network_chains: usize,
    solve_points: u64,
    mapper: slam::SavedMapper,
}

impl FleetMap {
    /// The map as a snapshot; `None` while a background solve is out (take it after the
    /// solve is applied: its job is not part of the state).
    pub fn snapshot(&self) -> Option<Vec<u8>> {
        let writing = Writing {
            nodes: self.nodes.len() as u64,
            datum: self.datum,
            robots: self
                .robots
                .iter()
                .map(|r| SavedRobot {
                    id: r.id.clone(),
                    last_node_seq: r.last_node_seq,
                    chains: r
                        .chains
                        .iter()
                        .map(|c| SavedChain {
                            chain_id: c.chain_id,
                            first_node_seq: c.first_node_seq,
                            last_node_seq: c.last_node_seq,
                            network_chain: c.network_chain,
                            last_node: c.last_node,
                        })
                        .collect(),
                })
                .collect(),
            network_chains: self.network_chains,
            solve_points: self.solve_points,
            mapper: self.mapper.saved()?,
        };
        let body = postcard::to_stdvec(&writing).expect("the map serializes");
        let mut bytes = Vec::with_capacity(body.len() + 8);
        bytes.extend_from_slice(&SNAPSHOT_FORMAT.to_le_bytes());
        bytes.extend_from_slice(&crc32fast::hash(&body).to_le_bytes());
        bytes.extend_from_slice(&body);
        Some(bytes)
    }

    /// What a snapshot covers (its first `nodes` stored nodes, its first `solves` solve
    /// points), if it is readable.
    pub fn snapshot_covers(bytes: &[u8]) -> Result<SnapshotCovers, SnapshotError> {
        let saved = read(bytes)?;
        Ok(SnapshotCovers {
            nodes: saved.nodes,
            solves: saved.solve_points,
        })
    }

    /// This map (empty, as the configuration makes it) restored from `bytes`, with the
    /// stored nodes it covers (the first of `stored`, encoded); how many it covers. The
    /// localized spans are not in the snapshot: `spans` takes those before the covered nodes
    /// in their place, as a replay does.
    pub fn restore(
        mut self,
        bytes: &[u8],
        stored: &[Vec<u8>],
        spans: &mut SpanReplay,
    ) -> Result<(FleetMap, usize), SnapshotError> {
        let mismatch = |what: String| SnapshotError::Mismatch(what);
        let saved = read(bytes)?;
        let nodes = saved.nodes as usize;
        if nodes > stored.len() || nodes != saved.mapper.nodes() {
            return Err(mismatch(format!(
                "{nodes} nodes ({} mapped) of {} stored",
                saved.mapper.nodes(),
                stored.len()
            )));
        }
        if let (Some(configured), Some(saved)) = (self.datum, saved.datum)
            && configured != saved
        {
            return Err(mismatch("another datum".into()));
        }
        // None saved: no fix yet, so nothing was placed by the datum, as in a replay.
        self.datum = saved.datum.or(self.datum);
        for r in saved.robots {
            self.by_id.insert(r.id.clone(), self.robots.len());
            let chains = r.chains.into_iter().map(|c| ChainRecord {
                chain_id: c.chain_id,
                first_node_seq: c.first_node_seq,
                last_node_seq: c.last_node_seq,
                network_chain: c.network_chain,
                last_node: c.last_node,
            });
            self.robots.push(RobotRecord {
                id: r.id,
                last_node_seq: r.last_node_seq,
                chains: chains.collect(),
                nodes: Vec::new(),
            });
        }
        let mut scans = Vec::with_capacity(nodes);
        for (arrival, bytes) in stored[..nodes].iter().enumerate() {
            let node = wire::decode_node(bytes)
                .map_err(|e| mismatch(format!("stored node {arrival}: {e}")))?;
            let robot = self.robot_index(&node.robot).ok_or_else(|| {
                mismatch(format!(
                    "stored node {arrival}: robot {} unknown",
                    node.robot
                ))
            })?;
            spans.before(&mut self, &node);
            self.localized.close_span(&node.robot, node.chain_id);
            let (record, scan) = self.read_node(&node, robot);
            self.robots[robot].nodes.push(arrival);
            self.nodes.push(Arc::new(record));
            scans.push(scan);
        }
        let chains_ok =
            self.robots.iter().flat_map(|r| &r.chains).all(|c| {
                c.last_node < nodes.max(1) && c.network_chain < saved.network_chains.max(1)
            });
        if !chains_ok {
            return Err(mismatch("a chain names a node it does not hold".into()));
        }
        self.network_chains = saved.network_chains;
        self.solve_points = saved.solve_points;
        self.mapper = saved
            .mapper
            .restore(self.mapper.params(), scans)
            .map_err(|e| mismatch(e.to_string()))?;
        Ok((self, nodes))
    }

    /// Solves applied so far (the next solve point's number).
    pub fn solves_applied(&self) -> u64 {
        self.solve_points
    }
}

/// A snapshot's envelope checked and its body read.
fn read(bytes: &[u8]) -> Result<Reading, SnapshotError> {
    let unreadable = |what: String| SnapshotError::Unreadable(what);
    let (Some(format), Some(crc), Some(body)) = (bytes.get(..4), bytes.get(4..8), bytes.get(8..))
    else {
        return Err(unreadable(format!("{} bytes", bytes.len())));
    };
    let format = u32::from_le_bytes(format.try_into().expect("4 bytes"));
    if format != SNAPSHOT_FORMAT {
        return Err(unreadable(format!(
            "format {format}, this mapper reads {SNAPSHOT_FORMAT}"
        )));
    }
    if u32::from_le_bytes(crc.try_into().expect("4 bytes")) != crc32fast::hash(body) {
        return Err(unreadable("wrong checksum".into()));
    }
    postcard::from_bytes(body).map_err(|e| unreadable(e.to_string()))
}
