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
            zenoh: SessionConfig::router("tcp/0.0.0.0:7447"),
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

    /// Reads a TOML file (none: the defaults), then the `LEVELMAP_…` environment variables
    /// (`wire::session::env`); unknown keys are errors.
    pub fn load(path: Option<&Path>) -> anyhow::Result<MapperConfig> {
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
        let file = wire::session::load_toml_with(Some(&path), []).unwrap();
        assert_eq!(MapperConfig::default(), file);
    }

    fn env(pairs: &[(&str, &str)]) -> Vec<(std::ffi::OsString, std::ffi::OsString)> {
        pairs.iter().map(|(k, v)| (k.into(), v.into())).collect()
    }

    #[test]
    fn every_key_can_come_from_the_environment_without_a_file() {
        let config: MapperConfig = wire::session::load_toml_with(
            None,
            env(&[
                ("LEVELMAP_HTTP_LISTEN", "0.0.0.0:8080"),
                ("LEVELMAP_FLEETS", r#"["park", "campus"]"#),
                ("LEVELMAP_STORE_PATH", "/var/lib/levelmap-mapper/store.redb"),
                ("LEVELMAP_ZENOH__LISTEN", r#"["tcp/10.0.0.1:7447"]"#),
                ("LEVELMAP_MAPPING__IDC__MIN_CORRESPONDENCES", "12"),
                ("LEVELMAP_DATUM__LATITUDE_DEG", "52.39"),
                ("LEVELMAP_DATUM__LONGITUDE_DEG", "9.71"),
                ("LEVELMAP_DATUM__HEIGHT_M", "55"),
                ("LEVELMAP_DATA", "../shared/data"),
            ]),
        )
        .unwrap();
        let defaults = MapperConfig::default();
        assert_eq!(config.http_listen, "0.0.0.0:8080");
        assert_eq!(config.fleets, ["park", "campus"]);
        assert_eq!(
            config.store_path,
            Path::new("/var/lib/levelmap-mapper/store.redb")
        );
        assert_eq!(config.zenoh.listen, ["tcp/10.0.0.1:7447"]);
        assert_eq!(config.zenoh.mode, defaults.zenoh.mode);
        assert_eq!(config.mapping.idc.min_correspondences, 12);
        // The fleet's mapping defaults, not the library's, around the key that was set.
        assert_eq!(config.mapping.odometry_sigma_xy_per_m, 0.02);
        assert_eq!(config.datum.map(|d| d.height_m), Some(55.0));
        assert_eq!(config.solve_interval_ms, defaults.solve_interval_ms);
    }

    #[test]
    fn a_variable_that_names_no_key_is_an_error() {
        let load = |pairs| wire::session::load_toml_with::<MapperConfig>(None, env(pairs));
        // A typo among the denied keys, and one among the mapping's (which serde ignores).
        let e = load(&[("LEVELMAP_HTTP_LISTN", "x")]).unwrap_err();
        assert!(e.to_string().contains("LEVELMAP_HTTP_LISTN"), "{e}");
        assert!(e.to_string().contains("http_listn"), "{e}");
        let e = load(&[("LEVELMAP_MAPPING__ODOMETRY_SIGMA", "0.1")]).unwrap_err();
        assert!(e.to_string().contains("mapping.odometry_sigma"), "{e}");
        // A value of the wrong type, as in the file.
        let e = load(&[("LEVELMAP_SOLVE_INTERVAL_MS", "soon")]).unwrap_err();
        assert!(e.to_string().contains("LEVELMAP_SOLVE_INTERVAL_MS"), "{e}");
    }

    #[test]
    fn the_environment_wins_over_the_file() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/mapper.toml");
        let config: MapperConfig =
            wire::session::load_toml_with(Some(&path), env(&[("LEVELMAP_TOKEN", "s3cret")]))
                .unwrap();
        assert_eq!(
            config,
            MapperConfig {
                token: "s3cret".into(),
                ..MapperConfig::default()
            }
        );
    }

    #[test]
    fn an_unknown_key_is_an_error() {
        let e = toml::from_str::<MapperConfig>("http_listn = \"x\"").unwrap_err();
        assert!(e.to_string().contains("http_listn"), "{e}");
    }
}
