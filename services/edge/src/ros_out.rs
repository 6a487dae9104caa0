//! `[ros2_out]` on the robot: the map→odom transform on `/tf`, so that the robot's own ROS 2
//! stack (RViz, Nav2) sees it in the fleet's map. The mapper sends back the corrected pose of
//! the robot's last node; with that node's odometry, the correction is
//! `map_from_odometry = map_from_robot · odometry_from_robot⁻¹`, published with the stamp of
//! the newest odometry at the odometry rate (tf2 wants a fresh transform) and at once when it
//! changes. Nothing is published before the first correction.

use anyhow::Result;
use runtime::ros2::{Durability, RosOut, RosOutConfig, RosPublisher};
use slam::Pose2;
use std::collections::VecDeque;

/// Nodes remembered for the mapper's corrections (the mapper answers within seconds; a
/// correction of an older node is ignored).
const FRAMES_KEPT: usize = 256;

/// What the correction of one node needs: where odometry had the robot, and the scan's
/// frame in the robot's (the mapper's poses are the scan frames').
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeFrame {
    /// The node's number in its chain.
    pub node_seq: u64,
    /// The robot's planar odometry pose at the node.
    pub odometry: Pose2,
    /// The scan's frame in the robot's planar frame.
    pub scan_origin: Pose2,
}

impl NodeFrame {
    /// The frame of a node.
    pub fn of(node: &wire::Node) -> NodeFrame {
        NodeFrame {
            node_seq: node.node_seq,
            odometry: Pose2::from_isometry3(&node.odometry.pose),
            scan_origin: node.scan_origin,
        }
    }
}

/// The map→odom correction, from the mapper's poses of this robot's nodes (pure).
#[derive(Debug, Default)]
pub struct MapCorrection {
    frames: VecDeque<NodeFrame>,
    map_from_odometry: Option<Pose2>,
    /// The node the latest correction came from.
    corrected_node_seq: Option<u64>,
}

impl MapCorrection {
    /// A node was made.
    pub fn on_node(&mut self, frame: NodeFrame) {
        if self.frames.len() == FRAMES_KEPT {
            self.frames.pop_front();
        }
        self.frames.push_back(frame);
    }

    /// The mapper placed node `node_seq`'s scan frame at `scan_in_map`: the new correction,
    /// if the node is one remembered.
    pub fn on_map_pose(&mut self, node_seq: u64, scan_in_map: Pose2) -> Option<Pose2> {
        let frame = self.frames.iter().rev().find(|f| f.node_seq == node_seq)?;
        let robot_in_map = scan_in_map.compose(&frame.scan_origin.inverse());
        let correction = robot_in_map.compose(&frame.odometry.inverse());
        self.map_from_odometry = Some(correction);
        self.corrected_node_seq = Some(node_seq);
        Some(correction)
    }

    /// Whether the latest correction is of the last node made (none made: yes).
    pub fn is_of_last_node(&self) -> bool {
        self.frames
            .back()
            .is_none_or(|f| self.corrected_node_seq == Some(f.node_seq))
    }

    /// The latest correction.
    pub fn map_from_odometry(&self) -> Option<Pose2> {
        self.map_from_odometry
    }
}

/// The transform `parent → child` of `pose` (planar), stamped.
pub fn tf_message(pose: &Pose2, stamp_ns: u64, parent: &str, child: &str) -> ros2msg::TfMessage {
    let half = 0.5 * pose.theta;
    ros2msg::TfMessage {
        transforms: vec![ros2msg::TransformStamped {
            header: ros2msg::Header {
                stamp: ros2msg::Time::from_ns(stamp_ns),
                frame_id: parent.to_owned(),
            },
            child_frame_id: child.to_owned(),
            transform: ros2msg::Transform {
                translation: ros2msg::Vector3 {
                    x: pose.x,
                    y: pose.y,
                    z: 0.0,
                },
                rotation: ros2msg::Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: half.sin(),
                    w: half.cos(),
                },
            },
        }],
    }
}

/// The `/tf` publisher of `[ros2_out]`.
pub struct TfOut {
    ros: RosOut,
    tf: RosPublisher,
}

/// The topic the transform goes on.
pub const TF_TOPIC: &str = "/tf";

impl TfOut {
    /// Opens the session to the robot's ROS 2 network and the `/tf` publisher.
    pub async fn open(config: &RosOutConfig) -> Result<TfOut> {
        let ros = RosOut::open(config).await?;
        let tf = ros
            .publisher(TF_TOPIC, &ros2msg::types::TF_MESSAGE, Durability::Volatile)
            .await?;
        tracing::info!("ROS 2 out: map→odom on {}", tf.key());
        Ok(TfOut { ros, tf })
    }

    /// Publishes the correction stamped `stamp_ns`; whether it went out.
    pub fn publish(&self, correction: &Pose2, stamp_ns: u64) -> bool {
        let config = self.ros.config();
        let message = tf_message(correction, stamp_ns, &config.map_frame, &config.odom_frame);
        self.tf.put(ros2msg::encode(&message))
    }

    /// Closes the session to the robot's ROS 2 network, after what was published.
    pub async fn close(self) -> Result<()> {
        drop(self.tf);
        self.ros.close().await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_correction_carries_odometry_onto_the_map() {
        let mut c = MapCorrection::default();
        let odometry = Pose2::new(3.0, 1.0, 0.4);
        let scan_origin = Pose2::new(0.5, 0.0, 0.0);
        c.on_node(NodeFrame {
            node_seq: 7,
            odometry,
            scan_origin,
        });
        assert_eq!(c.on_map_pose(6, Pose2::IDENTITY), None);
        let robot_in_map = Pose2::new(10.0, -2.0, 1.2);
        let correction = c
            .on_map_pose(7, robot_in_map.compose(&scan_origin))
            .expect("node 7 is known");
        let carried = correction.compose(&odometry);
        assert!((carried.x - robot_in_map.x).abs() < 1e-12);
        assert!((carried.y - robot_in_map.y).abs() < 1e-12);
        assert!((carried.theta - robot_in_map.theta).abs() < 1e-12);
        assert_eq!(c.map_from_odometry(), Some(correction));
        assert!(c.is_of_last_node());
        c.on_node(NodeFrame {
            node_seq: 8,
            odometry,
            scan_origin,
        });
        assert!(!c.is_of_last_node());
    }

    #[test]
    fn old_frames_are_forgotten() {
        let mut c = MapCorrection::default();
        for node_seq in 0..FRAMES_KEPT as u64 + 10 {
            c.on_node(NodeFrame {
                node_seq,
                odometry: Pose2::IDENTITY,
                scan_origin: Pose2::IDENTITY,
            });
        }
        assert_eq!(c.on_map_pose(0, Pose2::IDENTITY), None);
        assert!(c.on_map_pose(FRAMES_KEPT as u64, Pose2::IDENTITY).is_some());
    }

    #[test]
    fn the_transform_is_the_planar_pose() {
        let m = tf_message(
            &Pose2::new(1.0, 2.0, std::f64::consts::FRAC_PI_2),
            5,
            "map",
            "odom",
        );
        let t = &m.transforms[0];
        assert_eq!(
            (t.header.frame_id.as_str(), t.child_frame_id.as_str()),
            ("map", "odom")
        );
        assert_eq!(t.transform.translation.x, 1.0);
        assert!((t.transform.rotation.z - 0.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(t.header.stamp.nanosec, 5);
    }
}
