//! `[source.ros2]`: a ROS 2 robot's live topics over Zenoh, as rmw_zenoh puts them
//! (`<domain_id>/<topic>/<type>/<type hash>`, the type as DDS names it,
//! `sensor_msgs::msg::dds_::PointCloud2_`) or as zenoh-bridge-ros2dds does (`<topic>`,
//! under an optional namespace), through the same assembler as recordings. Samples wait in
//! a bounded queue; when the edge falls behind, new samples are dropped and counted.

use super::ros::{
    CLOUD_TYPE, GPS_TYPE, IMU_TYPE, ODOMETRY_TYPE, RosAssembler, RosStreams, TF_STATIC_TOPIC,
    TF_TYPE,
};
use super::{Source, SourceEvent};
use runtime::ros2::{KeyStyle, RosKeys};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, sync_channel};
use zenoh::Wait;

/// See the module.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Ros2SourceConfig {
    /// How topics are laid on keys.
    pub key_style: KeyStyle,
    /// The ROS domain (rmw_zenoh's first key chunk).
    pub domain_id: u32,
    /// zenoh-bridge-ros2dds's namespace prefix (empty: none).
    pub namespace: String,
    /// The Zenoh session to the robot's ROS 2 network (rmw_zenohd, the bridge): a client
    /// of `tcp/localhost:7447` by default, as `[zenoh]`'s keys.
    pub zenoh: runtime::session::SessionConfig,
    /// The topics and frames.
    #[serde(flatten)]
    pub streams: RosStreams,
    /// Keys no field takes: refused when the source opens.
    #[serde(flatten, skip_serializing)]
    pub unknown: BTreeMap<String, toml::Value>,
}

impl Ros2SourceConfig {
    /// Where the robot's topics are.
    pub fn keys(&self) -> RosKeys<'_> {
        RosKeys {
            style: self.key_style,
            domain_id: self.domain_id,
            namespace: &self.namespace,
        }
    }
}

/// A sample as received: its topic, type and bytes.
type Received = (&'static str, String, Vec<u8>);

/// See the module.
pub struct Ros2Source {
    samples: Receiver<Received>,
    assembler: RosAssembler,
    dropped: Arc<AtomicU64>,
    // Kept open while the source lives.
    _session: zenoh::Session,
}

/// Samples waiting for the edge, at most.
const QUEUE: usize = 256;

impl Ros2Source {
    /// Subscribes to the configured topics.
    pub fn new(config: &Ros2SourceConfig) -> anyhow::Result<Ros2Source> {
        let inputs = config.streams.inputs("[source.ros2]", &config.unknown)?;
        let zenoh = config.zenoh.to_zenoh(runtime::session::Role::Client)?;
        let session = zenoh::open(zenoh)
            .wait()
            .map_err(|e| anyhow::anyhow!("[source.ros2] zenoh session: {e}"))?;
        let (tx, samples) = sync_channel::<Received>(QUEUE);
        let dropped = Arc::new(AtomicU64::new(0));
        let mut topics: Vec<(String, &'static str)> = vec![
            (inputs.cloud_topic.clone(), CLOUD_TYPE),
            (inputs.odometry_topic.clone(), ODOMETRY_TYPE),
            (TF_STATIC_TOPIC.to_owned(), TF_TYPE),
        ];
        topics.extend(inputs.imu_topic.clone().map(|t| (t, IMU_TYPE)));
        topics.extend(inputs.gps_topic.clone().map(|t| (t, GPS_TYPE)));
        for (topic, type_name) in topics {
            let key = config.keys().subscription(&topic, type_name);
            let (tx, dropped) = (tx.clone(), Arc::clone(&dropped));
            session
                .declare_subscriber(&key)
                .callback(move |sample| {
                    let bytes = sample.payload().to_bytes().into_owned();
                    if tx.try_send((type_name, topic.clone(), bytes)).is_err() {
                        dropped.fetch_add(1, Ordering::Relaxed);
                    }
                })
                .background()
                .wait()
                .map_err(|e| anyhow::anyhow!("[source.ros2] subscribing to {key}: {e}"))?;
            tracing::info!("ROS 2 topic {key}");
        }
        Ok(Ros2Source {
            samples,
            assembler: RosAssembler::new(inputs),
            dropped,
            _session: session,
        })
    }

    /// Samples dropped because the edge fell behind.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

impl Source for Ros2Source {
    /// The next event; live topics never end (the service stops the source).
    fn next_event(&mut self) -> Option<SourceEvent> {
        loop {
            if let Some(event) = self.assembler.pop() {
                return Some(event);
            }
            let (type_name, topic, bytes) = self.samples.recv().ok()?;
            self.assembler.push(&topic, type_name, &bytes);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_keys_are_refused() {
        let config: Ros2SourceConfig =
            toml::from_str("key_style = \"ros2dds\"\ncloud_topc = \"/points\"").expect("parses");
        let error = Ros2Source::new(&config).err().expect("refused").to_string();
        assert!(error.contains("unknown key \"cloud_topc\""), "{error}");
    }
}
