//! The mapping server's configuration (TOML). Every field has a default; `deploy/mapper.toml`
//! shows them all.

mod cluster;
mod foxglove;
mod localization;

pub use cluster::ClusterConfig;
pub use foxglove::FoxgloveConfig;
pub use localization::LocalizationConfig;
use runtime::session::SessionConfig;
use serde::{Deserialize, Serialize};
use slam::Mapper2dParams;
use slam::geodesy::Geodetic;
use std::num::{NonZeroU64, NonZeroUsize};
use std::path::{Path, PathBuf};

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
    /// Bearer token of write and operator routes; empty: those routes are refused. It also
    /// reads.
    pub token: String,
    /// Bearer token of every `/api` route but `/api/v1/auth`; empty: reading needs no token.
    /// `/healthz`, `/metrics` and the dashboard's files stay open.
    pub read_token: String,
    /// What the HTTP API serves at once, and to which other origins.
    pub http: HttpConfig,
    /// The map's GPS datum (WGS84): the origin of its east-north frame, where the robots'
    /// odometry frames start. Unset: the first fix of each fleet.
    pub datum: Option<Geodetic>,
    /// Beams beyond this range are not used (m).
    pub max_range_m: f32,
    /// Solve a fleet's network at most this often (ms); nodes arriving between solves are
    /// placed by scan matching and odometry at once and corrected at the next solve.
    pub solve_interval_ms: u64,
    /// The pose network and scan matching. Keys a file leaves out keep the fleet's defaults
    /// ([`fleet_mapping_params`]), also inside a table it gives in part.
    #[serde(deserialize_with = "over_fleet_mapping")]
    pub mapping: Mapper2dParams,
    /// Where each fleet's map goes to ROS 2 (`/levelmap/<fleet>/map`); unset: nowhere.
    pub ros2_out: Option<runtime::ros2::RosOutConfig>,
    /// Map versions: frozen maps kept in the store (`[versions]`).
    pub versions: VersionsConfig,
    /// Robots localizing on a map version (`[localization]`).
    pub localization: LocalizationConfig,
    /// How long 3D clouds are kept (`[clouds]`).
    pub clouds: CloudsConfig,
    /// Snapshots of the fleets' maps in the store (`[store]`).
    pub store: StoreConfig,
    /// Cluster mode (`[cluster]`, docs/cluster.md): the fleets are sites spread over
    /// mapper hosts, each site's record in NATS JetStream. Unset: this one process holds
    /// every fleet (single-machine mode, the default).
    pub cluster: Option<ClusterConfig>,
    /// The fleets live in Foxglove (`[foxglove]`, docs/foxglove.md); off by default.
    pub foxglove: FoxgloveConfig,
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            zenoh: SessionConfig::default(),
            http_listen: "127.0.0.1:8080".into(),
            store_path: PathBuf::from("levelmap-mapper.redb"),
            fleets: vec!["park".into()],
            token: String::new(),
            read_token: String::new(),
            http: HttpConfig::default(),
            datum: None,
            max_range_m: 40.0,
            solve_interval_ms: 500,
            mapping: fleet_mapping_params(),
            ros2_out: None,
            versions: VersionsConfig::default(),
            localization: Default::default(),
            clouds: CloudsConfig::default(),
            store: StoreConfig::default(),
            cluster: None,
            foxglove: FoxgloveConfig::default(),
        }
    }
}
impl MapperConfig {
    /// Reads a TOML file (none: the defaults), then the `LEVELMAP_…` environment variables
    /// (`runtime::session::env`); unknown keys are errors.
    pub fn load(path: Option<&Path>) -> anyhow::Result<MapperConfig> {
        runtime::session::load_toml(path)
    }
}

/// The HTTP API's limits and cross-origin access (`[http]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HttpConfig {
    /// Heavy requests (the grid, the graph, covariances, a node's detail and cloud, GeoJSON)
    /// worked on at once; one more is answered 503 with `Retry-After` instead of queuing.
    pub heavy_requests: NonZeroUsize,
    /// How long a heavy request is waited for (ms) before it is answered 503. Its work runs
    /// on and keeps its place among `heavy_requests` until it ends.
    pub heavy_timeout_ms: NonZeroU64,
    /// Event streams (`/api/v1/events`) and robots' live feeds (`…/robots/{robot}/live`)
    /// open at once; one more is answered 503.
    pub event_streams: NonZeroUsize,
    /// Origins (`https://host[:port]`) whose pages may call the API (CORS); empty: no CORS
    /// headers, so only pages served by the mapper itself can read its answers.
    pub cors_origins: Vec<CorsOrigin>,
    /// A web map the dashboard may draw under the grid (`[http.base_map]`); none (the
    /// default): the page asks no other server for anything, as offline sites need.
    pub base_map: Option<BaseMap>,
}

/// A base map's XYZ tiles (Web Mercator, 256 px), drawn under the dashboard's grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BaseMap {
    /// The tiles' address with `{z}`, `{x}` and `{y}`, e.g.
    /// `https://tile.openstreetmap.org/{z}/{x}/{y}.png`. The browser fetches them itself, so
    /// the server must send CORS headers (OpenStreetMap's do).
    pub url: BaseMapUrl,
    /// Credit the tiles' provider asks for, shown over the map.
    #[serde(default)]
    pub attribution: String,
    /// The deepest zoom level the server has.
    #[serde(default = "default_base_map_zoom")]
    pub max_zoom: u8,
}

fn default_base_map_zoom() -> u8 {
    19
}

/// An XYZ tile address template: http(s), with `{z}`, `{x}` and `{y}`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(try_from = "String", into = "String")]
#[schema(value_type = String)]
pub struct BaseMapUrl(String);

impl TryFrom<String> for BaseMapUrl {
    type Error = String;

    fn try_from(url: String) -> Result<Self, String> {
        let web = url.starts_with("https://") || url.starts_with("http://");
        let placeholders = ["{z}", "{x}", "{y}"].iter().all(|p| url.contains(p));
        if web && placeholders {
            Ok(BaseMapUrl(url))
        } else {
            Err(format!(
                "base_map.url: {url:?} is not a tile address: want http[s]://… with {{z}}, {{x}} and {{y}}"
            ))
        }
    }
}

impl From<BaseMapUrl> for String {
    fn from(u: BaseMapUrl) -> String {
        u.0
    }
}

impl Default for HttpConfig {
    fn default() -> Self {
        HttpConfig {
            heavy_requests: NonZeroUsize::new(4).expect("nonzero"),
            heavy_timeout_ms: NonZeroU64::new(10_000).expect("nonzero"),
            event_streams: NonZeroUsize::new(256).expect("nonzero"),
            cors_origins: Vec::new(),
            base_map: None,
        }
    }
}

/// Cloud retention (`[clouds]`): each fleet's 3D clouds (for viewing; never mapped) are
/// dropped oldest first, off the worker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CloudsConfig {
    /// Drop clouds of nodes older than this (s); 0 keeps them however old.
    pub max_age_s: u64,
    /// Drop the oldest beyond this many bytes of clouds per fleet; 0: no bound.
    pub max_bytes: u64,
    /// Apply the two every this many seconds.
    pub prune_every_s: NonZeroU64,
}

impl Default for CloudsConfig {
    fn default() -> Self {
        CloudsConfig {
            max_age_s: 0,
            max_bytes: 2 << 30,
            prune_every_s: NonZeroU64::new(60).expect("nonzero"),
        }
    }
}

/// Map versions (`[versions]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VersionsConfig {
    /// Versions a fleet keeps at most; one more is refused (409) until one is deleted. Each
    /// is the whole map: 8 bytes a beam of every node's scan (2–3 KB a simulated node), a
    /// byte a grid cell (0.6 MB for 80 m × 80 m).
    pub max_versions: NonZeroUsize,
}

impl Default for VersionsConfig {
    fn default() -> Self {
        VersionsConfig {
            max_versions: NonZeroUsize::new(20).expect("nonzero"),
        }
    }
}

/// Snapshots of the fleets' maps (`[store]`): a restart restores a fleet from its newest
/// snapshot and maps only the nodes stored after it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StoreConfig {
    /// A fleet's snapshot is written once it took this many nodes and solves since its last
    /// one (what a restore from it would replay; robots passing over mapped ground add
    /// solves, not nodes), when no solve of it is out, and at a graceful stop; 0: never, and
    /// none stored is used (a restart replays every node). Writing one stalls the worker for
    /// a time that grows with the map.
    pub snapshot_every_nodes: u64,
}

impl Default for StoreConfig {
    fn default() -> Self {
        StoreConfig {
            snapshot_every_nodes: 1000,
        }
    }
}

/// A web origin as browsers send it in `Origin`: scheme, host and optional port, no path.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct CorsOrigin(String);

impl CorsOrigin {
    /// The origin as written.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl TryFrom<String> for CorsOrigin {
    type Error = String;

    fn try_from(origin: String) -> Result<Self, String> {
        let host = origin
            .strip_prefix("https://")
            .or_else(|| origin.strip_prefix("http://"));
        // Browsers send the origin without a path and in lower case: anything else never
        // matches, so it is refused here rather than silently ignored.
        let valid = host.is_some_and(|h| {
            !h.is_empty()
                && h.bytes()
                    .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b"-.:[]".contains(&b))
        });
        if valid {
            Ok(CorsOrigin(origin))
        } else {
            Err(format!(
                "cors_origins: {origin:?} is not an origin: want http[s]://host[:port] in lower \
                 case, without a path or a trailing /"
            ))
        }
    }
}

impl From<CorsOrigin> for String {
    fn from(o: CorsOrigin) -> String {
        o.0
    }
}

/// `[mapping]` as given, over the fleet's defaults: a table given in part (`[mapping.coverage]`
/// alone) keeps the fleet's values for the keys it leaves out, not the library's.
fn over_fleet_mapping<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Mapper2dParams, D::Error> {
    use serde::de::Error;
    let given = toml::Value::deserialize(d)?;
    let mut merged = toml::Value::try_from(fleet_mapping_params()).map_err(D::Error::custom)?;
    merge_over(&mut merged, given);
    merged.try_into().map_err(D::Error::custom)
}

/// `over` laid on `base`, table by table, so a key no table knows stays and is refused. A
/// table that names its kernel (`{ kernel = "huber", delta = 1.5 }` for a Cauchy one)
/// replaces the one it lands on: another kernel's parameters come with it.
fn merge_over(base: &mut toml::Value, over: toml::Value) {
    match (base, over) {
        (toml::Value::Table(base), toml::Value::Table(over)) if !over.contains_key("kernel") => {
            for (key, value) in over {
                match base.get_mut(&key) {
                    Some(slot) => merge_over(slot, value),
                    None => {
                        base.insert(key, value);
                    }
                }
            }
        }
        (base, over) => *base = over,
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

    /// Every table of the config, the unset ones too, refuses a misspelt key, naming the
    /// file, the line and the keys expected (a typo must not silently become a default).
    #[test]
    fn a_misspelt_key_in_any_table_is_refused_with_its_file_and_line() {
        settings::typos::assert_every_table_refuses::<MapperConfig, _>(
            &["cluster", "cluster.nats"],
            20,
            |path| MapperConfig::load(Some(path)),
        );
    }

    #[test]
    fn the_deploy_file_states_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/mapper.toml");
        let file = runtime::session::load_toml_with(Some(&path), []).unwrap();
        assert_eq!(MapperConfig::default(), file);
    }

    #[test]
    fn the_cluster_host_file_is_a_whole_valid_host() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/cluster/mapper-host.toml");
        let file: MapperConfig = runtime::session::load_toml_with(Some(&path), []).unwrap();
        let cluster = file.cluster.expect("[cluster]");
        cluster.check().unwrap();
        assert_eq!(cluster.nats.servers.len(), 3);
        assert_eq!(file.mapping, MapperConfig::default().mapping);
        let lone = ClusterConfig {
            host: "h9".into(),
            ..cluster
        };
        assert!(
            lone.check()
                .unwrap_err()
                .to_string()
                .contains("must list this host")
        );
    }

    fn env(pairs: &[(&str, &str)]) -> Vec<(std::ffi::OsString, std::ffi::OsString)> {
        pairs.iter().map(|(k, v)| (k.into(), v.into())).collect()
    }

    #[test]
    fn every_key_can_come_from_the_environment_without_a_file() {
        let config: MapperConfig = runtime::session::load_toml_with(
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
        assert_eq!(config.zenoh.listen, Some(vec!["tcp/10.0.0.1:7447".into()]));
        // Still a router: the mapper's session falls back to its role's mode.
        let zenoh = config
            .zenoh
            .to_zenoh(runtime::session::Role::Router)
            .unwrap();
        assert_eq!(zenoh.get_json("mode").unwrap(), r#""router""#);
        assert_eq!(config.mapping.idc.min_correspondences, 12);
        // The fleet's mapping defaults, not the library's, around the key that was set.
        assert_eq!(config.mapping.odometry_sigma_xy_per_m, 0.02);
        assert_eq!(config.datum.map(|d| d.height_m), Some(55.0));
        assert_eq!(config.solve_interval_ms, defaults.solve_interval_ms);
    }

    #[test]
    fn a_variable_that_names_no_key_is_an_error() {
        let load = |pairs| runtime::session::load_toml_with::<MapperConfig>(None, env(pairs));
        // A typo at the top and one in the mapping's parameters.
        let e = load(&[("LEVELMAP_HTTP_LISTN", "x")]).unwrap_err();
        assert!(e.to_string().contains("LEVELMAP_HTTP_LISTN"), "{e}");
        assert!(e.to_string().contains("http_listn"), "{e}");
        let e = load(&[("LEVELMAP_MAPPING__ODOMETRY_SIGMA", "0.1")]).unwrap_err();
        let e = e.to_string();
        assert!(e.contains("LEVELMAP_MAPPING__ODOMETRY_SIGMA"), "{e}");
        assert!(
            e.contains("odometry_sigma") && e.contains("expected"),
            "{e}"
        );
        // A value of the wrong type, as in the file.
        let e = load(&[("LEVELMAP_SOLVE_INTERVAL_MS", "soon")]).unwrap_err();
        assert!(e.to_string().contains("LEVELMAP_SOLVE_INTERVAL_MS"), "{e}");
    }

    #[test]
    fn the_environment_wins_over_the_file() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/mapper.toml");
        let config: MapperConfig =
            runtime::session::load_toml_with(Some(&path), env(&[("LEVELMAP_TOKEN", "s3cret")]))
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
    fn a_mapping_table_given_in_part_keeps_the_fleets_defaults() {
        let config: MapperConfig = toml::from_str(
            "[mapping.coverage]\nenabled = false\n[mapping.loop_robust]\nkernel = \"huber\"\ndelta = 2.0\n",
        )
        .unwrap();
        let fleet = fleet_mapping_params();
        assert!(!config.mapping.coverage.enabled);
        assert_eq!(
            config.mapping.loop_robust,
            slam::Robust::Huber { delta: 2.0 }
        );
        // The keys it leaves out: the fleet's, not the library's.
        assert_eq!(config.mapping.idc, fleet.idc);
        assert_eq!(config.mapping.odometry_sigma_xy_per_m, 0.02);
        assert_eq!(config.mapping.coverage.radius_m, fleet.coverage.radius_m);
    }

    #[test]
    fn cors_origins_are_checked_when_read() {
        let ok: MapperConfig =
            toml::from_str("[http]\ncors_origins = [\"https://ops.example.org:8443\"]").unwrap();
        assert_eq!(
            ok.http.cors_origins[0].as_str(),
            "https://ops.example.org:8443"
        );
        for bad in [
            "https://ops.example.org/",
            "ops.example.org",
            "*",
            "https://Ops.example.org",
        ] {
            let text = format!("[http]\ncors_origins = [{bad:?}]");
            let e = toml::from_str::<MapperConfig>(&text).unwrap_err();
            assert!(e.to_string().contains("not an origin"), "{bad}: {e}");
        }
        let e = toml::from_str::<MapperConfig>("[http]\nheavy_requests = 0").unwrap_err();
        assert!(e.to_string().contains("heavy_requests"), "{e}");
    }

    #[test]
    fn a_base_map_needs_a_tile_address() {
        let ok: MapperConfig = toml::from_str(
            "[http.base_map]\nurl = \"https://tile.openstreetmap.org/{z}/{x}/{y}.png\"",
        )
        .unwrap();
        let base = ok.http.base_map.unwrap();
        assert_eq!((base.max_zoom, base.attribution.as_str()), (19, ""));
        for bad in [
            "tile.example.org/{z}/{x}/{y}.png",
            "https://tile.example.org/{z}/{x}.png",
        ] {
            let text = format!("[http.base_map]\nurl = {bad:?}");
            let e = toml::from_str::<MapperConfig>(&text).unwrap_err();
            assert!(e.to_string().contains("not a tile address"), "{bad}: {e}");
        }
    }

    #[test]
    fn an_unknown_key_is_an_error() {
        let e = toml::from_str::<MapperConfig>("http_listn = \"x\"").unwrap_err();
        assert!(e.to_string().contains("http_listn"), "{e}");
    }
}
