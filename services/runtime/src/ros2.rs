//! ROS 2 over Zenoh, the two ways it is laid on keys: rmw_zenoh (`<domain_id>/<topic>/<dds
//! type>/<type hash>`, each sample with rmw_zenoh's attachment, each entity announced by a
//! liveliness token) and zenoh-bridge-ros2dds (`[namespace/]<topic>`, plain CDR). The edge
//! reads a robot's topics this way (`[source.ros2]`) and both services write theirs
//! (`[ros2_out]`: the map→odom transform, the fleet's occupancy grid).

use crate::session::{Role, SessionConfig};
use ros2msg::RosType;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicI64, AtomicU32, Ordering};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// How ROS 2 topics are laid on Zenoh keys.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KeyStyle {
    /// rmw_zenoh: `<domain_id>/<topic>/<dds type>/<type hash>`.
    #[default]
    RmwZenoh,
    /// zenoh-bridge-ros2dds: `<namespace>/<topic>`.
    Ros2dds,
}

/// How the mapper's `OccupancyGrid` carries a cell, as Nav2's map_server publishes a map it
/// loaded in that mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapValues {
    /// 0 free, 100 occupied, −1 unknown (Nav2's static layer reads only 100 as an obstacle).
    #[default]
    Trinary,
    /// The evidence: 0 free, 100 occupied, 1–99 for a cell seen but undecided between the
    /// thresholds, −1 never seen.
    Scale,
}

/// Where a ROS 2 network's topics are: the key style and its parameters.
#[derive(Clone, Copy, Debug)]
pub struct RosKeys<'a> {
    /// See [`KeyStyle`].
    pub style: KeyStyle,
    /// The ROS domain (rmw_zenoh's first key chunk).
    pub domain_id: u32,
    /// zenoh-bridge-ros2dds's namespace prefix (empty: none).
    pub namespace: &'a str,
}

/// The DDS name of a ROS 2 type: `sensor_msgs/msg/Imu` → `sensor_msgs::msg::dds_::Imu_`.
pub fn dds_type_name(type_name: &str) -> String {
    match type_name.rsplit_once('/') {
        Some((package, name)) => format!("{}::dds_::{name}_", package.replace('/', "::")),
        None => type_name.to_owned(),
    }
}

impl RosKeys<'_> {
    /// The key expression a topic's samples of any type hash come on.
    pub fn subscription(&self, topic: &str, type_name: &str) -> String {
        self.key(topic, type_name, "*")
    }

    /// The key a publisher of `ros_type` on `topic` puts its samples on.
    pub fn publication(&self, topic: &str, ros_type: &RosType) -> String {
        self.key(topic, ros_type.name, ros_type.hash)
    }

    fn key(&self, topic: &str, type_name: &str, hash: &str) -> String {
        let topic = topic.trim_start_matches('/');
        match self.style {
            KeyStyle::RmwZenoh => format!(
                "{}/{topic}/{}/{hash}",
                self.domain_id,
                dds_type_name(type_name)
            ),
            KeyStyle::Ros2dds if self.namespace.is_empty() => topic.to_owned(),
            KeyStyle::Ros2dds => format!("{}/{topic}", self.namespace.trim_matches('/')),
        }
    }
}

/// A ROS 2 topic name made of `name`: characters ROS does not allow in a name (`-`, …)
/// become `_`, and a token never starts with a digit (fleet `7-north` → `_7_north`).
pub fn ros_name_token(name: &str) -> String {
    let token: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if token.starts_with(|c: char| c.is_ascii_digit()) {
        format!("_{token}")
    } else {
        token
    }
}

/// `[ros2_out]`: where a service puts what it gives back to ROS 2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RosOutConfig {
    /// How topics are laid on keys.
    pub key_style: KeyStyle,
    /// The ROS domain (rmw_zenoh's first key chunk).
    pub domain_id: u32,
    /// zenoh-bridge-ros2dds's namespace prefix (empty: none).
    pub namespace: String,
    /// The ROS 2 node the publishers belong to, as `ros2 node list` shows it (rmw_zenoh).
    pub node_name: String,
    /// The map frame (`map`): the parent of the published transform, the grid's frame.
    pub map_frame: String,
    /// The robot's odometry frame (`odom`), the child of the published transform (edge).
    pub odom_frame: String,
    /// The mapper publishes a fleet's changed grid at most this often (ms).
    pub map_period_ms: u64,
    /// How the mapper's grid carries a cell.
    pub map_values: MapValues,
    /// The Zenoh session to the ROS 2 network (rmw_zenohd, the bridge): a client of
    /// `tcp/localhost:7447` by default, as `[zenoh]`'s keys.
    pub zenoh: SessionConfig,
}

impl Default for RosOutConfig {
    fn default() -> Self {
        RosOutConfig {
            key_style: KeyStyle::default(),
            domain_id: 0,
            namespace: String::new(),
            node_name: "levelmap".into(),
            map_frame: "map".into(),
            odom_frame: "odom".into(),
            map_period_ms: 2000,
            map_values: MapValues::Trinary,
            zenoh: SessionConfig::default(),
        }
    }
}

impl RosOutConfig {
    /// The keys of this network.
    pub fn keys(&self) -> RosKeys<'_> {
        RosKeys {
            style: self.key_style,
            domain_id: self.domain_id,
            namespace: &self.namespace,
        }
    }
}

/// A publication's durability, as ROS 2 QoS names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Durability {
    /// Late subscribers get nothing old (`/tf`).
    Volatile,
    /// Late subscribers get the last sample (a map): here a queryable answers it.
    TransientLocal,
}

/// A session to a ROS 2 network and what it announces (rmw_zenoh: a node).
pub struct RosOut {
    session: zenoh::Session,
    config: RosOutConfig,
    next_entity: AtomicU32,
    _node_token: Option<zenoh::liveliness::LivelinessToken>,
}

/// The node's own entity id in its liveliness keys.
const NODE_ENTITY: u32 = 0;

impl RosOut {
    /// Opens the session (a client by default) and, for rmw_zenoh, announces the node.
    pub async fn open(config: &RosOutConfig) -> anyhow::Result<RosOut> {
        let session = config
            .zenoh
            .open(Role::Client)
            .await
            .map_err(|e| anyhow::anyhow!("[ros2_out] {e:#}"))?;
        let node_token = match config.key_style {
            KeyStyle::RmwZenoh => Some(
                session
                    .liveliness()
                    .declare_token(node_liveliness(&session, config))
                    .await
                    .map_err(|e| anyhow::anyhow!("[ros2_out] node token: {e}"))?,
            ),
            KeyStyle::Ros2dds => None,
        };
        Ok(RosOut {
            session,
            config: config.clone(),
            next_entity: AtomicU32::new(NODE_ENTITY + 1),
            _node_token: node_token,
        })
    }

    /// The configuration it was opened with.
    pub fn config(&self) -> &RosOutConfig {
        &self.config
    }

    /// Closes the session: what was put goes out first (a session dropped instead may lose
    /// its last samples).
    pub async fn close(self) -> anyhow::Result<()> {
        self.session
            .close()
            .await
            .map_err(anyhow::Error::from_boxed)
    }

    /// A publisher of `ros_type` on `topic`: best effort on the Zenoh side (a sample that
    /// cannot go out at once is dropped, never waited for), announced by rmw_zenoh's token.
    pub async fn publisher(
        &self,
        topic: &str,
        ros_type: &RosType,
        durability: Durability,
    ) -> anyhow::Result<RosPublisher> {
        let key = self.config.keys().publication(topic, ros_type);
        let entity = self.next_entity.fetch_add(1, Ordering::Relaxed);
        let publisher = self
            .session
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Drop)
            .await
            .map_err(|e| anyhow::anyhow!("[ros2_out] publisher on {key}: {e}"))?;
        let token = match self.config.key_style {
            KeyStyle::RmwZenoh => {
                let token_key = publisher_liveliness(
                    &self.session,
                    &self.config,
                    entity,
                    topic,
                    ros_type,
                    durability,
                );
                Some(
                    self.session
                        .liveliness()
                        .declare_token(token_key)
                        .await
                        .map_err(|e| anyhow::anyhow!("[ros2_out] token of {key}: {e}"))?,
                )
            }
            KeyStyle::Ros2dds => None,
        };
        let mut gid = [0u8; 16];
        gid[..8].copy_from_slice(&self.session.zid().to_le_bytes()[..8]);
        gid[8..12].copy_from_slice(&entity.to_le_bytes());
        Ok(RosPublisher {
            publisher,
            style: self.config.key_style,
            sequence: AtomicI64::new(0),
            gid,
            _token: token,
        })
    }

    /// Answers queries on `key` with what `answer` gives (nothing: no reply), for late
    /// joiners of a transient-local topic.
    pub fn answer_queries(
        &self,
        key: &str,
        answer: impl Fn() -> Option<Vec<u8>> + Send + Sync + 'static,
    ) -> anyhow::Result<()> {
        let reply_key = key.to_owned();
        self.session
            .declare_queryable(key)
            .callback(move |query| {
                if let Some(bytes) = answer() {
                    let _ = query.reply(&reply_key, bytes).wait();
                }
            })
            .background()
            .wait()
            .map_err(|e| anyhow::anyhow!("[ros2_out] queryable on {key}: {e}"))
    }
}

/// One topic's publisher.
pub struct RosPublisher {
    publisher: zenoh::pubsub::Publisher<'static>,
    style: KeyStyle,
    sequence: AtomicI64,
    gid: [u8; 16],
    _token: Option<zenoh::liveliness::LivelinessToken>,
}

impl RosPublisher {
    /// The key samples go on.
    pub fn key(&self) -> &str {
        self.publisher.key_expr().as_str()
    }

    /// Puts one CDR sample (rmw_zenoh: with its attachment); `false` if Zenoh refused it.
    pub fn put(&self, sample: Vec<u8>) -> bool {
        let put = self.publisher.put(sample);
        let put = match self.style {
            KeyStyle::RmwZenoh => {
                let seq = self.sequence.fetch_add(1, Ordering::Relaxed) + 1;
                let now = i64::try_from(crate::session::now_ns()).unwrap_or(i64::MAX);
                put.attachment(rmw_zenoh_attachment(seq, now, &self.gid))
            }
            KeyStyle::Ros2dds => put,
        };
        put.wait().is_ok()
    }
}

/// rmw_zenoh's attachment (`AttachmentData`, zenoh-ext serialization): the publisher's
/// sequence number and source time (i64, little endian), then its 16-byte gid.
pub fn rmw_zenoh_attachment(sequence: i64, source_ns: i64, gid: &[u8; 16]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(32);
    bytes.extend_from_slice(&sequence.to_le_bytes());
    bytes.extend_from_slice(&source_ns.to_le_bytes());
    bytes.extend_from_slice(gid);
    bytes
}

/// A name chunk of a liveliness key: `/` becomes `%` (rmw_zenoh's mangling), empty is `%`.
fn mangled(name: &str) -> String {
    if name.is_empty() {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>`.
fn liveliness_prefix(
    session: &zenoh::Session,
    config: &RosOutConfig,
    entity: u32,
    kind: &str,
) -> String {
    let namespace = match config.namespace.trim_matches('/') {
        "" => "%".to_owned(),
        ns => mangled(&format!("/{ns}")),
    };
    format!(
        "@ros2_lv/{}/{}/{NODE_ENTITY}/{entity}/{kind}/%/{namespace}/{}",
        config.domain_id,
        session.zid(),
        config.node_name
    )
}

fn node_liveliness(session: &zenoh::Session, config: &RosOutConfig) -> String {
    liveliness_prefix(session, config, NODE_ENTITY, "NN")
}

/// A publisher's token: the prefix, then topic, type, hash and QoS (rmw_zenoh's
/// `qos_to_keyexpr`: reliability, durability, history and depth, each empty at ROS 2's
/// default — reliable, volatile, keep last 10).
fn publisher_liveliness(
    session: &zenoh::Session,
    config: &RosOutConfig,
    entity: u32,
    topic: &str,
    ros_type: &RosType,
    durability: Durability,
) -> String {
    let qos = match durability {
        Durability::Volatile => "::,100:,:,:,,",
        Durability::TransientLocal => ":1:,1:,:,:,,",
    };
    let topic = format!("/{}", topic.trim_start_matches('/'));
    format!(
        "{}/{}/{}/{}/{qos}",
        liveliness_prefix(session, config, entity, "MP"),
        mangled(&topic),
        dds_type_name(ros_type.name),
        ros_type.hash
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_laid_as_rmw_zenoh_and_the_bridge_lay_them() {
        assert_eq!(
            dds_type_name("sensor_msgs/msg/PointCloud2"),
            "sensor_msgs::msg::dds_::PointCloud2_"
        );
        let mut keys = RosKeys {
            style: KeyStyle::RmwZenoh,
            domain_id: 3,
            namespace: "",
        };
        assert_eq!(
            keys.subscription("/ouster/points", ros2msg::types::POINT_CLOUD2.name),
            "3/ouster/points/sensor_msgs::msg::dds_::PointCloud2_/*"
        );
        assert_eq!(
            keys.publication("/tf", &ros2msg::types::TF_MESSAGE),
            format!(
                "3/tf/tf2_msgs::msg::dds_::TFMessage_/{}",
                ros2msg::types::TF_MESSAGE.hash
            )
        );
        keys.style = KeyStyle::Ros2dds;
        assert_eq!(keys.subscription("/ouster/points", "any"), "ouster/points");
        keys.namespace = "/robot7/";
        assert_eq!(
            keys.publication("/tf", &ros2msg::types::TF_MESSAGE),
            "robot7/tf"
        );
    }

    #[test]
    fn fleet_ids_become_ros_name_tokens() {
        assert_eq!(ros_name_token("park"), "park");
        assert_eq!(ros_name_token("7-north"), "_7_north");
    }

    #[test]
    fn the_attachment_is_rmw_zenohs() {
        let gid = [7u8; 16];
        let a = rmw_zenoh_attachment(5, -2, &gid);
        assert_eq!(a.len(), 32);
        assert_eq!(a[..8], 5i64.to_le_bytes());
        assert_eq!(a[8..16], (-2i64).to_le_bytes());
        assert_eq!(a[16..], gid);
    }
}
