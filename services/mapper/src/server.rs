//! The mapping server: Zenoh in, one worker thread mapping every fleet, the store, acks out,
//! the HTTP API beside it.
//!
//! A node goes: Zenoh callback → channel → worker: decode and check → fleet and sequence →
//! map → store commit → ack → new view for HTTP → event. Live odometry is handled in its
//! Zenoh callback (no mapping work), so teleoperation sees it at once.

use crate::config::MapperConfig;
use crate::fleet::{FleetMap, IngestError, Sequence};
use crate::state::{FleetView, LiveOdometry, Metrics, Shared};
use crate::store::Store;
use anyhow::{Context, Result};
use serde_json::json;
use slam::Pose2;
use slam::geodesy::GeoDatum;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::{Duration, Instant};
use wire::session::now_ns;
use wire::{Message, Topic, v1};
use zenoh::Wait;

/// Work for the mapping worker.
pub enum Work {
    Node {
        key: String,
        payload: Vec<u8>,
    },
    /// Re-optimize a fleet now; the reply is the report as JSON.
    Optimize {
        fleet: String,
        reply: tokio::sync::oneshot::Sender<Result<serde_json::Value, String>>,
    },
}

/// A running mapper: its HTTP address and the handle to stop it.
pub struct Running {
    pub http_addr: std::net::SocketAddr,
    pub shared: Arc<Shared>,
    session: zenoh::Session,
    http: tokio::task::JoinHandle<()>,
    worker: Option<std::thread::JoinHandle<()>>,
    work: mpsc::Sender<Work>,
}

impl Running {
    /// Re-optimizes a fleet's network now; the optimizer's report as JSON.
    pub async fn optimize(&self, fleet: &str) -> Result<serde_json::Value> {
        let (reply, answer) = tokio::sync::oneshot::channel();
        self.work
            .send(Work::Optimize {
                fleet: fleet.to_owned(),
                reply,
            })
            .map_err(|_| anyhow::anyhow!("the mapping worker stopped"))?;
        answer
            .await?
            .map_err(|e| anyhow::anyhow!("optimizing fleet {fleet}: {e}"))
    }

    /// Stops accepting, lets the worker finish what it holds, closes the session.
    pub async fn stop(mut self) -> Result<()> {
        self.http.abort();
        drop(self.work);
        let worker = self.worker.take();
        session_close(&self.session).await?;
        if let Some(w) = worker {
            tokio::task::spawn_blocking(move || w.join())
                .await?
                .map_err(|_| anyhow::anyhow!("the mapping worker panicked"))?;
        }
        Ok(())
    }
}

async fn session_close(session: &zenoh::Session) -> Result<()> {
    session.close().await.map_err(anyhow::Error::from_boxed)
}

/// Starts the mapper: restores the store, opens Zenoh and the HTTP listener.
pub async fn start(config: MapperConfig) -> Result<Running> {
    for fleet in &config.fleets {
        wire::validate_id("fleet", fleet)?;
    }
    let store = Store::open(&config.store_path)
        .with_context(|| format!("{}: cannot open the store", config.store_path.display()))?;
    // The worker writes; the HTTP side reads clouds (redb: readers never wait on the writer).
    let store = Arc::new(store);
    let shared = Arc::new(Shared::new(config.token.clone(), now_ns()));
    let fleets = restore(&config, &store, &shared)?;

    let session = config.zenoh.open().await?;
    let (work_tx, work_rx) = mpsc::channel::<Work>();
    let node_keys = format!("{}/*/robots/*/{}", wire::KEY_ROOT, Topic::Node);
    let tx = work_tx.clone();
    let nodes = session
        .declare_subscriber(node_keys)
        .callback(move |sample| {
            let _ = tx.send(Work::Node {
                key: sample.key_expr().as_str().to_owned(),
                payload: sample.payload().to_bytes().into_owned(),
            });
        })
        .await
        .map_err(anyhow::Error::from_boxed)?;
    let odom_keys = format!("{}/*/robots/*/{}", wire::KEY_ROOT, Topic::Odom);
    let (live, known) = (shared.clone(), config.fleets.clone());
    let odometry = session
        .declare_subscriber(odom_keys)
        .callback(move |sample| {
            on_odometry(
                &live,
                &known,
                sample.key_expr().as_str(),
                &sample.payload().to_bytes(),
            )
        })
        .await
        .map_err(anyhow::Error::from_boxed)?;
    // `levelmap/{fleet}/map/{summary,poses}` as Zenoh queries, for robots and tools on the bus.
    let views = shared.clone();
    let queries = session
        .declare_queryable(format!("{}/*/map/*", wire::KEY_ROOT))
        .callback(move |query| {
            let key = query.key_expr().as_str().to_owned();
            if let Some(body) = map_query(&views, &key) {
                let _ = query.reply(key, body.to_string()).wait();
            }
        })
        .await
        .map_err(anyhow::Error::from_boxed)?;
    let subscriptions = (nodes, odometry, queries);

    let worker = {
        let shared = shared.clone();
        let store = store.clone();
        let session = session.clone();
        let config = config.clone();
        std::thread::Builder::new()
            .name("levelmap-mapping".into())
            .spawn(move || {
                // The subscriptions live as long as the worker.
                let _subscriptions = subscriptions;
                worker(config, store, fleets, shared, session, work_rx)
            })?
    };

    let listener = tokio::net::TcpListener::bind(&config.http_listen)
        .await
        .with_context(|| format!("HTTP: cannot listen on {}", config.http_listen))?;
    let http_addr = listener.local_addr()?;
    let app = crate::api::router(shared.clone(), work_tx.clone(), store);
    let http = tokio::spawn(async move {
        if let Err(e) = axum::serve(listener, app).await {
            tracing::error!("HTTP server: {e}");
        }
    });
    Ok(Running {
        http_addr,
        shared,
        session,
        http,
        worker: Some(worker),
        work: work_tx,
    })
}

fn new_fleet(config: &MapperConfig, id: &str) -> FleetMap {
    FleetMap::new(
        id,
        config.mapping.clone(),
        config.datum.map(|origin| GeoDatum { origin }),
        config.max_range_m,
    )
}

/// Replays the store; checks the edges it rebuilt against the stored ones.
fn restore(
    config: &MapperConfig,
    store: &Store,
    shared: &Shared,
) -> Result<HashMap<String, FleetMap>> {
    let mut fleets = HashMap::new();
    for stored in store.load()? {
        let started = Instant::now();
        let mut map = new_fleet(config, &stored.id);
        let mut solves = stored.solves.iter().peekable();
        for (arrival, bytes) in stored.nodes.iter().enumerate() {
            let node = wire::decode_node(bytes)
                .with_context(|| format!("store: a node of fleet {} is unreadable", stored.id))?;
            map.ingest(&node)
                .with_context(|| format!("store: replaying fleet {}", stored.id))?;
            if solves.next_if_eq(&&(arrival as u64)).is_some() {
                map.optimize_now()?;
            }
        }
        let rebuilt: Vec<Vec<u8>> = map
            .graph()
            .edges
            .iter()
            .map(|e| serde_json::to_vec(e).expect("edges serialize"))
            .collect();
        anyhow::ensure!(
            rebuilt == stored.edges,
            "store: fleet {} replays to {} edges that differ from the {} stored",
            stored.id,
            rebuilt.len(),
            stored.edges.len()
        );
        tracing::info!(
            fleet = %stored.id,
            nodes = stored.nodes.len(),
            edges = stored.edges.len(),
            "restored in {:.0} ms",
            started.elapsed().as_secs_f64() * 1e3
        );
        shared.publish_view(FleetView::of(&map, 0.0, now_ns()));
        fleets.insert(stored.id.clone(), map);
    }
    Ok(fleets)
}

/// The answer to a `levelmap/{fleet}/map/{item}` query: `summary` or `poses` (every node's
/// pose), as JSON; `None` for an unknown fleet or item.
fn map_query(shared: &Shared, key: &str) -> Option<serde_json::Value> {
    let mut chunks = key.split('/').skip(1);
    let (fleet, _map, item) = (chunks.next()?, chunks.next()?, chunks.next()?);
    let view = shared.fleet(fleet)?;
    match item {
        "summary" => Some(json!({
            "fleet": view.id,
            "robots": view.robots.len(),
            "nodes": view.poses.len(),
            "edges": view.edges.len(),
            "loop_closures": view.stats.loop_closures,
            "inter_robot_closures": view.stats.inter_robot_closures,
        })),
        "poses" => Some(json!({
            "fleet": view.id,
            "nodes": view.nodes.iter().zip(&view.poses).map(|(n, p)| json!({
                "robot": view.robots[n.robot].id, "node_seq": n.node_seq, "pose": p,
            })).collect::<Vec<_>>(),
        })),
        _ => None,
    }
}

fn on_odometry(shared: &Shared, fleets: &[String], key: &str, payload: &[u8]) {
    let metrics = &shared.metrics;
    let Ok(parsed) = wire::parse_robot_key(key) else {
        metrics.reject("odom", "invalid_key");
        return;
    };
    if !fleets.iter().any(|f| f == parsed.fleet) {
        metrics.reject("odom", "unknown_fleet");
        return;
    }
    let odometry = match wire::decode_odometry(payload) {
        Ok(o) => o,
        Err(e) => {
            metrics.reject("odom", e.reason());
            return;
        }
    };
    let header = odometry.header.as_ref().expect("validated");
    if header.fleet_id != parsed.fleet || header.robot_id != parsed.robot {
        metrics.reject("odom", "key_mismatch");
        return;
    }
    let pose = wire::odometry_from_wire(&odometry).expect("validated");
    Metrics::bump(&metrics.odometry_received);
    let now = now_ns();
    let odometry = Pose2::from_isometry3(&pose.pose);
    // A `pose` event on the stream at most POSE_EVENT_PERIOD_NS apart per robot.
    let due = {
        let mut live = shared.live.lock().expect("live lock");
        let key = (parsed.fleet.to_owned(), parsed.robot.to_owned());
        let last_event = live.get(&key).map_or(0, |p| p.evented_ns);
        let due = now.saturating_sub(last_event) >= POSE_EVENT_PERIOD_NS;
        let evented_ns = if due { now } else { last_event };
        live.insert(
            key,
            LiveOdometry {
                odometry,
                stamp_ns: pose.stamp_ns,
                received_ns: now,
                evented_ns,
            },
        );
        due
    };
    let map_pose = || {
        let view = shared.fleet(parsed.fleet)?;
        Some(view.robot(parsed.robot)?.live_pose(&odometry))
    };
    if let Some(map_pose) = due.then(map_pose).flatten() {
        shared.event(&json!({
            "type": "pose",
            "fleet": parsed.fleet,
            "robot": parsed.robot,
            "pose": map_pose,
            "stamp_ns": pose.stamp_ns,
        }));
    }
}

/// Live poses go on the event stream at most 2 Hz per robot (odometry arrives at 10 Hz or
/// more; `GET …/robots` has every one).
const POSE_EVENT_PERIOD_NS: u64 = 500_000_000;

/// Most messages taken into one batch (one solve, one store commit).
const MAX_BATCH: usize = 512;

/// A node mapped in this batch, not yet committed.
struct Accepted {
    fleet: String,
    robot: String,
    node_seq: u64,
    node: usize,
    arrival: u64,
    /// The node as stored: as received, without its cloud.
    payload: Vec<u8>,
    /// Its encoded `Node.cloud`, stored apart.
    cloud: Option<Vec<u8>>,
}

/// Takes what arrived, maps every node, solves each touched fleet once, commits it all in one
/// transaction, then acks and publishes: under load, nodes batch up instead of queueing
/// behind one solve each.
fn worker(
    config: MapperConfig,
    store: Arc<Store>,
    mut fleets: HashMap<String, FleetMap>,
    shared: Arc<Shared>,
    session: zenoh::Session,
    work: mpsc::Receiver<Work>,
) {
    let mut edges_stored: HashMap<String, usize> = fleets
        .iter()
        .map(|(id, map)| (id.clone(), map.graph().edges.len()))
        .collect();
    let ctx = NodeContext {
        config: &config,
        shared: &shared,
        session: &session,
    };
    let mut store_failed = false;
    let mut last_solve: HashMap<String, Instant> = HashMap::new();
    loop {
        // Wake up for a solve that is due even when nothing arrives.
        let first = match work.recv_timeout(Duration::from_millis(config.solve_interval_ms.max(10)))
        {
            Ok(w) => Some(w),
            Err(mpsc::RecvTimeoutError::Timeout) => None,
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        };
        let started = Instant::now();
        let mut batch: Vec<Work> = first.into_iter().collect();
        while !batch.is_empty() && batch.len() < MAX_BATCH {
            match work.try_recv() {
                Ok(w) => batch.push(w),
                Err(_) => break,
            }
        }
        let mut accepted = Vec::new();
        let mut reacks = Vec::new();
        let mut requests = Vec::new();
        for job in batch {
            match job {
                Work::Node { key, payload } if !store_failed => {
                    accepted.extend(ctx.on_node(&mut fleets, &key, payload, &mut reacks));
                }
                Work::Node { key, .. } => ctx.reject("store", &key, &"the store failed"),
                Work::Optimize { fleet, reply } => requests.push((fleet, reply)),
            }
        }
        // Solve each fleet that got nodes once, then commit nodes, edges and solves together.
        let mut touched: Vec<&str> = accepted.iter().map(|a| a.fleet.as_str()).collect();
        touched.sort_unstable();
        touched.dedup();
        let mut batches = Vec::new();
        for &fleet in &touched {
            let map = &fleets[fleet];
            let stored = edges_stored.entry(fleet.to_owned()).or_default();
            let edges: Vec<Vec<u8>> = map.graph().edges[*stored..]
                .iter()
                .map(|e| serde_json::to_vec(e).expect("edges serialize"))
                .collect();
            let nodes: Vec<(u64, &[u8])> = accepted
                .iter()
                .filter(|a| a.fleet == fleet)
                .map(|a| (a.arrival, a.payload.as_slice()))
                .collect();
            let clouds: Vec<(u64, &[u8])> = accepted
                .iter()
                .filter(|a| a.fleet == fleet)
                .filter_map(|a| Some((a.node as u64, a.cloud.as_deref()?)))
                .collect();
            batches.push(crate::store::FleetBatch {
                fleet,
                solved_after: None,
                nodes,
                clouds,
                first_edge: *stored as u64,
                edges,
            });
        }
        if !batches.is_empty() {
            if let Err(e) = store.commit(&batches) {
                // Not durable, so not acked: the robots keep these nodes and re-send them to
                // the restarted mapper. This one stops taking nodes rather than diverge from
                // its store.
                tracing::error!("store commit failed; restart the mapper: {e}");
                store_failed = true;
                shared.healthy.store(false, Ordering::Relaxed);
                continue;
            }
            for b in &batches {
                *edges_stored.get_mut(b.fleet).expect("counted above") += b.edges.len();
            }
        }
        drop(batches);
        // Ack each robot's highest node, publish the new views and events.
        let mut acks: HashMap<(&str, &str), u64> = HashMap::new();
        for (fleet, robot) in &reacks {
            let map = &fleets[fleet];
            if let Some(r) = map.robot_index(robot) {
                acks.insert((fleet, robot), map.robots()[r].last_node_seq);
            }
        }
        for a in &accepted {
            Metrics::bump(&shared.metrics.nodes_accepted);
            let seq = acks.entry((&a.fleet, &a.robot)).or_default();
            *seq = (*seq).max(a.node_seq);
        }
        for ((fleet, robot), seq) in acks {
            ctx.ack(fleet, robot, seq);
        }
        let ms = started.elapsed().as_secs_f64() * 1e3;
        for &fleet in &touched {
            shared.publish_view(FleetView::of(&fleets[fleet], ms, now_ns()));
        }
        for a in &accepted {
            let map = &fleets[&a.fleet];
            shared.event(&json!({
                "type": "node",
                "fleet": a.fleet,
                "robot": a.robot,
                "node": a.node,
                "node_seq": a.node_seq,
                "pose": map.poses()[a.node],
            }));
        }
        // Solve after the batch is visible, at most every solve interval per fleet: nodes
        // arriving meanwhile wait for one solve at most, not for one each. The solve point is
        // committed before the next node is mapped, so a replay solves at the same place.
        let interval = Duration::from_millis(config.solve_interval_ms);
        for (id, map) in fleets.iter_mut() {
            if last_solve
                .get(id)
                .is_some_and(|t: &Instant| t.elapsed() < interval)
            {
                continue;
            }
            let solve_started = Instant::now();
            match map.optimize_pending() {
                Ok(false) => continue,
                Ok(true) => {}
                Err(e) => {
                    tracing::error!(fleet = %id, "optimization failed: {e}");
                    continue;
                }
            }
            last_solve.insert(id.clone(), Instant::now());
            Metrics::bump(&shared.metrics.optimizations);
            let marker = crate::store::FleetBatch {
                fleet: id,
                solved_after: Some(map.nodes().len() as u64 - 1),
                ..Default::default()
            };
            if let Err(e) = store.commit(&[marker]) {
                tracing::error!("store commit failed; restart the mapper: {e}");
                store_failed = true;
                shared.healthy.store(false, Ordering::Relaxed);
                break;
            }
            let ms = solve_started.elapsed().as_secs_f64() * 1e3;
            shared.publish_view(FleetView::of(map, ms, now_ns()));
            ctx.publish_poses(map);
        }
        for (fleet, reply) in requests {
            let result = match fleets.get_mut(&fleet) {
                None => Err(format!("no fleet {fleet}")),
                Some(map) => match map.optimize_now() {
                    Ok(ran) => {
                        let marker = crate::store::FleetBatch {
                            fleet: &fleet,
                            solved_after: Some(map.nodes().len() as u64 - 1),
                            ..Default::default()
                        };
                        match (ran, store_failed) {
                            (false, _) => Err("part of the network is not anchored yet".into()),
                            (true, true) => Err("the store failed".into()),
                            (true, false) => match store.commit(&[marker]) {
                                Err(e) => {
                                    tracing::error!("store commit failed; restart the mapper: {e}");
                                    store_failed = true;
                                    shared.healthy.store(false, Ordering::Relaxed);
                                    Err(e.to_string())
                                }
                                Ok(()) => {
                                    Metrics::bump(&shared.metrics.optimizations);
                                    shared.publish_view(FleetView::of(map, 0.0, now_ns()));
                                    ctx.publish_poses(map);
                                    Ok(serde_json::to_value(map.last_optimization())
                                        .expect("report serializes"))
                                }
                            },
                        }
                    }
                    Err(e) => Err(e.to_string()),
                },
            };
            let _ = reply.send(result);
        }
    }
}

struct NodeContext<'a> {
    config: &'a MapperConfig,
    shared: &'a Shared,
    session: &'a zenoh::Session,
}

impl NodeContext<'_> {
    fn reject(&self, reason: &'static str, key: &str, detail: &dyn std::fmt::Display) {
        self.shared.metrics.reject("node", reason);
        tracing::warn!(key, reason, "node rejected: {detail}");
    }

    fn ack(&self, fleet: &str, robot: &str, acked: u64) {
        let ack = v1::Ack {
            header: Some(v1::Header::new(fleet, robot, 0, now_ns(), now_ns())),
            acked_node_seq: acked,
        };
        let Ok(key) = wire::ack_key(fleet, robot) else {
            return;
        };
        match self.session.put(key, ack.encode_to_vec()).wait() {
            Ok(()) => Metrics::bump(&self.shared.metrics.acks_sent),
            Err(e) => tracing::warn!(fleet, robot, "ack not sent: {e}"),
        }
    }

    /// Checks and maps one node; `None` when it was rejected or a duplicate (re-acked).
    fn on_node(
        &self,
        fleets: &mut HashMap<String, FleetMap>,
        key: &str,
        payload: Vec<u8>,
        reacks: &mut Vec<(String, String)>,
    ) -> Option<Accepted> {
        let Ok(parsed) = wire::parse_robot_key(key) else {
            self.reject("invalid_key", key, &"not a levelmap node key");
            return None;
        };
        let (fleet, robot) = (parsed.fleet.to_owned(), parsed.robot.to_owned());
        if !self.config.fleets.contains(&fleet) {
            self.reject(
                "unknown_fleet",
                key,
                &format!("fleet {fleet} is not served"),
            );
            return None;
        }
        let mut node = match wire::decode_node(&payload) {
            Ok(n) => n,
            Err(e) => {
                self.reject(e.reason(), key, &e);
                return None;
            }
        };
        let header = node.header.as_ref().expect("validated");
        if header.fleet_id != fleet || header.robot_id != robot {
            self.reject(
                "key_mismatch",
                key,
                &format!("header says {}/{}", header.fleet_id, header.robot_id),
            );
            return None;
        }
        let map = fleets
            .entry(fleet.clone())
            .or_insert_with(|| new_fleet(self.config, &fleet));
        match map.sequence(&robot, node.node_seq) {
            Sequence::Next => {}
            Sequence::Duplicate => {
                // Taken already: its ack was lost, so ack again once this batch is durable.
                Metrics::bump(&self.shared.metrics.nodes_duplicate);
                reacks.push((fleet, robot));
                return None;
            }
            Sequence::Gap { expected } => {
                self.reject(
                    "out_of_order",
                    key,
                    &format!("node {} before {expected}", node.node_seq),
                );
                // The ack tells the robot where to re-send from.
                reacks.push((fleet, robot));
                return None;
            }
        }
        let arrival = map.nodes().len() as u64;
        match map.ingest(&node) {
            Ok(ingested) => {
                // The cloud goes to its own table: the node is stored (and replayed) without.
                let (payload, cloud) = crate::store::split_cloud(&mut node, payload);
                Some(Accepted {
                    fleet,
                    robot,
                    node_seq: node.node_seq,
                    node: ingested.node,
                    arrival,
                    payload,
                    cloud,
                })
            }
            Err(IngestError::Graph(e)) => {
                tracing::error!(key, "node not mapped: {e}");
                self.shared.metrics.reject("node", "graph");
                None
            }
            Err(e) => {
                self.reject("invalid_value", key, &e);
                None
            }
        }
    }

    /// Corrected poses of every robot's last node on `levelmap/{fleet}/map/poses` (JSON).
    fn publish_poses(&self, map: &FleetMap) {
        let poses: Vec<serde_json::Value> = map
            .robots()
            .iter()
            .filter_map(|r| {
                let &last = r.nodes.last()?;
                Some(json!({"robot": r.id, "node_seq": r.last_node_seq, "pose": map.poses()[last]}))
            })
            .collect();
        let body = json!({"fleet": map.id(), "poses": poses});
        if let Ok(key) = wire::map_key(map.id(), "poses") {
            let _ = self.session.put(key, body.to_string()).wait();
        }
        self.shared
            .event(&json!({"type": "optimized", "fleet": map.id()}));
    }
}
