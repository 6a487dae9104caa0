//! The mapping worker: one thread owns every fleet's map and the store's writer.
//!
//! Each turn: take a batch → check each node → map it → commit the batch → ack → publish
//! views and events → apply the solves the solver thread finished and send out the due ones
//! (the `solving` module) → answer operator requests. Under load, nodes batch up (one commit
//! per batch) and the whole network is solved beside them, not between them.
//! The worker is the single writer: every change of a site's record (a batch, a version, a
//! change of modes) is an entry it makes durable through the journal ([`crate::journal`])
//! before it acks or answers. A node is acked only once it is committed. A failed commit (a
//! full disk) keeps what the maps took but the store did not (`Unstored`): no node is taken
//! meanwhile, the commit is tried again every second, and its nodes are acked once it
//! succeeds; the robots keep re-sending the rest. A site whose log alone failed waits alone
//! in the same way. Nodes of a quarantined fleet (its store did not replay) are not taken.

use crate::bus::Outbound;
use crate::config::MapperConfig;
use crate::inbox::Work;
use crate::journal::Journal;
use crate::views::instruments::Instruments;
use crate::views::{Metrics, Shared};
use commit::Unstored;
use fleetmap::{FleetMap, IngestError, Sequence};
use serde_json::json;
use solving::{SolveRequest, Solving};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};
use wire::Node;

mod commit;
mod localizing;
mod sites;
mod snapshots;
mod solving;

/// Most messages taken into one batch (one solve, one store commit).
const MAX_BATCH: usize = 512;

/// A node that passed the checks: who sent it, what it holds, what is stored of it.
struct Checked {
    input: Node,
    /// The node as stored: as received, without its cloud.
    payload: Vec<u8>,
    /// Its encoded `Node.cloud`, stored apart.
    cloud: Option<Vec<u8>>,
}

/// A node mapped in this batch, not yet committed.
struct Accepted {
    fleet: String,
    robot: String,
    chain_id: u64,
    node_seq: u64,
    /// Its index in the fleet's map.
    node: usize,
    /// Its arrival index in the fleet (the store's node key).
    arrival: u64,
    payload: Vec<u8>,
    cloud: Option<Vec<u8>>,
    /// When it reached the mapper.
    received: Instant,
}

/// A robot's chain to re-ack (a duplicate or a gap): its highest node taken, and where to
/// re-send from after a gap.
struct Reack {
    fleet: String,
    robot: String,
    chain_id: u64,
    resend_from: Option<u64>,
}

/// What one batch brought.
#[derive(Default)]
struct Batch {
    accepted: Vec<Accepted>,
    reacks: Vec<Reack>,
    /// Nodes of localizing robots: taken, not mapped.
    localized: Vec<localizing::LocalizedNode>,
    requests: Vec<(String, SolveRequest)>,
    /// A stop was asked for: this is the last turn.
    stop: bool,
}

/// The worker's state: the maps, and what of them is stored.
pub struct Worker {
    config: MapperConfig,
    fleets: HashMap<String, FleetMap>,
    shared: Arc<Shared>,
    /// Where acks, localizations and corrected poses go (the Zenoh bus).
    bus: Box<dyn Outbound>,
    /// Per fleet, how many of its edges are stored.
    edges_stored: HashMap<String, usize>,
    /// The solver thread and the solves out on it.
    solving: Solving,
    /// Set by a failed commit, until it is committed: no node is taken meanwhile.
    unstored: Option<Unstored>,
    /// When to try the failed commit again.
    retry_at: Instant,
    /// Per fleet, robots' modes and the trackers of those that localize.
    localizing: HashMap<String, crate::localization::Localizing>,
    /// Per fleet, the nodes its stored snapshot covers.
    snapshots: HashMap<String, usize>,
    /// Makes the entries durable: the store, or in cluster mode the sites' logs first.
    journal: Box<dyn Journal>,
}

impl Worker {
    /// A worker over the restored `fleets` (all of it stored), their robots' modes in
    /// `localizing`, writing through `journal`.
    pub fn new(
        config: MapperConfig,
        fleets: HashMap<String, FleetMap>,
        localizing: HashMap<String, crate::localization::Localizing>,
        shared: Arc<Shared>,
        bus: Box<dyn Outbound>,
        journal: Box<dyn Journal>,
    ) -> Worker {
        let edges_stored = fleets
            .iter()
            .map(|(id, map)| (id.clone(), map.graph().edges.len()))
            .collect();
        Worker {
            config,
            fleets,
            shared,
            bus,
            edges_stored,
            solving: Solving::start(),
            unstored: None,
            retry_at: Instant::now(),
            localizing,
            snapshots: HashMap::new(),
            journal,
        }
    }

    /// Runs until every sender of `work` is gone.
    pub fn run(mut self, work: &mpsc::Receiver<Work>) {
        let interval = Duration::from_millis(self.config.solve_interval_ms.max(10));
        while let Some(jobs) = take_batch(work, self.solving.wake(interval)) {
            let started = Instant::now();
            self.retry_store();
            let mut batch = self.check_and_map(jobs);
            let (requests, stop) = (std::mem::take(&mut batch.requests), batch.stop);
            self.store_and_ack(
                Unstored {
                    batch,
                    ..Unstored::default()
                },
                started,
            );
            self.solve_requests(requests);
            if stop {
                break;
            }
        }
        self.stop_solving();
        if let Some(unstored) = &self.unstored {
            let nodes = unstored.batch.accepted.len();
            tracing::warn!(
                nodes,
                "stopped with a batch not stored: its robots keep its nodes"
            );
        }
    }

    /// Checks and maps every node of the batch; sets the operator requests aside.
    fn check_and_map(&mut self, jobs: Vec<Work>) -> Batch {
        let mut batch = Batch::default();
        for job in jobs {
            match job {
                // Counted, not logged: robots re-send every second while the store is down.
                Work::Node { key, .. } if self.waits(&key) => {
                    self.shared.metrics.reject("node", "store")
                }
                Work::Node { key, .. } if self.quarantined(&key) => {
                    self.shared.metrics.reject("node", "quarantined")
                }
                Work::Node {
                    key,
                    payload,
                    received,
                } => {
                    if let Some(checked) = self.check(&key, payload) {
                        self.map(&key, checked, received, &mut batch);
                    }
                }
                Work::Optimize { fleet, reply } => {
                    batch.requests.push((fleet, SolveRequest::Optimize(reply)))
                }
                Work::TakeSolve { fleet, reply } => {
                    batch.requests.push((fleet, SolveRequest::Take(reply)))
                }
                Work::ApplySolve { fleet, reply } => {
                    batch.requests.push((fleet, SolveRequest::Apply(reply)))
                }
                Work::SetModes {
                    fleet,
                    modes,
                    maps,
                    reply,
                } => {
                    self.set_modes(&fleet, modes, maps);
                    let _ = reply.send(());
                }
                Work::Adopt {
                    site,
                    map,
                    covered,
                    reply,
                } => {
                    self.adopt(site, *map, covered);
                    let _ = reply.send(());
                }
                Work::Change {
                    site,
                    change,
                    file,
                    asked_ns,
                    reply,
                } => {
                    let done = self.change_site(&site, &change, file, asked_ns, &mut batch);
                    let _ = reply.send(done);
                }
                Work::Drop { site, reply } => {
                    self.drop_site(&site, "its lease was lost", &mut batch);
                    let _ = reply.send(());
                }
                Work::Stop => batch.stop = true,
            }
        }
        batch
    }

    /// A node from `key`, decoded and checked: a served fleet, a valid message, the sender
    /// its key names. `None` (counted, logged) otherwise.
    fn check(&self, key: &str, payload: Vec<u8>) -> Option<Checked> {
        let Ok(parsed) = wire::parse_robot_key(key) else {
            self.reject("invalid_key", key, &"not a levelmap node key");
            return None;
        };
        if !self.config.fleets.iter().any(|f| f == parsed.fleet) {
            let why = format!("fleet {} is not served", parsed.fleet);
            self.reject("unknown_fleet", key, &why);
            return None;
        }
        if !self.owns(parsed.fleet) {
            // Another host's site (a node that reached this host as the site moved). Counted only.
            self.shared.metrics.reject("node", "not_owner");
            return None;
        }
        let input = match wire::decode_node(&payload) {
            Ok(d) => d,
            Err(e) => {
                self.reject(e.reason(), key, &e);
                return None;
            }
        };
        if input.fleet != parsed.fleet || input.robot != parsed.robot {
            let why = format!("header says {}/{}", input.fleet, input.robot);
            self.reject("key_mismatch", key, &why);
            return None;
        }
        // The cloud goes to its own table: the node is stored (and replayed) without it.
        let (payload, cloud) = wire::split_node_cloud(payload);
        Some(Checked {
            input,
            payload,
            cloud,
        })
    }

    /// Maps a checked node if it is the next of its robot (or localizes it, if its robot
    /// localizes); a duplicate or a node after a gap is not mapped, and its robot is
    /// re-acked (the ack says where to re-send from).
    fn map(&mut self, key: &str, checked: Checked, received: Instant, batch: &mut Batch) {
        let reacks = &mut batch.reacks;
        let Checked {
            input,
            payload,
            cloud,
        } = checked;
        let (fleet, robot) = (input.fleet.clone(), input.robot.clone());
        let config = &self.config;
        let map = self
            .fleets
            .entry(fleet.clone())
            .or_insert_with(|| crate::mapping::new_fleet(config, &fleet));
        let reack = |resend_from| Reack {
            fleet: fleet.clone(),
            robot: robot.clone(),
            chain_id: input.chain_id,
            resend_from,
        };
        match map.sequence(&input) {
            Sequence::Next => {}
            Sequence::Duplicate => {
                // Taken already: its ack was lost, so ack again once this batch is durable.
                Metrics::bump(&self.shared.metrics.nodes_duplicate);
                reacks.push(reack(None));
                return;
            }
            Sequence::Gap { expected } => {
                let why = format!("node {} before {expected}", input.node_seq);
                self.reject("out_of_order", key, &why);
                reacks.push(reack(Some(expected)));
                return;
            }
        }
        if let Some(version) = self.localizes(&fleet, &robot) {
            self.localize(key, &input, version, batch);
            return;
        }
        let map = self.fleets.get_mut(&fleet).expect("made above");
        if let Some(pose) = map.pass(&input) {
            self.take_passed(key, &input, pose, batch);
            return;
        }
        let map = self.fleets.get_mut(&fleet).expect("made above");
        let arrival = map.nodes().len() as u64;
        let accepted = match map.ingest(&input) {
            Ok(ingested) => {
                if let Some(e) = &ingested.odometry_break {
                    // Taken, but its odometry link is not: counted under the reason.
                    tracing::warn!(key, "odometry break, a new odometry chain starts: {e}");
                    self.shared.metrics.reject("odometry_step", e.reason());
                }
                Some(Accepted {
                    fleet,
                    robot,
                    chain_id: input.chain_id,
                    node_seq: input.node_seq,
                    node: ingested.node,
                    arrival,
                    payload,
                    cloud,
                    received,
                })
            }
            Err(IngestError::Graph(e)) => {
                tracing::error!(key, "node not mapped: {e}");
                self.shared.metrics.reject("node", "graph");
                None
            }
            Err(IngestError::Refused { source, .. }) => {
                self.reject(source.reason(), key, &source);
                None
            }
            Err(e) => {
                self.reject("invalid_value", key, &e);
                None
            }
        };
        batch.accepted.extend(accepted);
    }

    /// Whether `key` is a node of a site whose last entries are not durable yet (all of
    /// them, when the store failed).
    fn waits(&self, key: &str) -> bool {
        match wire::parse_robot_key(key) {
            Ok(k) => self.site_waits(k.fleet),
            Err(_) => self.store_stalled(),
        }
    }

    /// Whether `key` is a node of a quarantined fleet.
    fn quarantined(&self, key: &str) -> bool {
        wire::parse_robot_key(key).is_ok_and(|k| self.shared.quarantine(k.fleet).is_some())
    }

    /// Acks each robot chain's highest node taken, once per chain, with where to re-send
    /// from when the batch showed a gap.
    fn ack(&self, batch: &Batch) {
        type Chain<'a> = (&'a str, &'a str, u64);
        let mut resend: HashMap<Chain, Option<u64>> = HashMap::new();
        for r in &batch.reacks {
            let entry = resend.entry((&r.fleet, &r.robot, r.chain_id)).or_default();
            *entry = (*entry).or(r.resend_from);
        }
        for a in &batch.accepted {
            Metrics::bump(&self.shared.metrics.nodes_accepted);
            Instruments::time(&self.shared.instruments.node_ack, a.received.elapsed());
            resend.entry((&a.fleet, &a.robot, a.chain_id)).or_default();
        }
        for l in &batch.localized {
            resend.entry((&l.fleet, &l.robot, l.chain_id)).or_default();
        }
        for ((fleet, robot, chain_id), resend_from) in resend {
            let acked = self.fleets[fleet].chain_acked(robot, chain_id);
            // A gap the batch filled after all needs no re-send.
            let resend_from = resend_from.filter(|&r| acked.is_none_or(|a| r > a));
            let ack = crate::bus::AckOf {
                fleet,
                robot,
                chain_id,
                acked,
                resend_from,
            };
            self.bus.ack(&self.shared.metrics, &ack);
        }
    }

    /// New views of the fleets that got nodes, and a `node` event per node.
    fn publish(&self, accepted: &[Accepted], started: Instant) {
        let ms = started.elapsed().as_secs_f64() * 1e3;
        for fleet in fleets_of(accepted) {
            self.shared.publish_map(&self.fleets[fleet], ms);
        }
        for a in accepted {
            let map = &self.fleets[&a.fleet];
            self.shared.event(&json!({
                "type": "node",
                "fleet": a.fleet,
                "robot": a.robot,
                "node": a.node,
                "node_seq": a.node_seq,
                "pose": map.poses()[a.node],
            }));
        }
    }

    fn reject(&self, reason: &'static str, key: &str, detail: &dyn std::fmt::Display) {
        self.shared.metrics.reject("node", reason);
        tracing::warn!(key, reason, "node rejected: {detail}");
    }
}

/// The fleets that got nodes, each once.
fn fleets_of(accepted: &[Accepted]) -> Vec<&str> {
    let mut fleets: Vec<&str> = accepted.iter().map(|a| a.fleet.as_str()).collect();
    fleets.sort_unstable();
    fleets.dedup();
    fleets
}

/// What arrived: waits up to `wake` for the first message (a solve may be due even when
/// nothing arrives), then takes what is queued, up to [`MAX_BATCH`]. `None` once every
/// sender is gone.
fn take_batch(work: &mpsc::Receiver<Work>, wake: Duration) -> Option<Vec<Work>> {
    let first = match work.recv_timeout(wake) {
        Ok(w) => w,
        Err(mpsc::RecvTimeoutError::Timeout) => return Some(Vec::new()),
        Err(mpsc::RecvTimeoutError::Disconnected) => return None,
    };
    let mut batch = vec![first];
    while batch.len() < MAX_BATCH {
        match work.try_recv() {
            Ok(w) => batch.push(w),
            Err(_) => break,
        }
    }
    Some(batch)
}

#[cfg(test)]
mod tests;
