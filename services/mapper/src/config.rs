//! The mapping server's configuration (TOML). Every field has a default; `deploy/mapper.toml`
//! shows them all.

use serde::{Deserialize, Serialize};
use slam::Mapper2dParams;
use slam::geodesy::Geodetic;
use std::path::{Path, PathBuf};
use wire::session::SessionConfig;

/// The mapping server's configuration (`deploy/mapper.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MapperConfig {
    /// The Zenoh session: a router listening on TCP by default; robots connect as clients.
    pub zenoh: SessionConfig,
    /// The HTTP API's address.
    pub http_listen: String,
    /// The durable store (a redb file).
    pub store_path: PathBuf,
    /// Fleets this mapper serves; nodes of any other fleet are rejected (and counted).
    pub fleets: Vec<String>,
    /// Bearer token of write and operator routes; empty: those routes are refused.
    pub token: String,
    /// The map's GPS datum (WGS84): the origin of its east-north frame, where the robots'
    /// odometry frames start. Unset: the first fix of each fleet.
    pub datum: Option<Geodetic>,
    /// Beams beyond this range are not used (m).
    pub max_range_m: f32,
    /// Solve a fleet's network at most this often (ms); nodes arriving between solves are
    /// placed by scan matching and odometry at once and corrected at the next solve.
    pub solve_interval_ms: u64,
    /// The pose network and scan matching.
    pub mapping: Mapper2dParams,
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            zenoh: SessionConfig::default(),
            http_listen: "127.0.0.1:8080".into(),
            store_path: PathBuf::from("levelmap-mapper.redb"),
            fleets: vec!["park".into()],
            token: String::new(),
            datum: None,
            max_range_m: 40.0,
            solve_interval_ms: 500,
            mapping: fleet_mapping_params(),
        }
    }
}

impl MapperConfig {
    /// A fleet's empty map, as this configuration sets it up.
    pub fn new_fleet(&self, id: &str) -> crate::fleet::FleetMap {
        crate::fleet::FleetMap::new(
            id,
            self.mapping.clone(),
            self.datum.map(|origin| slam::geodesy::GeoDatum { origin }),
            self.max_range_m,
        )
    }

    /// Reads a TOML file; unknown keys are errors.
    pub fn load(path: &Path) -> anyhow::Result<MapperConfig> {
        wire::session::load_toml(path)
    }
}

/// The mapping parameters for fleets of robots sending a node every metre or so (measured on
/// the simulated park: `services/sim/tests/fleet_mapping.rs`).
pub fn fleet_mapping_params() -> Mapper2dParams {
    let defaults = Mapper2dParams::default();
    Mapper2dParams {
        odometry_sigma_xy_per_m: 0.02,
        idc: slam::matching::IdcParams {
            min_correspondences: 10,
            ..defaults.idc.clone()
        },
        ..defaults
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_deploy_file_states_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/mapper.toml");
        assert_eq!(MapperConfig::load(&path).unwrap(), MapperConfig::default());
    }

    #[test]
    fn an_unknown_key_is_an_error() {
        let e = toml::from_str::<MapperConfig>("http_listn = \"x\"").unwrap_err();
        assert!(e.to_string().contains("http_listn"), "{e}");
    }
}
