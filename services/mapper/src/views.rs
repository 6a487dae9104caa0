//! What the HTTP side reads: per fleet, an immutable view replaced after every accepted node
//! (readers never wait on the mapping), live odometry, counters and the event stream; the
//! nodes' clouds, which no view holds, through a read-only handle on the store ([`clouds`]).

use fleetmap::{FleetMap, FleetView};
use runtime::session::now_ns;
use slam::Pose2;
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use tokio::sync::broadcast;

/// A robot's latest odometry.
#[derive(Clone, Copy, Debug)]
pub struct LiveOdometry {
    /// Its planar odometry pose.
    pub odometry: Pose2,
    /// When it was measured (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// When it arrived.
    pub received_ns: u64,
    /// When this robot's last `pose` event went out.
    pub evented_ns: u64,
}

/// Counters for `/metrics`.
#[derive(Debug, Default)]
pub struct Metrics {
    /// Node messages from robots (re-sends included), before any check.
    pub nodes_received: AtomicU64,
    /// Nodes mapped and stored.
    pub nodes_accepted: AtomicU64,
    /// Re-sent nodes taken already (re-acked).
    pub nodes_duplicate: AtomicU64,
    /// Nodes of localizing robots localized and stored (as spans), not mapped.
    pub nodes_localized: AtomicU64,
    /// Nodes of mapping robots passed over covered ground: located, stored as spans, not
    /// mapped.
    pub nodes_passed: AtomicU64,
    /// Clouds dropped by the retention policy (`[clouds]`).
    pub clouds_pruned: AtomicU64,
    /// Live odometry messages taken.
    pub odometry_received: AtomicU64,
    /// Acks published.
    pub acks_sent: AtomicU64,
    /// Localizations published to localizing robots.
    pub localizations_sent: AtomicU64,
    /// Network solves run.
    pub optimizations: AtomicU64,
    /// Fleets rebuilt from their nodes at start (mapped by another mapping version).
    pub fleets_rebuilt: AtomicU64,
    /// Rejections by (topic, reason).
    pub rejected: Mutex<BTreeMap<(&'static str, &'static str), u64>>,
}

impl Metrics {
    /// Counts a rejected message of `topic` (`node`, `odom`) for `reason`.
    pub fn reject(&self, topic: &'static str, reason: &'static str) {
        *self
            .rejected
            .lock()
            .expect("metrics lock")
            .entry((topic, reason))
            .or_default() += 1;
    }

    /// Rejections of `topic` for `reason` so far.
    pub fn rejected(&self, topic: &str, reason: &str) -> u64 {
        self.rejected
            .lock()
            .expect("metrics lock")
            .get(&(topic, reason))
            .copied()
            .unwrap_or(0)
    }

    /// Adds one to a counter.
    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// Everything the HTTP side shares with the mapping worker and the Zenoh callbacks.
#[derive(Debug)]
pub struct Shared {
    /// Each fleet's latest view.
    pub fleets: RwLock<HashMap<String, Arc<FleetView>>>,
    /// Each robot's (fleet, robot) latest odometry.
    pub live: Mutex<HashMap<(String, String), LiveOdometry>>,
    /// Each robot's live feed for teleoperation.
    pub live_feeds: crate::views::live::LiveFeeds,
    /// The counters of `/metrics`.
    pub metrics: Metrics,
    /// The histograms and the cluster's figures (`prometheus-client`).
    pub instruments: instruments::Instruments,
    /// Events as JSON text (see `docs/api.md`).
    pub events: broadcast::Sender<String>,
    /// The bearer token of the write routes (empty: they are off).
    pub token: String,
    /// When the mapper started (ns since the Unix epoch).
    pub started_ns: u64,
    /// Why the store cannot commit, while it cannot: nodes are neither taken nor acked, the
    /// routes that need the store answer 503, and the worker tries again every second.
    pub store_fault: RwLock<Option<String>>,
    /// Fleets whose stored map did not replay at start, with the reason: their routes answer
    /// 503 and their nodes are not taken (the robots keep them); the other fleets run.
    pub quarantined: RwLock<BTreeMap<String, String>>,
    /// Set when the mapper stops: open event streams end, so HTTP can shut down gracefully.
    pub stopping: tokio::sync::watch::Sender<bool>,
    /// Set while a recording is fed ([`crate::bus::recording`]): the worker solves only when the
    /// feed asks, where the recorded mapper solved, not on its own timer.
    pub feeding: std::sync::atomic::AtomicBool,
    /// Localizing robots' recent localizations.
    pub localizations: crate::localization::LocalizationLog,
}

impl Shared {
    /// Nothing mapped yet.
    pub fn new(token: String, started_ns: u64) -> Shared {
        Shared {
            fleets: RwLock::default(),
            live: Mutex::default(),
            live_feeds: crate::views::live::LiveFeeds::default(),
            metrics: Metrics::default(),
            instruments: Default::default(),
            events: broadcast::channel(1024).0,
            token,
            started_ns,
            store_fault: RwLock::default(),
            quarantined: RwLock::default(),
            stopping: tokio::sync::watch::Sender::new(false),
            feeding: Default::default(),
            localizations: Default::default(),
        }
    }

    /// A robot's pose on the map now: its live odometry since its last node, composed onto
    /// the node's map pose, or that node's pose alone; with the odometry's stamp and arrival
    /// (ns, 0 without live odometry).
    pub fn robot_pose(&self, view: &FleetView, robot: &fleetmap::RobotView) -> (Pose2, u64, u64) {
        let live = self
            .live
            .lock()
            .expect("live lock")
            .get(&(view.id.clone(), robot.id.clone()))
            .copied();
        match live {
            Some(l) => (robot.live_pose(&l.odometry), l.stamp_ns, l.received_ns),
            None => (robot.map_pose_at_last_node, 0, 0),
        }
    }

    /// Every fleet's latest view.
    pub fn views(&self) -> Vec<Arc<FleetView>> {
        let fleets = self.fleets.read().expect("views lock");
        fleets.values().cloned().collect()
    }

    /// A fleet's latest view.
    pub fn fleet(&self, id: &str) -> Option<Arc<FleetView>> {
        self.fleets.read().expect("views lock").get(id).cloned()
    }

    /// Why the store cannot commit, while it cannot.
    pub fn store_fault(&self) -> Option<String> {
        self.store_fault.read().expect("fault lock").clone()
    }

    /// Every quarantined fleet with why, by fleet.
    pub fn quarantined_fleets(&self) -> BTreeMap<String, String> {
        self.quarantined.read().expect("quarantine lock").clone()
    }

    /// Why a fleet is quarantined, if it is.
    pub fn quarantine(&self, fleet: &str) -> Option<String> {
        self.quarantined
            .read()
            .expect("quarantine lock")
            .get(fleet)
            .cloned()
    }

    /// Makes and publishes the view of `map` now, sharing what it can with the last one.
    pub fn publish_map(&self, map: &FleetMap, last_ingest_ms: f64) {
        let previous = self.fleet(map.id());
        let view = FleetView::of(map, previous.as_deref(), last_ingest_ms, now_ns());
        self.publish_view(view);
    }

    /// Replaces the fleet's view: readers see the new one from now on.
    pub fn publish_view(&self, view: FleetView) {
        self.fleets
            .write()
            .expect("views lock")
            .insert(view.id.clone(), Arc::new(view));
    }

    /// Sends an event to the stream's subscribers (none listening is fine).
    pub fn event(&self, event: &serde_json::Value) {
        let _ = self.events.send(event.to_string());
    }
}

pub mod clouds;
pub mod instruments;
pub mod live;
