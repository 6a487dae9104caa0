//! The edge service: source → nodes → outbox → Zenoh, until the mapper acks.
//!
//! Measurements are paced in (scaled) real time on a blocking thread, which also levels the
//! scans and commits each node to the outbox before it is sent. The async loop publishes new
//! nodes in order, live odometry best effort, takes the mapper's acks, and re-sends every
//! unacked node, in order, when no ack progress was seen for `resend_after_ms` (a put made
//! before the mapper's subscription reached us, a radio outage, a mapper restart).

use crate::config::EdgeConfig;
use crate::node::NodeBuilder;
use crate::outbox::Outbox;
use crate::source::{Source, SourceEvent};
use anyhow::{Context, Result};
use serde::Serialize;
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use wire::session::now_ns;
use wire::{Message, v1};
use zenoh::qos::CongestionControl;

/// Most nodes sent in one burst of re-sending.
const RESEND_WINDOW: usize = 64;

/// What an edge service did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct EdgeReport {
    pub robot: String,
    /// Nodes made (committed to the outbox) by this run.
    pub nodes: u64,
    /// Node publications, first sends and re-sends.
    pub node_sends: u64,
    pub node_resends: u64,
    pub odometry_sent: u64,
    /// Highest node_seq the mapper acked, if any.
    pub acked_node_seq: Option<u64>,
    /// Nodes still waiting for their ack at exit (they stay in the outbox for the next run).
    pub outbox_pending: u64,
    /// Scans the leveling could not use (logged).
    pub scan_errors: u64,
    /// Corrected poses the mapper sent back after its solves, and the latest: this robot's
    /// last node on the map.
    pub map_pose_updates: u64,
    pub map_pose: Option<slam::Pose2>,
}

enum Produced {
    Node,
    Odometry(Box<v1::Odometry>),
    ScanError,
    End,
}

/// Runs the edge service until the source ends and every node is acked, or `shutdown`
/// completes. With `linger_for_acks` false it stops as soon as the source ends.
pub async fn run(
    config: EdgeConfig,
    source: Box<dyn Source>,
    shutdown: impl Future<Output = ()>,
) -> Result<EdgeReport> {
    wire::validate_id("fleet", &config.fleet)?;
    wire::validate_id("robot", &config.robot)?;
    let outbox =
        Arc::new(Outbox::open(&config.outbox_path).with_context(|| {
            format!("{}: cannot open the outbox", config.outbox_path.display())
        })?);
    let session = config.zenoh.open().await?;
    let node_key = wire::node_key(&config.fleet, &config.robot)?;
    let odom_key = wire::odom_key(&config.fleet, &config.robot)?;
    let ack_key = wire::ack_key(&config.fleet, &config.robot)?;
    let node_pub = session
        .declare_publisher(node_key)
        .congestion_control(CongestionControl::Block)
        .await
        .map_err(anyhow::Error::from_boxed)?;
    let odom_pub = session
        .declare_publisher(odom_key)
        .congestion_control(CongestionControl::Drop)
        .await
        .map_err(anyhow::Error::from_boxed)?;
    let acks = session
        .declare_subscriber(ack_key)
        .await
        .map_err(anyhow::Error::from_boxed)?;
    let map_poses = session
        .declare_subscriber(wire::map_key(&config.fleet, "poses")?)
        .await
        .map_err(anyhow::Error::from_boxed)?;

    let (tx, mut rx) = mpsc::channel::<Produced>(256);
    let producer = {
        let outbox = outbox.clone();
        let config = config.clone();
        tokio::task::spawn_blocking(move || produce(config, source, outbox, tx))
    };

    let mut report = EdgeReport {
        robot: config.robot.clone(),
        ..Default::default()
    };
    let mut header_seq = 0u64;
    let mut next_to_send = outbox.acked_below()?;
    let mut last_progress = Instant::now();
    let resend_after = Duration::from_millis(config.resend_after_ms);
    let mut source_done = false;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    tokio::pin!(shutdown);

    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            produced = rx.recv(), if !source_done => match produced {
                Some(Produced::Node) => {
                    report.nodes += 1;
                    // The ack timer runs from the newest send, not from the last ack.
                    last_progress = Instant::now();
                    next_to_send = send_pending(&outbox, &node_pub, next_to_send, &mut header_seq, &mut report).await?;
                }
                Some(Produced::Odometry(mut odometry)) => {
                    header_seq += 1;
                    if let Some(h) = odometry.header.as_mut() {
                        h.seq = header_seq;
                        h.sent_ns = now_ns();
                    }
                    if odom_pub.put(odometry.encode_to_vec()).await.is_ok() {
                        report.odometry_sent += 1;
                    }
                }
                Some(Produced::ScanError) => report.scan_errors += 1,
                Some(Produced::End) | None => {
                    source_done = true;
                    if !config.linger_for_acks { break; }
                }
            },
            sample = acks.recv_async() => {
                let Ok(sample) = sample else { break };
                match wire::decode_ack(&sample.payload().to_bytes()) {
                    Ok(ack) => {
                        let seq = ack.acked_node_seq;
                        if report.acked_node_seq.is_none_or(|a| seq > a) {
                            report.acked_node_seq = Some(seq);
                            last_progress = Instant::now();
                        }
                        outbox.ack(seq)?;
                        next_to_send = next_to_send.max(seq + 1);
                    }
                    Err(e) => tracing::warn!(robot = %config.robot, "bad ack: {e}"),
                }
            }
            sample = map_poses.recv_async() => {
                let Ok(sample) = sample else { break };
                // The mapper's corrected pose of this robot's last node.
                match wire::decode_map_poses(&sample.payload().to_bytes()) {
                    Ok((_, poses)) => {
                        if let Some(p) = poses.into_iter().find(|p| p.robot == config.robot) {
                            report.map_pose_updates += 1;
                            report.map_pose = Some(p.pose);
                        }
                    }
                    Err(e) => tracing::warn!(robot = %config.robot, "bad map poses: {e}"),
                }
            }
            _ = tick.tick() => {
                let pending = outbox.len()?;
                if source_done && pending == 0 {
                    break;
                }
                if pending > 0 && last_progress.elapsed() >= resend_after {
                    let from = outbox.acked_below()?;
                    let before = report.node_sends;
                    next_to_send = send_pending(&outbox, &node_pub, from, &mut header_seq, &mut report).await?.max(next_to_send);
                    report.node_resends += report.node_sends - before;
                    last_progress = Instant::now();
                }
            }
        }
    }
    drop(rx);
    producer.abort();
    report.outbox_pending = outbox.len()?;
    session.close().await.map_err(anyhow::Error::from_boxed)?;
    Ok(report)
}

/// Sends the outbox's nodes from `from` on (at most a window), in order; returns the next
/// node_seq to send.
async fn send_pending(
    outbox: &Outbox,
    publisher: &zenoh::pubsub::Publisher<'_>,
    from: u64,
    header_seq: &mut u64,
    report: &mut EdgeReport,
) -> Result<u64> {
    let mut next = from;
    for (seq, bytes) in outbox.pending(from, RESEND_WINDOW)? {
        let mut node = v1::Node::decode(bytes.as_slice()).context("outbox holds a bad node")?;
        *header_seq += 1;
        if let Some(h) = node.header.as_mut() {
            h.seq = *header_seq;
            h.sent_ns = now_ns();
        }
        publisher
            .put(node.encode_to_vec())
            .await
            .map_err(anyhow::Error::from_boxed)?;
        report.node_sends += 1;
        next = seq + 1;
    }
    Ok(next)
}

/// The blocking side: paces the source, levels scans, commits nodes.
fn produce(
    config: EdgeConfig,
    mut source: Box<dyn Source>,
    outbox: Arc<Outbox>,
    tx: mpsc::Sender<Produced>,
) {
    let first_seq = match outbox.next_node_seq() {
        Ok(s) => s,
        Err(e) => {
            tracing::error!("{e}");
            let _ = tx.blocking_send(Produced::End);
            return;
        }
    };
    let mut builder = NodeBuilder::new(
        &config.fleet,
        &config.robot,
        config.node.clone(),
        config.leveling,
        first_seq,
    )
    .with_cloud(&config.cloud);
    let started = Instant::now();
    let mut first_stamp = None;
    let odometry_period_ns = (1e9 / config.odometry_rate_hz.max(0.1)) as u64;
    let mut last_odometry_ns: Option<u64> = None;
    while let Some(event) = source.next_event() {
        let stamp = event.stamp_ns();
        let first = *first_stamp.get_or_insert(stamp);
        if config.speed > 0.0 {
            let due =
                Duration::from_secs_f64(stamp.saturating_sub(first) as f64 * 1e-9 / config.speed);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let produced = match event {
            SourceEvent::Odometry(pose) => {
                if last_odometry_ns.is_some_and(|t| pose.stamp_ns < t + odometry_period_ns) {
                    continue;
                }
                last_odometry_ns = Some(pose.stamp_ns);
                let header = v1::Header::new(&config.fleet, &config.robot, 0, pose.stamp_ns, 0);
                Produced::Odometry(Box::new(wire::odometry_to_wire(&pose, header)))
            }
            SourceEvent::Scan(scan) => match builder.offer(&scan) {
                Ok(None) => continue,
                Ok(Some(node)) => {
                    if let Err(e) = outbox.push(node.node_seq, &node.encode_to_vec()) {
                        tracing::error!(robot = %config.robot, "node {} not kept: {e}", node.node_seq);
                        break;
                    }
                    Produced::Node
                }
                Err(e) => {
                    tracing::warn!(robot = %config.robot, "scan skipped: {e}");
                    Produced::ScanError
                }
            },
        };
        if tx.blocking_send(produced).is_err() {
            return;
        }
    }
    let _ = tx.blocking_send(Produced::End);
}
