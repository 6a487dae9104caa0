//! The edge service: source → nodes → outbox → Zenoh, until the mapper acks.
//!
//! Measurements are paced in (scaled) real time on a blocking thread ([`produce`](mod@produce)),
//! which also levels the scans and commits each node to the outbox before it is sent. The async loop publishes new
//! nodes in order, live odometry best effort, takes the mapper's acks, and re-sends every
//! unacked node, in order, when no ack progress was seen for `resend_after_ms` (a put made
//! before the mapper's subscription reached us, a radio outage, a mapper restart).

use crate::config::EdgeConfig;
use crate::outbox::Outbox;
use crate::ros_out::{MapCorrection, NodeFrame, TfOut};
use crate::source::Source;
use anyhow::{Context, Result};
use runtime::session::now_ns;
use serde::Serialize;
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, oneshot};
use zenoh::qos::{CongestionControl, Priority};

/// Most nodes sent in one burst of re-sending.
const RESEND_WINDOW: usize = 64;

/// What an edge service did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct EdgeReport {
    /// The robot's id.
    pub robot: String,
    /// Nodes made (committed to the outbox) by this run.
    pub nodes: u64,
    /// Node publications, first sends and re-sends.
    pub node_sends: u64,
    /// Of `node_sends`, the re-sends.
    pub node_resends: u64,
    /// Zenoh sessions closed and opened again after `reopen_link_after_ms` without an ack.
    pub link_reopens: u64,
    /// Live odometry messages sent.
    pub odometry_sent: u64,
    /// Live leveled scans sent.
    pub live_scans_sent: u64,
    /// Highest node_seq the mapper acked, if any.
    pub acked_node_seq: Option<u64>,
    /// Nodes still waiting for their ack at exit (they stay in the outbox for the next run).
    pub outbox_pending: u64,
    /// Scans the leveling could not use (logged).
    pub scan_errors: u64,
    /// Nodes that failed the wire's checks, kept in the outbox's quarantine and not sent.
    pub quarantined: u64,
    /// Acks that named another chain or nodes this robot never made, ignored.
    pub acks_ignored: u64,
    /// Corrected poses the mapper sent back after its solves, and the latest: this robot's
    /// last node on the map.
    pub map_pose_updates: u64,
    /// The latest corrected pose of this robot's last node (mapped, or localized on a map
    /// version).
    pub map_pose: Option<slam::Pose2>,
    /// Localizations of this robot's nodes on a map version (while it localizes), and of
    /// them, those found in the map (the rest carried forward by odometry, or lost).
    pub localizations: u64,
    /// See `localizations`.
    pub localized: u64,
    /// The latest localization's status and map version.
    pub localization: Option<(slam::localize::TrackStatus, u64)>,
    /// The latest map→odom correction (`[ros2_out]` publishes it on `/tf`).
    pub map_from_odometry: Option<slam::Pose2>,
    /// Transforms published on `/tf` (`[ros2_out]`).
    pub tf_published: u64,
}

/// What the blocking side hands the sending loop.
pub(super) enum Produced {
    /// A node is in the outbox: its frame, for corrections.
    Node(NodeFrame),
    /// Live odometry (best effort).
    Odometry(leveling::TimedPose),
    /// A live leveled scan (best effort).
    LiveScan(Box<wire::LiveScan>),
    ScanError,
    Quarantined,
    End,
}

mod backoff;
pub use backoff::ResendBackoff;
mod produce;
mod tf;
use produce::produce;
use tf::{FINAL_CORRECTION_WAIT, close_tf_out, open_tf_out};

/// The robot's side of the bus: its publishers and subscriptions.
struct Link {
    session: zenoh::Session,
    nodes: zenoh::pubsub::Publisher<'static>,
    odometry: zenoh::pubsub::Publisher<'static>,
    live_scans: zenoh::pubsub::Publisher<'static>,
    acks: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    map_poses:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    /// The mapper's localizations of this robot's nodes, while it localizes on a version.
    localizations:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
}

impl Link {
    /// Nodes reliable (blocking under congestion), odometry best effort (dropped).
    async fn open(config: &EdgeConfig) -> Result<Link> {
        let session = config.zenoh.open(runtime::session::Role::Client).await?;
        let node_key = wire::node_key(&config.fleet, &config.robot)?;
        let odom_key = wire::odom_key(&config.fleet, &config.robot)?;
        let ack_key = wire::ack_key(&config.fleet, &config.robot)?;
        let nodes = session
            .declare_publisher(node_key)
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(anyhow::Error::from_boxed)?;
        let odometry = session
            .declare_publisher(odom_key)
            .congestion_control(CongestionControl::Drop)
            .await
            .map_err(anyhow::Error::from_boxed)?;
        // Below odometry: a teleoperator's view can wait, the robot's pose should not.
        let live_scans = session
            .declare_publisher(wire::scan_key(&config.fleet, &config.robot)?)
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::DataLow)
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
        let localizations = session
            .declare_subscriber(wire::localization_key(&config.fleet, &config.robot)?)
            .await
            .map_err(anyhow::Error::from_boxed)?;
        Ok(Link {
            session,
            nodes,
            odometry,
            live_scans,
            acks,
            map_poses,
            localizations,
        })
    }
}

/// What the sending loop keeps between events.
struct Sending {
    /// The robot's fleet (its robot is the report's).
    fleet: String,
    outbox: Arc<Outbox>,
    report: EdgeReport,
    /// Publications of this run, for `Header.seq`.
    header_seq: u64,
    /// The next node_seq not sent yet.
    next_to_send: u64,
    /// The newest ack progress or re-send while nodes wait: no progress for the backoff's wait
    /// re-sends (new nodes do not count: a gap must not hide behind fresh sends).
    last_progress: Instant,
    /// How long without progress before re-sending: doubles while re-sends bring none.
    resend_backoff: backoff::ResendBackoff,
    /// The newest ack of our chain, or when a node began to wait with none waiting before:
    /// with nodes waiting, silence since then longer than `reopen_after` reopens the link.
    last_heard: Instant,
    reopen_after: Option<Duration>,
    /// The last re-send the mapper asked for (`Ack.resend_from`), to answer a burst of such
    /// acks (one per batch it received after the gap) with one re-send.
    last_gap_resend: Option<Instant>,
    /// This outbox's chain: acks of any other are not ours.
    chain_id: u64,
    /// The map→odom correction from the mapper's poses.
    correction: MapCorrection,
    /// `[ros2_out]`: the `/tf` publisher once its session is open, and until then where it
    /// comes from.
    tf_out: Option<TfOut>,
    tf_opening: Option<oneshot::Receiver<TfOut>>,
    /// The newest live odometry's stamp: the transform's.
    last_odometry_ns: u64,
    /// When the source had ended and every node was acked.
    settled_at: Option<Instant>,
}

/// The least time between two re-sends the mapper asked for: the nodes of the first must have
/// time to arrive before a second is worth making.
const GAP_RESEND_HOLDOFF: Duration = Duration::from_millis(300);

impl Sending {
    /// A node was made (sent or not yet).
    fn made(&mut self, frame: NodeFrame) {
        self.report.nodes += 1;
        self.correction.on_node(frame);
    }

    /// A new node is in the outbox: send it (and any before it not sent yet).
    async fn on_node(&mut self, link: &Link, frame: NodeFrame) -> Result<()> {
        self.made(frame);
        if self.next_to_send <= self.outbox.acked_below()? {
            // Nothing was waiting for an ack: the timers start with this node.
            self.last_progress = Instant::now();
            self.last_heard = Instant::now();
        }
        self.send_backlog(link).await
    }

    /// Sends what the outbox holds beyond what was sent (nodes made before the link was up).
    async fn send_backlog(&mut self, link: &Link) -> Result<()> {
        self.next_to_send = self.send_from(link, self.next_to_send).await?;
        Ok(())
    }

    /// Sends the outbox's nodes from `from` on (at most a window); the next node_seq to send.
    async fn send_from(&mut self, link: &Link, from: u64) -> Result<u64> {
        send_pending(
            &self.outbox,
            &link.nodes,
            from,
            &mut self.header_seq,
            &mut self.report,
        )
        .await
    }

    /// Live odometry, best effort; the transform with its stamp.
    async fn on_odometry(&mut self, link: &Link, pose: leveling::TimedPose) {
        self.header_seq += 1;
        self.last_odometry_ns = pose.stamp_ns;
        let (fleet, robot) = (&self.fleet, &self.report.robot);
        let bytes = wire::encode_odometry(fleet, robot, &pose, self.header_seq, now_ns());
        self.publish_tf();
        if link.odometry.put(bytes).await.is_ok() {
            self.report.odometry_sent += 1;
        }
    }

    /// A live scan, best effort at low priority.
    async fn on_live_scan(&mut self, link: &Link, scan: Box<wire::LiveScan>) {
        self.header_seq += 1;
        let bytes = scan.encode(self.header_seq, now_ns());
        if link.live_scans.put(bytes).await.is_ok() {
            self.report.live_scans_sent += 1;
        }
    }

    /// The mapper took every node of our chain up to the ack's: they leave the outbox. An ack
    /// deletes only what it names: our chain, nodes we made. After a gap, the mapper names
    /// the node it needs next, and it is re-sent at once.
    async fn on_ack(&mut self, link: &Link, robot: &str, payload: &[u8]) -> Result<()> {
        let ack = match wire::decode_ack(payload) {
            Ok(ack) => ack,
            Err(e) => {
                tracing::warn!(robot, "bad ack: {e}");
                self.report.acks_ignored += 1;
                return Ok(());
            }
        };
        let made = self.outbox.next_node_seq()?;
        if ack.chain_id != self.chain_id || ack.acked_node_seq.is_some_and(|a| a >= made) {
            tracing::warn!(
                robot,
                chain = ack.chain_id,
                acked = ?ack.acked_node_seq,
                "ack ignored: not of this outbox's chain {} and its {made} nodes",
                self.chain_id
            );
            self.report.acks_ignored += 1;
            return Ok(());
        }
        self.last_heard = Instant::now();
        if let Some(seq) = ack.acked_node_seq {
            if self.report.acked_node_seq.is_none_or(|a| seq > a) {
                self.report.acked_node_seq = Some(seq);
                self.last_progress = Instant::now();
                self.resend_backoff.reset();
            }
            self.outbox.ack(seq)?;
            self.next_to_send = self.next_to_send.max(seq + 1);
        }
        // Acked nodes kept count: a mapper started from a backup asks for them again.
        let held = self.outbox.held_from()?;
        if let Some(from) = ack.resend_from.filter(|&f| f >= held && f < made)
            && self
                .last_gap_resend
                .is_none_or(|t| t.elapsed() >= GAP_RESEND_HOLDOFF)
        {
            self.last_gap_resend = Some(Instant::now());
            self.resend(link, from).await?;
        }
        Ok(())
    }

    /// Re-sends from `from` on (a window), counted as re-sends.
    async fn resend(&mut self, link: &Link, from: u64) -> Result<()> {
        let before = self.report.node_sends;
        let next = self.send_from(link, from).await?;
        self.next_to_send = next.max(self.next_to_send);
        self.report.node_resends += self.report.node_sends - before;
        self.last_progress = Instant::now();
        Ok(())
    }

    /// The mapper's corrected pose of this robot's last node.
    fn on_map_poses(&mut self, robot: &str, payload: &[u8]) {
        match wire::decode_map_poses(payload) {
            Ok((_, poses)) => {
                if let Some(p) = poses.into_iter().find(|p| p.robot == robot) {
                    self.report.map_pose_updates += 1;
                    self.report.map_pose = Some(p.pose);
                    if self.correction.on_map_pose(p.node_seq, p.pose).is_some() {
                        self.report.map_from_odometry = self.correction.map_from_odometry();
                        self.publish_tf();
                    }
                }
            }
            Err(e) => tracing::warn!(robot, "bad map poses: {e}"),
        }
    }

    /// The mapper's localization of one of this robot's nodes on a map version: a corrected
    /// pose like a solve's, unless the robot is lost.
    fn on_localization(&mut self, robot: &str, payload: &[u8]) {
        match wire::decode_localization(payload) {
            Ok(l) if l.robot == robot => {
                self.report.localizations += 1;
                self.report.localization = Some((l.status, l.map_version));
                if l.status == slam::localize::TrackStatus::Localized {
                    self.report.localized += 1;
                }
                if let Some(pose) = l.pose {
                    self.report.map_pose = Some(pose);
                    if self.correction.on_map_pose(l.node_seq, pose).is_some() {
                        self.report.map_from_odometry = self.correction.map_from_odometry();
                        self.publish_tf();
                    }
                }
            }
            Ok(l) => tracing::warn!(robot, "a localization of {} ignored", l.robot),
            Err(e) => tracing::warn!(robot, "bad localization: {e}"),
        }
    }

    /// The latest correction on `/tf`, once there is one and `[ros2_out]` is open.
    fn publish_tf(&mut self) {
        if let Some(opening) = self.tf_opening.as_mut()
            && let Ok(tf_out) = opening.try_recv()
        {
            self.tf_out = Some(tf_out);
            self.tf_opening = None;
        }
        if let (Some(tf_out), Some(correction)) =
            (&self.tf_out, self.correction.map_from_odometry())
            && self.last_odometry_ns > 0
            && tf_out.publish(&correction, self.last_odometry_ns)
        {
            self.report.tf_published += 1;
        }
    }

    /// Nodes wait and nothing was heard from the mapper for `reopen_after`. Zenoh mends a dead
    /// transport by itself, but a reconnection racing the router's teardown of the old one
    /// can leave a transport that stays open and is not routed (eclipse-zenoh/zenoh#1886): a
    /// new session, with a new id, cannot meet that old state.
    fn link_silent(&self) -> Result<bool> {
        let Some(after) = self.reopen_after else {
            return Ok(false);
        };
        Ok(self.last_heard.elapsed() >= after && self.outbox.len()? > 0)
    }

    /// Re-sends every unacked node, in order, after the backoff's wait without progress (it
    /// then doubles); whether the run is over (the source ended and everything is acked).
    async fn on_tick(&mut self, link: &Link, source_done: bool) -> Result<bool> {
        let pending = self.outbox.len()?;
        if source_done && pending == 0 {
            let publishes_tf = self.tf_out.is_some() || self.tf_opening.is_some();
            if !publishes_tf || self.correction.is_of_last_node() {
                return Ok(true);
            }
            let settled = *self.settled_at.get_or_insert_with(Instant::now);
            return Ok(settled.elapsed() >= FINAL_CORRECTION_WAIT);
        }
        if pending > 0 && self.last_progress.elapsed() >= self.resend_backoff.wait() {
            let from = self.outbox.acked_below()?;
            self.resend(link, from).await?;
            self.resend_backoff.resent();
        }
        Ok(false)
    }
}

/// How long one attempt to reach the mapper may take, and the wait before the next.
const LINK_RETRY: Duration = Duration::from_secs(1);

/// Opens the link, again every [`LINK_RETRY`] while the mapper is out of reach; the robot
/// keeps making nodes meanwhile (they wait in the outbox). `None` when asked to stop first, or
/// when the source ended and the config does not linger for acks.
async fn connect(
    config: &EdgeConfig,
    sending: &mut Sending,
    rx: &mut mpsc::Receiver<Produced>,
    source_done: &mut bool,
    mut shutdown: std::pin::Pin<&mut impl Future<Output = ()>>,
) -> Option<Link> {
    let robot = config.robot.as_str();
    loop {
        match tokio::time::timeout(5 * LINK_RETRY, Link::open(config)).await {
            Ok(Ok(link)) => return Some(link),
            Ok(Err(e)) => tracing::warn!(robot, "mapper not reachable ({e:#}); retrying"),
            Err(_) => tracing::warn!(robot, "mapper not reachable (timed out); retrying"),
        }
        let retry = tokio::time::sleep(LINK_RETRY);
        tokio::pin!(retry);
        loop {
            tokio::select! {
                _ = shutdown.as_mut() => return None,
                _ = &mut retry => break,
                produced = rx.recv(), if !*source_done => match produced {
                    Some(Produced::Node(frame)) => sending.made(frame),
                    // Live odometry is best effort: nobody to send it to.
                    Some(Produced::Odometry(_) | Produced::LiveScan(_)) => {}
                    Some(Produced::ScanError) => sending.report.scan_errors += 1,
                    Some(Produced::Quarantined) => sending.report.quarantined += 1,
                    Some(Produced::End) | None => {
                        *source_done = true;
                        if !config.linger_for_acks {
                            return None;
                        }
                    }
                },
            }
        }
    }
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
    let outbox = Outbox::open(&config.outbox_path)
        .with_context(|| format!("{}: cannot open the outbox", config.outbox_path.display()))?;
    let outbox = Arc::new(outbox.keeping_acked(config.outbox_keep_acked));
    let (tx, mut rx) = mpsc::channel::<Produced>(256);
    let producer = {
        let outbox = outbox.clone();
        let config = config.clone();
        tokio::task::spawn_blocking(move || produce(&config, source, &outbox, &tx))
    };
    let mut sending = Sending {
        fleet: config.fleet.clone(),
        report: EdgeReport {
            robot: config.robot.clone(),
            ..Default::default()
        },
        header_seq: 0,
        next_to_send: outbox.acked_below()?,
        chain_id: outbox.chain_id()?,
        outbox,
        last_progress: Instant::now(),
        resend_backoff: backoff::ResendBackoff::new(
            Duration::from_millis(config.resend_after_ms),
            Duration::from_millis(config.resend_max_after_ms),
        ),
        last_heard: Instant::now(),
        reopen_after: (config.reopen_link_after_ms > 0)
            .then(|| Duration::from_millis(config.reopen_link_after_ms)),
        last_gap_resend: None,
        correction: MapCorrection::default(),
        tf_out: None,
        tf_opening: config.ros2_out.clone().map(open_tf_out),
        last_odometry_ns: 0,
        settled_at: None,
    };
    let robot = config.robot.as_str();
    let mut source_done = false;
    tokio::pin!(shutdown);
    // Each pass is one session: it ends the run, or the link fell silent and a new one opens.
    while let Some(link) = connect(
        &config,
        &mut sending,
        &mut rx,
        &mut source_done,
        shutdown.as_mut(),
    )
    .await
    {
        // Silence counts from here; on a new session, the first tick re-sends everything
        // unacked (no progress since long before the first wait, to which the backoff returns).
        sending.last_heard = Instant::now();
        sending.resend_backoff.reset();
        sending.send_backlog(&link).await?;
        let mut tick = tokio::time::interval(Duration::from_millis(100));
        let silent = loop {
            tokio::select! {
                _ = &mut shutdown => break false,
                produced = rx.recv(), if !source_done => match produced {
                    Some(Produced::Node(frame)) => sending.on_node(&link, frame).await?,
                    Some(Produced::Odometry(odometry)) => sending.on_odometry(&link, odometry).await,
                    Some(Produced::LiveScan(scan)) => sending.on_live_scan(&link, scan).await,
                    Some(Produced::ScanError) => sending.report.scan_errors += 1,
                    Some(Produced::Quarantined) => sending.report.quarantined += 1,
                    Some(Produced::End) | None => {
                        source_done = true;
                        if !config.linger_for_acks { break false; }
                    }
                },
                sample = link.acks.recv_async() => {
                    let Ok(sample) = sample else { break false };
                    sending.on_ack(&link, robot, &sample.payload().to_bytes()).await?;
                }
                sample = link.map_poses.recv_async() => {
                    let Ok(sample) = sample else { break false };
                    sending.on_map_poses(robot, &sample.payload().to_bytes());
                }
                sample = link.localizations.recv_async() => {
                    let Ok(sample) = sample else { break false };
                    sending.on_localization(robot, &sample.payload().to_bytes());
                }
                _ = tick.tick() => {
                    if sending.on_tick(&link, source_done).await? { break false; }
                    if sending.link_silent()? { break true; }
                }
            }
        };
        if !silent {
            close_session(link).await?;
            break;
        }
        let waiting = sending.outbox.len()?;
        tracing::warn!(
            robot,
            waiting,
            "no ack for {:?} with nodes waiting: opening a new Zenoh session",
            sending.reopen_after.unwrap_or_default()
        );
        sending.report.link_reopens += 1;
        // A dead link may not answer a close: it is dropped after the bound either way.
        let _ = tokio::time::timeout(LINK_RETRY, close_session(link)).await;
    }
    drop(rx);
    producer.abort();
    if let Some(tf_out) = sending.tf_out.take() {
        close_tf_out(tf_out, LINK_RETRY).await;
    }
    let mut report = sending.report;
    report.outbox_pending = sending.outbox.len()?;
    Ok(report)
}

async fn close_session(link: Link) -> Result<()> {
    link.session
        .close()
        .await
        .map_err(anyhow::Error::from_boxed)
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
    let held_from = outbox.held_from()?;
    for (seq, bytes) in outbox.pending(from, RESEND_WINDOW)? {
        *header_seq += 1;
        publisher
            .put(wire::node_as_sent(&bytes, held_from, *header_seq, now_ns()))
            .await
            .map_err(anyhow::Error::from_boxed)?;
        report.node_sends += 1;
        next = seq + 1;
    }
    Ok(next)
}
