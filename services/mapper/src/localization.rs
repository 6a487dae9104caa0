//! Robots that localize on a map version instead of mapping (docs/services.md,
//! "Localization"). An operator sets a fleet's robots (all, or by id) to `localize` on a
//! version or back to `map` (`PUT …/modes`, kept in the store). A localizing robot's nodes
//! are taken in sequence and acked as usual, but not added to the network: each is found on
//! the version's map (`slam::localize::Tracker`) and the answer goes back to the robot on
//! `levelmap/{fleet}/robots/{robot}/localization` at once. The network does not grow.
//!
//! A version's map (its scans rasterized in tiles) is built once, off the worker, and
//! shared by the worker and `POST …/localize` ([`MapCache`]).

use crate::store::{Store, StoredModes};
use serde::{Deserialize, Serialize};
use slam::Pose2;
use slam::localize::{
    LocalizationMap, LocalizeError, LocalizeParams, TrackParams, TrackStatus, Tracker,
};
use slam::matching::Scan2;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::num::NonZeroUsize;
use std::sync::{Arc, Mutex};
use utoipa::ToSchema;
use wire::{Localized, NodeInput};

/// Localization (`[localization]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizationConfig {
    /// Versions' maps kept built at once (the newest used): each takes a byte per 0.1 m cell
    /// per pooled level, about 8 MB per tile of 64 m (the park's map: 6 tiles).
    pub max_maps: NonZeroUsize,
    /// Localizations kept per robot for `GET …/robots/{robot}/localization`.
    pub history: NonZeroUsize,
    /// How a map is rasterized and searched (`slam::localize::LocalizeParams`).
    pub search: LocalizeParams,
    /// How a robot is followed from node to node (`slam::localize::TrackParams`).
    pub track: TrackParams,
}

impl Default for LocalizationConfig {
    fn default() -> Self {
        LocalizationConfig {
            max_maps: NonZeroUsize::new(4).expect("nonzero"),
            history: NonZeroUsize::new(1024).expect("nonzero"),
            search: LocalizeParams::default(),
            track: TrackParams::default(),
        }
    }
}

/// What a robot does with its nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
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

    fn from_stored(version: u64) -> RobotMode {
        match version {
            0 => RobotMode::Map,
            version => RobotMode::Localize { version },
        }
    }
}

/// A fleet's modes: the fleet's, for every robot without one of its own, and robots' own.
#[derive(Clone, Debug, Default, PartialEq, Serialize, ToSchema)]
pub struct FleetModes {
    /// The fleet's mode.
    pub fleet: RobotMode,
    /// Robots with a mode of their own.
    pub robots: BTreeMap<String, RobotMode>,
}

impl FleetModes {
    /// As stored.
    pub fn from_stored(stored: &StoredModes) -> FleetModes {
        FleetModes {
            fleet: RobotMode::from_stored(stored.fleet.unwrap_or(0)),
            robots: stored
                .robots
                .iter()
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

/// Why a version's map could not be had.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// No such version.
    #[error("fleet {fleet} has no version {version}")]
    NoVersion {
        /// The fleet.
        fleet: String,
        /// The version.
        version: u64,
    },
    /// The version's file does not decode.
    #[error("version {version}: {source}")]
    File {
        /// The version.
        version: u64,
        /// Why.
        source: wire::WireError,
    },
    /// The map cannot be localized on (no scan).
    #[error("version {version}: {source}")]
    Map {
        /// The version.
        version: u64,
        /// Why.
        source: LocalizeError,
    },
    /// The store failed.
    #[error(transparent)]
    Store(#[from] crate::store::StoreError),
}

/// A version's map by (fleet, version).
type KeptMap = ((String, u64), Arc<LocalizationMap>);

/// Versions' maps, built once each and shared; the newest used are kept, up to a bound.
pub struct MapCache {
    maps: Mutex<VecDeque<KeptMap>>,
    limit: usize,
    params: LocalizeParams,
    max_range_m: f32,
}

impl MapCache {
    /// An empty cache of `config.max_maps` maps; scans are cut at `max_range_m` as in mapping.
    pub fn new(config: &LocalizationConfig, max_range_m: f32) -> MapCache {
        MapCache {
            maps: Mutex::default(),
            limit: config.max_maps.get(),
            params: config.search.clone(),
            max_range_m,
        }
    }

    /// Scans are cut at this range (m), as in mapping.
    pub fn max_range_m(&self) -> f32 {
        self.max_range_m
    }

    /// The map of `fleet`'s `version`, built from the store when not kept (seconds for a
    /// large map: call it off the worker and off the async runtime).
    pub fn get(
        &self,
        store: &Store,
        fleet: &str,
        version: u64,
    ) -> Result<Arc<LocalizationMap>, MapError> {
        let key = (fleet.to_owned(), version);
        if let Some(map) = self.kept(&key) {
            return Ok(map);
        }
        let no_version = || MapError::NoVersion {
            fleet: fleet.to_owned(),
            version,
        };
        let file = store.version_file(fleet, version)?.ok_or_else(no_version)?;
        let frozen = wire::decode_map_version_file(&file)
            .map_err(|source| MapError::File { version, source })?;
        let scans = frozen
            .nodes
            .iter()
            .map(|n| {
                let (bearings, ranges): (Vec<f32>, Vec<f32>) = n.returns().unzip();
                let scan = Scan2::from_polar(&bearings, &ranges, self.max_range_m)
                    .expect("returns come in pairs");
                (n.pose, scan)
            })
            .collect();
        let map = LocalizationMap::new(scans, self.params.clone())
            .map_err(|source| MapError::Map { version, source })?;
        let map = Arc::new(map);
        let mut maps = self.maps.lock().expect("maps lock");
        maps.retain(|(k, _)| *k != key);
        maps.push_back((key, map.clone()));
        while maps.len() > self.limit {
            maps.pop_front();
        }
        Ok(map)
    }

    fn kept(&self, key: &(String, u64)) -> Option<Arc<LocalizationMap>> {
        let mut maps = self.maps.lock().expect("maps lock");
        let at = maps.iter().position(|(k, _)| k == key)?;
        let entry = maps.remove(at).expect("found");
        let map = entry.1.clone();
        maps.push_back(entry);
        Some(map)
    }
}

/// One localization of a robot's node, as the API lists it.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
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
    #[schema(value_type = String)]
    pub status: TrackStatus,
    /// The scan frame in the map frame, unless lost.
    pub pose: Option<Pose2>,
    /// Covariance of (x, y, yaw) when found (m², m·rad, rad²).
    pub covariance: Option<[[f64; 3]; 3]>,
    /// The correlative score when found (0–1).
    pub score: Option<f64>,
    /// The search that found it: "window" or "global".
    #[schema(value_type = Option<String>)]
    pub search: Option<slam::localize::SearchKind>,
    /// Why not found, when not.
    pub reason: Option<String>,
    /// Time the localization took (ms).
    pub took_ms: f64,
}

/// Each robot's recent localizations, for the API: bounded per robot.
#[derive(Debug, Default)]
pub struct LocalizationLog {
    robots: Mutex<HashMap<(String, String), VecDeque<NodeLocalization>>>,
}

impl LocalizationLog {
    /// Adds one, dropping the oldest beyond `limit`.
    pub fn push(&self, fleet: &str, robot: &str, entry: NodeLocalization, limit: usize) {
        let mut robots = self.robots.lock().expect("log lock");
        let log = robots
            .entry((fleet.to_owned(), robot.to_owned()))
            .or_default();
        log.push_back(entry);
        while log.len() > limit {
            log.pop_front();
        }
    }

    /// A robot's localizations, oldest first, from node_seq `since` on.
    pub fn of(&self, fleet: &str, robot: &str, since: u64) -> Option<Vec<NodeLocalization>> {
        let robots = self.robots.lock().expect("log lock");
        let log = robots.get(&(fleet.to_owned(), robot.to_owned()))?;
        Some(
            log.iter()
                .filter(|e| e.node_seq >= since)
                .cloned()
                .collect(),
        )
    }

    /// Each robot's newest, of one fleet.
    pub fn newest(&self, fleet: &str) -> BTreeMap<String, NodeLocalization> {
        let robots = self.robots.lock().expect("log lock");
        robots
            .iter()
            .filter(|((f, _), _)| f == fleet)
            .filter_map(|((_, r), log)| Some((r.clone(), log.back()?.clone())))
            .collect()
    }
}

/// Every fleet's stored modes with the maps they name, for the worker at start. A map
/// that cannot be built is logged: its robots are answered lost until their mode changes.
pub fn restore(
    store: &Store,
    maps: &MapCache,
) -> Result<HashMap<String, Localizing>, crate::store::StoreError> {
    let mut fleets = HashMap::new();
    for (fleet, stored) in store.modes()? {
        let modes = FleetModes::from_stored(&stored);
        let mut built = HashMap::new();
        for version in modes.versions() {
            match maps.get(store, &fleet, version) {
                Ok(map) => {
                    built.insert(version, map);
                }
                Err(e) => tracing::error!(fleet, version, "localization map not built: {e}"),
            }
        }
        let mut localizing = Localizing::default();
        localizing.set(modes, built);
        fleets.insert(fleet, localizing);
    }
    Ok(fleets)
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
    /// The answer to `node`'s robot and what the API lists of it.
    pub fn answers(&self, node: &NodeInput, took_ms: f64) -> (Localized, NodeLocalization) {
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
            sent_ns: runtime::session::now_ns(),
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

    /// Finds `node` on its robot's version; a robot that changed version starts anew.
    pub fn localize(
        &mut self,
        node: &NodeInput,
        version: u64,
        params: &TrackParams,
        max_range_m: f32,
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
        let scan = wire::matching_scan(&node.scan, max_range_m);
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
        outcome.answers(node, started.elapsed().as_secs_f64() * 1e3)
    }
}
