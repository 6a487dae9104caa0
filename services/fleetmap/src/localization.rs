//! Robots that localize on a map version instead of mapping (docs/services.md,
//! "Localization"), the pure part: each robot's mode, a version's map built from its file,
//! and each localizing robot's tracker. A localizing robot's nodes are not added to the
//! network: each is found on the version's map (`slam::localize::Tracker`). The mapper keeps
//! the modes and the versions in its store and answers the robots.

use serde::{Deserialize, Serialize};
use slam::Pose2;
use slam::localize::{
    LocalizationMap, LocalizeError, LocalizeParams, TrackParams, TrackStatus, Tracker,
};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use wire::{Localized, MapVersion, Node};

/// What a robot does with its nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case", tag = "mode")]
pub enum RobotMode {
    /// Its nodes are added to the fleet's network.
    #[default]
    Map,
    /// Its nodes are found on a map version; the network does not grow.
    Localize {
        /// The version.
        version: u64,
    },
}

impl RobotMode {
    /// The store's form: the version, 0 to map.
    pub fn stored(self) -> u64 {
        match self {
            RobotMode::Map => 0,
            RobotMode::Localize { version } => version,
        }
    }

    /// From the store's form.
    pub fn from_stored(version: u64) -> RobotMode {
        match version {
            0 => RobotMode::Map,
            version => RobotMode::Localize { version },
        }
    }
}

/// A fleet's modes: the fleet's, for every robot without one of its own, and robots' own.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FleetModes {
    /// The fleet's mode.
    pub fleet: RobotMode,
    /// Robots with a mode of their own.
    pub robots: BTreeMap<String, RobotMode>,
}

impl FleetModes {
    /// From the store's form: the fleet's setting (none: map) and robots' own.
    pub fn from_stored<'a>(
        fleet: Option<u64>,
        robots: impl IntoIterator<Item = &'a (String, u64)>,
    ) -> FleetModes {
        FleetModes {
            fleet: RobotMode::from_stored(fleet.unwrap_or(0)),
            robots: robots
                .into_iter()
                .map(|(r, v)| (r.clone(), RobotMode::from_stored(*v)))
                .collect(),
        }
    }

    /// A robot's mode.
    pub fn of(&self, robot: &str) -> RobotMode {
        self.robots.get(robot).copied().unwrap_or(self.fleet)
    }

    /// The versions robots localize on.
    pub fn versions(&self) -> Vec<u64> {
        let mut versions: Vec<u64> = std::iter::once(self.fleet)
            .chain(self.robots.values().copied())
            .filter_map(|m| match m {
                RobotMode::Localize { version } => Some(version),
                RobotMode::Map => None,
            })
            .collect();
        versions.sort_unstable();
        versions.dedup();
        versions
    }
}

/// A version's map to localize on: its scans, cut at `max_range_m` as in mapping, at their
/// frozen poses (seconds for a large map).
pub fn version_map(
    frozen: &MapVersion,
    params: &LocalizeParams,
    max_range_m: f32,
) -> Result<LocalizationMap, LocalizeError> {
    let scans = frozen
        .nodes
        .iter()
        .map(|n| (n.pose, n.matching_scan(max_range_m)))
        .collect();
    LocalizationMap::new(scans, params.clone())
}

/// One localization of a robot's node, as the API lists it.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct NodeLocalization {
    /// The node's chain and number.
    pub chain_id: u64,
    /// See `chain_id`.
    pub node_seq: u64,
    /// The scan's start (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// The map version.
    pub version: u64,
    /// Found, carried forward by odometry, or lost.
    #[cfg_attr(feature = "openapi", schema(value_type = String))]
    pub status: TrackStatus,
    /// The scan frame in the map frame, unless lost.
    pub pose: Option<Pose2>,
    /// Covariance of (x, y, yaw) when found (m², m·rad, rad²).
    pub covariance: Option<[[f64; 3]; 3]>,
    /// The correlative score when found (0–1).
    pub score: Option<f64>,
    /// The search that found it: "window" or "global".
    #[cfg_attr(feature = "openapi", schema(value_type = Option<String>))]
    pub search: Option<slam::localize::SearchKind>,
    /// Why not found, when not.
    pub reason: Option<String>,
    /// Time the localization took (ms).
    pub took_ms: f64,
}

/// One node's outcome on a map (a version, or 0: the live map a pass is located on).
pub struct Outcome {
    /// The map version.
    pub version: u64,
    /// Found, carried forward by odometry, or lost.
    pub status: TrackStatus,
    /// The node's scan frame on the map, unless lost.
    pub pose: Option<Pose2>,
    /// The match, when the localizer found it.
    pub found: Option<slam::localize::Localization>,
    /// The search that placed it.
    pub search: Option<slam::localize::SearchKind>,
    /// Why not found, when not.
    pub reason: Option<String>,
}

impl Outcome {
    /// The answer to `node`'s robot, sent at `sent_ns`, and what the API lists of it.
    pub fn answers(
        &self,
        node: &Node,
        took_ms: f64,
        sent_ns: u64,
    ) -> (Localized, NodeLocalization) {
        let found = self.found.as_ref();
        let message = Localized {
            fleet: node.fleet.clone(),
            robot: node.robot.clone(),
            chain_id: node.chain_id,
            node_seq: node.node_seq,
            map_version: self.version,
            status: self.status,
            pose: self.pose,
            covariance: found.map(|f| f.covariance),
            score: found.map_or(0.0, |f| f.score),
            search: self.search,
            sent_ns,
            reason: self.reason.clone().unwrap_or_default(),
        };
        let entry = NodeLocalization {
            chain_id: node.chain_id,
            node_seq: node.node_seq,
            stamp_ns: node.stamp_ns,
            version: self.version,
            status: self.status,
            pose: self.pose,
            covariance: message.covariance,
            score: found.map(|f| f.score),
            search: self.search,
            reason: self.reason.clone(),
            took_ms,
        };
        (message, entry)
    }
}

/// The worker's side of one fleet: its modes, the maps they name, each robot's tracker.
#[derive(Default)]
pub struct Localizing {
    modes: FleetModes,
    maps: HashMap<u64, Arc<LocalizationMap>>,
    trackers: HashMap<String, (u64, Tracker)>,
}

impl Localizing {
    /// New modes, with the maps of the versions they name.
    pub fn set(&mut self, modes: FleetModes, maps: HashMap<u64, Arc<LocalizationMap>>) {
        self.modes = modes;
        self.maps = maps;
    }

    /// The fleet's modes.
    pub fn modes(&self) -> &FleetModes {
        &self.modes
    }

    /// A robot's mode.
    pub fn mode(&self, robot: &str) -> RobotMode {
        self.modes.of(robot)
    }

    /// Finds `node` on its robot's version; a robot that changed version starts anew. The
    /// answer is stamped `sent_ns`.
    pub fn localize(
        &mut self,
        node: &Node,
        version: u64,
        params: &TrackParams,
        max_range_m: f32,
        sent_ns: u64,
    ) -> (Localized, NodeLocalization) {
        let started = std::time::Instant::now();
        let map = self.maps.get(&version);
        let (tracked, tracker) = self
            .trackers
            .entry(node.robot.clone())
            .or_insert_with(|| (version, Tracker::new()));
        if *tracked != version {
            *tracked = version;
            *tracker = Tracker::new();
        }
        let scan = node.matching_scan(max_range_m);
        let odometry = Pose2::from_isometry3(&node.odometry.pose).compose(&node.scan_origin);
        let step = match map {
            Some(map) => tracker.step(map, params, odometry, &scan),
            None => slam::localize::TrackStep {
                pose: None,
                status: TrackStatus::Lost,
                found: None,
                error: None,
            },
        };
        let reason = match (&step.error, map) {
            (_, None) => Some(format!("version {version}'s map is not loaded")),
            (Some(e), _) => Some(e.to_string()),
            (None, _) => None,
        };
        let outcome = Outcome {
            version,
            status: step.status,
            pose: step.pose,
            search: step.found.as_ref().map(|f| f.search),
            found: step.found,
            reason,
        };
        outcome.answers(node, started.elapsed().as_secs_f64() * 1e3, sent_ns)
    }
}
