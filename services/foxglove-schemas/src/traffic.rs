//! A fleet's bus traffic as Foxglove's messages, for `levelmap record --foxglove`: each
//! levelmap message in, the Foxglove messages it makes out (pure: no clock, no I/O).
//!
//! | levelmap key | Foxglove topic | schema, frame |
//! |---|---|---|
//! | `…/robots/{robot}/node` | `/{fleet}/robots/{robot}/scan` | `foxglove.LaserScan` in `{fleet}/{robot}/odom`, at the scan frame |
//! | | `/{fleet}/robots/{robot}/cloud` | `foxglove.PointCloud`, likewise (when the node has one) |
//! | | `/{fleet}/robots/{robot}/gps` | `foxglove.LocationFix` per fix, frame `{fleet}/{robot}` |
//! | `…/robots/{robot}/scan` (live) | `/{fleet}/robots/{robot}/live_scan` | `foxglove.LaserScan` in `{fleet}/{robot}/odom` |
//! | `…/robots/{robot}/odom` | `/tf` | `foxglove.FrameTransforms`: `{fleet}/{robot}/odom` → `{fleet}/{robot}` |
//! | `…/map/poses` | `/tf` | `foxglove.FrameTransforms`: `{fleet}/map` → `{fleet}/{robot}/odom`, per robot of the put |
//!
//! A solve's put names each robot's last node and its map pose; the map → odometry transform
//! is that pose composed with the inverse of the node's odometry pose, so it needs the node:
//! the last [`NODES_KEPT`] nodes' odometry poses of each robot are kept.

use crate::{laser_scan, location_fix, map_frame, odom_frame, point_cloud, robot_frame, transform};
use foxglove::Encode;
use foxglove::messages::{FrameTransforms, LaserScan, LocationFix, PointCloud};
use slam::Pose2;
use std::collections::{BTreeMap, HashMap};
use wire::{Topic, WireError};

#[cfg(test)]
mod tests;

/// Nodes per robot whose odometry pose is kept, to place a solve's put (a solve names
/// robots' last nodes, seconds old).
pub const NODES_KEPT: usize = 4096;

/// One Foxglove message made from a levelmap one.
#[derive(Clone, Debug)]
pub struct Made {
    /// Its topic.
    pub topic: String,
    /// Its schema's name (`foxglove.LaserScan`, …).
    pub schema_name: String,
    /// Its schema's encoding (`protobuf`).
    pub schema_encoding: String,
    /// Its schema (a `FileDescriptorSet`).
    pub schema_data: Vec<u8>,
    /// The message, protobuf-encoded.
    pub data: Vec<u8>,
    /// Its measurement time (ns since the Unix epoch).
    pub stamp_ns: u64,
}

fn made<T: Encode>(topic: String, message: &T, stamp_ns: u64) -> Made {
    let schema = T::get_schema().expect("foxglove's well-known messages have schemas");
    let mut data = Vec::new();
    message.encode(&mut data).expect("a Vec takes any message");
    Made {
        topic,
        schema_name: schema.name,
        schema_encoding: schema.encoding,
        schema_data: schema.data.into_owned(),
        data,
        stamp_ns,
    }
}

/// The translation of one fleet's traffic, with what it keeps of it.
#[derive(Default)]
pub struct Traffic {
    /// Per fleet and robot, its last nodes' scan frames in its odometry frame, by node_seq.
    odometry: HashMap<(String, String), BTreeMap<u64, Pose2>>,
}

impl Traffic {
    /// The Foxglove messages of the message `payload` on `key`, received at `received_ns`
    /// (a solve's transforms are stamped with it): none for a key or message that makes none
    /// (acks, summaries, another key); an error for a message that does not decode or check.
    pub fn translate(
        &mut self,
        key: &str,
        payload: &[u8],
        received_ns: u64,
    ) -> Result<Vec<Made>, WireError> {
        if let Ok(k) = wire::parse_robot_key(key) {
            let (fleet, robot) = (k.fleet, k.robot);
            return match k.topic {
                Topic::Node => self.node(fleet, robot, payload),
                Topic::Odom => {
                    let odom = wire::odometry_input(payload)?;
                    let pose = Pose2::from_isometry3(&odom.pose.pose);
                    let (parent, child) = (odom_frame(fleet, robot), robot_frame(fleet, robot));
                    let stamp = odom.pose.stamp_ns;
                    let transforms = vec![transform(parent, child, &pose, stamp)];
                    Ok(vec![tf(&FrameTransforms { transforms }, stamp)])
                }
                Topic::Scan => {
                    let live = wire::decode_live_scan(payload)?;
                    let origin =
                        Pose2::from_isometry3(&live.odometry.pose).compose(&live.scan_origin);
                    let topic = format!("/{fleet}/robots/{robot}/live_scan");
                    let scan = laser_scan(odom_frame(fleet, robot), &origin, &live.scan);
                    Ok(vec![made::<LaserScan>(topic, &scan, live.stamp_ns)])
                }
                Topic::Ack | Topic::Localization => Ok(Vec::new()),
            };
        }
        if wire::message_name_of_key(key) == Some("levelmap.v1.MapPoses") {
            return self.map_poses(payload, received_ns);
        }
        Ok(Vec::new())
    }

    fn node(&mut self, fleet: &str, robot: &str, payload: &[u8]) -> Result<Vec<Made>, WireError> {
        let node = wire::decode_node(payload)?;
        let origin = Pose2::from_isometry3(&node.odometry.pose).compose(&node.scan_origin);
        let kept = self
            .odometry
            .entry((fleet.to_owned(), robot.to_owned()))
            .or_default();
        kept.insert(node.node_seq, origin);
        while kept.len() > NODES_KEPT {
            kept.pop_first();
        }
        let topic = |what: &str| format!("/{fleet}/robots/{robot}/{what}");
        let frame = || odom_frame(fleet, robot);
        let mut out = vec![made::<LaserScan>(
            topic("scan"),
            &laser_scan(frame(), &origin, &node.scan),
            node.stamp_ns,
        )];
        if let Some(cloud) = &node.cloud {
            let msg = point_cloud(frame(), &origin, cloud, node.stamp_ns);
            out.push(made::<PointCloud>(topic("cloud"), &msg, node.stamp_ns));
        }
        for fix in &node.gps {
            if let Some(msg) = location_fix(robot_frame(fleet, robot), fix) {
                out.push(made::<LocationFix>(topic("gps"), &msg, fix.stamp_ns));
            }
        }
        Ok(out)
    }

    fn map_poses(&mut self, payload: &[u8], stamp_ns: u64) -> Result<Vec<Made>, WireError> {
        let (fleet, poses) = wire::decode_map_poses(payload)?;
        let mut transforms = Vec::new();
        for p in &poses {
            let key = (fleet.clone(), p.robot.clone());
            let Some(odometry) = self.odometry.get(&key).and_then(|k| k.get(&p.node_seq)) else {
                continue;
            };
            let map_to_odom = p.pose.compose(&odometry.inverse());
            let (parent, child) = (map_frame(&fleet), odom_frame(&fleet, &p.robot));
            transforms.push(transform(parent, child, &map_to_odom, stamp_ns));
        }
        Ok(match transforms.is_empty() {
            true => Vec::new(),
            false => vec![tf(&FrameTransforms { transforms }, stamp_ns)],
        })
    }
}

fn tf(transforms: &FrameTransforms, stamp_ns: u64) -> Made {
    made::<FrameTransforms>("/tf".into(), transforms, stamp_ns)
}
