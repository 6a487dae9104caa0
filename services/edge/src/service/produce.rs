//! The edge service's blocking side: paces the source, levels each scan, commits every node to
//! the outbox before the async side sends it, and hands over live odometry and live scans.

use super::Produced;
use crate::config::EdgeConfig;
use crate::node::{NodeBuilder, NodeError, SensorScan};
use crate::outbox::Outbox;
use crate::ros_out::NodeFrame;
use crate::source::{Source, SourceEvent};
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use wire::{LiveScan, Node};

/// Offers a scan to the node builder; when a live scan is due, it goes too (the node's own
/// scan when the scan made one), dropped rather than waited for when the sender is behind.
fn offer(
    builder: &mut NodeBuilder,
    scan: &SensorScan,
    live_due: bool,
    tx: &mpsc::Sender<Produced>,
) -> Result<Option<Node>, NodeError> {
    let offered = builder.offer(scan);
    if live_due {
        let live = match &offered {
            Ok(Some(node)) => Ok(LiveScan::of_node(node)),
            _ => builder.live_scan(scan),
        };
        match live {
            Ok(live) => {
                let _ = tx.try_send(Produced::LiveScan(Box::new(live)));
            }
            Err(e) => tracing::debug!("live scan skipped: {e}"),
        }
    }
    offered
}

/// The blocking side: paces the source, levels scans, commits nodes.
pub(super) fn produce(
    config: &EdgeConfig,
    mut source: Box<dyn Source>,
    outbox: &Outbox,
    tx: &mpsc::Sender<Produced>,
) {
    let numbering = outbox
        .next_node_seq()
        .and_then(|seq| Ok((seq, outbox.chain_id()?)));
    let (first_seq, chain_id) = match numbering {
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
    .in_chain(chain_id)
    .with_cloud(&config.cloud);
    let started = Instant::now();
    let mut first_stamp = None;
    let odometry_period_ns = (1e9 / config.odometry_rate_hz.max(0.1)) as u64;
    let mut last_odometry_ns: Option<u64> = None;
    let live_period_ns =
        (config.live_scan_rate_hz > 0.0).then(|| (1e9 / config.live_scan_rate_hz) as u64);
    let mut last_live_ns: Option<u64> = None;
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
        let live_due =
            live_period_ns.is_some_and(|period| last_live_ns.is_none_or(|t| stamp >= t + period));
        if live_due && matches!(event, SourceEvent::Scan(_)) {
            last_live_ns = Some(stamp);
        }
        let produced = match event {
            SourceEvent::Odometry(pose) => {
                if last_odometry_ns.is_some_and(|t| pose.stamp_ns < t + odometry_period_ns) {
                    continue;
                }
                last_odometry_ns = Some(pose.stamp_ns);
                Produced::Odometry(pose)
            }
            SourceEvent::Scan(scan) => match offer(&mut builder, &scan, live_due, tx) {
                Ok(None) => continue,
                Ok(Some(node)) => {
                    if let Err(e) = outbox.push(&node) {
                        tracing::error!(robot = %config.robot, "node {} not kept: {e}", node.node_seq);
                        break;
                    }
                    Produced::Node(NodeFrame::of(&node))
                }
                Err(NodeError::Invalid { node, error }) => {
                    tracing::error!(robot = %config.robot, "node quarantined, not sent: {error}");
                    if let Err(e) = outbox.quarantine(error.reason(), &node) {
                        tracing::error!(robot = %config.robot, "quarantine not kept: {e}");
                    }
                    Produced::Quarantined
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
