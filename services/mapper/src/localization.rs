//! Robots that localize on a map version instead of mapping (docs/services.md,
//! "Localization"). An operator sets a fleet's robots (all, or by id) to `localize` on a
//! version or back to `map` (`PUT …/modes`, kept in the store). A localizing robot's nodes
//! are taken in sequence and acked as usual, but not added to the network: each is found on
//! the version's map (`slam::localize::Tracker`) and the answer goes back to the robot on
//! `levelmap/{fleet}/robots/{robot}/localization` at once. The network does not grow.
//!
//! A version's map (its scans rasterized in tiles, `fleetmap::localization::version_map`) is
//! built once, off the worker, and shared by the worker and `POST …/localize` ([`MapCache`]).
//! The modes and the trackers are the map core's (`fleetmap::localization`).

pub use crate::config::LocalizationConfig;
use crate::store::{Store, StoredModes};
pub use fleetmap::localization::{FleetModes, Localizing, NodeLocalization, Outcome, RobotMode};
use slam::localize::{LocalizationMap, LocalizeError, LocalizeParams};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::{Arc, Mutex};

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
        let map = fleetmap::localization::version_map(&frozen, &self.params, self.max_range_m)
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
        let (modes, built) = with_maps(store, maps, &fleet, &stored);
        let mut localizing = Localizing::default();
        localizing.set(modes, built);
        fleets.insert(fleet, localizing);
    }
    Ok(fleets)
}

/// `fleet`'s stored modes with the maps they name. A map that cannot be built is logged:
/// its robots are answered lost until their mode changes.
pub fn with_maps(
    store: &Store,
    maps: &MapCache,
    fleet: &str,
    stored: &StoredModes,
) -> (FleetModes, HashMap<u64, Arc<LocalizationMap>>) {
    let modes = modes_of(stored);
    let mut built = HashMap::new();
    for version in modes.versions() {
        match maps.get(store, fleet, version) {
            Ok(map) => {
                built.insert(version, map);
            }
            Err(e) => tracing::error!(fleet, version, "localization map not built: {e}"),
        }
    }
    (modes, built)
}

/// A fleet's modes as stored.
pub fn modes_of(stored: &StoredModes) -> FleetModes {
    FleetModes::from_stored(stored.fleet, &stored.robots)
}
