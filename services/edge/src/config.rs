//! The edge service's configuration (TOML). Every field has a default; `deploy/edge.toml`
//! shows them all.

use crate::cloud::CloudParams;
use crate::node::NodeParams;
use crate::source::{FilesSourceConfig, McapSourceConfig, Ros2SourceConfig, SimSourceConfig};
use leveling::SegmentParams;
use runtime::session::SessionConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The edge service's configuration (`deploy/edge.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EdgeConfig {
    /// Fleet (site) id: `[A-Za-z0-9_-]+`.
    pub fleet: String,
    /// This robot's id: `[A-Za-z0-9_-]+`, unique in the fleet.
    pub robot: String,
    /// The Zenoh session: a client of the mapper's router by default.
    pub zenoh: SessionConfig,
    /// The on-disk outbox (redb file): nodes stay here until the mapper acks them.
    pub outbox_path: PathBuf,
    /// Acked nodes the outbox keeps, newest first, for a mapper started from a backup that
    /// asks for the nodes it acked after it: 10,000 (about 2.8 h at a node a second; 3 KB a
    /// node, 44 KB with its cloud: 30 MB or 440 MB of disk). 0 drops each node at its ack.
    pub outbox_keep_acked: u64,
    /// When to start a node.
    pub node: NodeParams,
    /// Segmentation thresholds (paper 3.1); see deploy/leveling.toml.
    pub leveling: SegmentParams,
    /// Whether nodes carry their segmented 3D cloud, and how it is reduced.
    pub cloud: CloudParams,
    /// Live odometry publication rate (Hz).
    pub odometry_rate_hz: f64,
    /// Live leveled scans for teleoperation views, at most this often (Hz, best effort, the
    /// first dropped under load); 0: none.
    pub live_scan_rate_hz: f64,
    /// Re-send every unacked node after this long without ack progress (ms).
    pub resend_after_ms: u64,
    /// Each re-send that brings no ack progress doubles that wait, up to this (ms): a dead
    /// link costs one window of re-sends every 8 s rather than every second, and a mapper
    /// back (a cluster takeover takes 4–9 s) hears from a robot that makes no new node within
    /// 8 s. Progress or a new session brings the wait back to `resend_after_ms`.
    pub resend_max_after_ms: u64,
    /// With nodes waiting and no ack for this long (ms), close the Zenoh session and open a
    /// new one: a transport Zenoh keeps but the router no longer routes must not hold nodes
    /// back for good; 0: never. 15 s lets Zenoh mend a dead link first (a put blocked 5 s or
    /// its 10 s lease closes the transport, and it dials again within 1–4 s), and is far
    /// above the mapper's ack latency (p99 44 ms with 100 robots).
    pub reopen_link_after_ms: u64,
    /// Source time per wall-clock time: 1 is real time, 0 as fast as possible.
    pub speed: f64,
    /// At the source's end, keep running until every node is acked (or shutdown); with
    /// `ros2_out`, also until the correction of the last node has come (at most 3 s).
    pub linger_for_acks: bool,
    /// The measurement source.
    pub source: SourceConfig,
    /// Where the map→odom transform goes back to the robot's ROS 2 stack (`/tf`); unset:
    /// nowhere.
    pub ros2_out: Option<runtime::ros2::RosOutConfig>,
}

/// The measurement source.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum SourceConfig {
    /// A simulated robot in the hilly park.
    Sim(SimSourceConfig),
    /// Scan files in a folder (KITTI, 3DTK, simulator JSON).
    Files(FilesSourceConfig),
    /// A ROS 2 recording (MCAP).
    Mcap(McapSourceConfig),
    /// A ROS 2 robot's live topics over Zenoh.
    Ros2(Ros2SourceConfig),
}

impl SourceConfig {
    /// A ROS 2 source's first key that no field takes (those tables take their streams'
    /// keys flattened, where serde cannot deny unknown ones): its table, the key and the
    /// keys expected.
    pub fn unknown_key(&self) -> Option<(&'static str, &str, Vec<String>)> {
        fn known<T: Serialize>(defaults: T) -> Vec<String> {
            toml::Table::try_from(defaults)
                .map(|t| t.keys().cloned().collect())
                .unwrap_or_default()
        }
        let (table, unknown, expected) = match self {
            SourceConfig::Mcap(c) => ("mcap", &c.unknown, known(McapSourceConfig::default())),
            SourceConfig::Ros2(c) => ("ros2", &c.unknown, known(Ros2SourceConfig::default())),
            SourceConfig::Sim(_) | SourceConfig::Files(_) => return None,
        };
        let key = unknown.keys().next()?;
        Some((table, key.as_str(), expected))
    }
}

impl Default for SourceConfig {
    fn default() -> Self {
        SourceConfig::Sim(SimSourceConfig::default())
    }
}

impl Default for EdgeConfig {
    fn default() -> Self {
        EdgeConfig {
            fleet: "park".into(),
            robot: "robot0".into(),
            zenoh: SessionConfig::default(),
            outbox_path: PathBuf::from("levelmap-edge-outbox.redb"),
            outbox_keep_acked: 10_000,
            node: NodeParams::default(),
            leveling: SegmentParams::default(),
            cloud: CloudParams::default(),
            odometry_rate_hz: 10.0,
            live_scan_rate_hz: 2.0,
            resend_after_ms: 1000,
            resend_max_after_ms: 8000,
            reopen_link_after_ms: 15_000,
            speed: 1.0,
            linger_for_acks: true,
            source: SourceConfig::default(),
            ros2_out: None,
        }
    }
}

impl EdgeConfig {
    /// Reads a TOML file (none: the defaults), then the `LEVELMAP_…` environment variables
    /// (`runtime::session::env`); unknown keys are errors (a typo must not silently become a
    /// default), and `[leveling]` is checked as `levelmap level` checks it.
    pub fn load(path: Option<&Path>) -> anyhow::Result<EdgeConfig> {
        let config: EdgeConfig = runtime::session::load_toml(path)?;
        if let Some((table, key, expected)) = config.source.unknown_key() {
            // Where the file has it (a key the environment set names its variable at load).
            let at = path
                .and_then(|p| {
                    let text = std::fs::read_to_string(p).ok()?;
                    let line = settings::line_of(&text, &["source", table, key])?;
                    Some(format!("{}: line {line}: ", p.display()))
                })
                .unwrap_or_default();
            anyhow::bail!(
                "{at}[source.{table}]: unknown key `{key}`, expected one of {}",
                expected.join(", ")
            );
        }
        config.check()?;
        Ok(config)
    }

    /// The checks beyond the keys' types: the segmentation's thresholds (paper 3.1).
    pub fn check(&self) -> anyhow::Result<()> {
        self.leveling
            .validate()
            .map_err(|e| anyhow::anyhow!("[leveling]: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every table of the config, the unset ones too, refuses a misspelt key, naming the
    /// file, the line and the keys expected (a typo must not silently become a default).
    #[test]
    fn a_misspelt_key_in_any_table_is_refused_with_its_file_and_line() {
        settings::typos::assert_every_table_refuses::<EdgeConfig, _>(
            &["ros2_out", "source.files", "source.mcap", "source.ros2"],
            8,
            |path| EdgeConfig::load(Some(path)),
        );
    }

    #[test]
    fn the_deploy_file_states_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/edge.toml");
        let file = runtime::session::load_toml_with(Some(&path), []).unwrap();
        assert_eq!(EdgeConfig::default(), file);
    }

    #[test]
    fn leveling_thresholds_are_checked_at_load() {
        let dir = std::env::temp_dir().join(format!("edge-leveling-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("edge.toml");
        std::fs::write(&path, "[leveling]\nmax_misalignment_deg = 95\n").unwrap();
        let why = EdgeConfig::load(Some(&path)).unwrap_err().to_string();
        assert!(
            why.contains("[leveling]") && why.contains("max_misalignment_deg"),
            "{why}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_robot_id_and_nested_keys_come_from_the_environment() {
        let env = [
            ("LEVELMAP_ROBOT", "007"),
            ("LEVELMAP_ZENOH__CONNECT", r#"["tcp/10.0.0.1:7447"]"#),
            ("LEVELMAP_SOURCE__SIM__SEED", "9"),
            ("LEVELMAP_CLOUD__KEEP", "false"),
        ]
        .map(|(k, v)| (k.into(), v.into()));
        let config: EdgeConfig = runtime::session::load_toml_with(None, env).unwrap();
        // A numeric-looking id stays a string: the key holds one.
        assert_eq!(config.robot, "007");
        assert_eq!(config.zenoh.connect, Some(vec!["tcp/10.0.0.1:7447".into()]));
        assert!(!config.cloud.keep);
        let SourceConfig::Sim(sim) = &config.source else {
            panic!("{:?}", config.source)
        };
        assert_eq!(sim.seed, 9);
        assert_eq!(sim.loop_index, SimSourceConfig::default().loop_index);
    }

    #[test]
    fn a_mapper_key_is_not_an_edge_key() {
        let env = [("LEVELMAP_TOKEN".into(), "x".into())];
        let e = runtime::session::load_toml_with::<EdgeConfig>(None, env).unwrap_err();
        assert!(e.to_string().contains("LEVELMAP_TOKEN"), "{e}");
    }
}
