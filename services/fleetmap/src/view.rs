//! A fleet's map at one moment, for readers: the robots, the nodes, the poses and the
//! network, shared with the view before it (`SharedLog`) so that a new view after every
//! accepted node copies what changed.

use crate::fleet::{FleetMap, NodeRecord};
use crate::shared_log::SharedLog;
use serde::Serialize;
use slam::geodesy::GeoDatum;
use slam::{GpsEdge, MapperStats, OptimizeReport, Pose2, RelativeEdge};
use std::sync::Arc;

/// A robot as the map knows it.
#[derive(Clone, Debug, Serialize)]
pub struct RobotView {
    /// The robot's id.
    pub id: String,
    /// Its nodes in the map.
    pub nodes: usize,
    /// Highest node_seq taken of its newest chain.
    pub last_node_seq: u64,
    /// Its chains (one per outbox it sent from), oldest first.
    pub chains: Vec<ChainView>,
    /// The robot frame's map pose at its last node, and its odometry pose there: live odometry
    /// since then, composed onto the first, gives the live map pose.
    pub map_pose_at_last_node: Pose2,
    /// The robot's planar odometry pose at its last node.
    pub odometry_at_last_node: Pose2,
}

/// One chain of a robot's nodes (what one outbox sent), as readers see it.
#[derive(Clone, Debug, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ChainView {
    /// `Node.chain_id` (0: a robot from before chains).
    pub chain_id: u64,
    /// The first node_seq mapped of it.
    pub first_node_seq: u64,
    /// The highest node_seq mapped of it.
    pub last_node_seq: u64,
    /// The highest node_seq taken of it, mapped or located over covered ground (a pass):
    /// what the mapper acks. The chain's nodes are taken in sequence only, so every node
    /// from its first to this one is in.
    pub acked_node_seq: u64,
}

impl RobotView {
    /// The map pose of the robot at odometry pose `odometry`.
    pub fn live_pose(&self, odometry: &Pose2) -> Pose2 {
        self.map_from_odometry().compose(odometry)
    }

    /// The map pose of the robot's odometry frame (ROS's map→odom).
    pub fn map_from_odometry(&self) -> Pose2 {
        self.map_pose_at_last_node
            .compose(&self.odometry_at_last_node.inverse())
    }
}

/// One fleet's map at one moment.
#[derive(Debug)]
pub struct FleetView {
    /// The fleet's id.
    pub id: String,
    /// The GPS datum (origin of the east-north map frame), once known.
    pub datum: Option<GeoDatum>,
    /// The robots, as in [`FleetMap::robots`].
    pub robots: Vec<RobotView>,
    /// Every node with what it came with, in map order.
    pub nodes: SharedLog<Arc<NodeRecord>>,
    /// The nodes' poses in the map frame.
    pub poses: SharedLog<Pose2>,
    /// The network's relative edges.
    pub edges: SharedLog<RelativeEdge>,
    /// The network's GPS edges.
    pub gps: SharedLog<GpsEdge>,
    /// What the mapping did so far.
    pub stats: MapperStats,
    /// The last solve's report.
    pub last_optimization: Option<OptimizeReport>,
    /// Time the last batch of nodes took to map (ms).
    pub last_ingest_ms: f64,
    /// When the view was made (ns since the Unix epoch).
    pub updated_ns: u64,
}

impl FleetView {
    /// A copy of `map` now, for readers, sharing the edges of the fleet's `previous` view.
    pub fn of(
        map: &FleetMap,
        previous: Option<&FleetView>,
        last_ingest_ms: f64,
        updated_ns: u64,
    ) -> FleetView {
        let poses = map.poses();
        let robots = map
            .robots()
            .iter()
            .map(|r| {
                let last = *r.nodes.last().expect("a robot has a node");
                let record = &map.nodes()[last];
                RobotView {
                    id: r.id.clone(),
                    nodes: r.nodes.len(),
                    last_node_seq: r.last_node_seq,
                    chains: (r.chains.iter().zip(map.chains_acked(r)))
                        .map(|(c, acked_node_seq)| ChainView {
                            chain_id: c.chain_id,
                            first_node_seq: c.first_node_seq,
                            last_node_seq: c.last_node_seq,
                            acked_node_seq,
                        })
                        .collect(),
                    map_pose_at_last_node: poses[last].compose(&record.scan_origin.inverse()),
                    odometry_at_last_node: record.robot_odometry,
                }
            })
            .collect();
        FleetView {
            id: map.id().to_owned(),
            datum: map.datum().copied(),
            robots,
            nodes: SharedLog::extend(
                previous.map_or(&SharedLog::default(), |v| &v.nodes),
                map.nodes(),
            ),
            poses: SharedLog::refresh(previous.map_or(&SharedLog::default(), |v| &v.poses), poses),
            edges: SharedLog::extend(
                previous.map_or(&SharedLog::default(), |v| &v.edges),
                &map.graph().edges,
            ),
            gps: SharedLog::extend(
                previous.map_or(&SharedLog::default(), |v| &v.gps),
                &map.graph().gps,
            ),
            stats: map.stats(),
            last_optimization: map.last_optimization().copied(),
            last_ingest_ms,
            updated_ns,
        }
    }

    /// A robot of the fleet by id.
    pub fn robot(&self, id: &str) -> Option<&RobotView> {
        self.robots.iter().find(|r| r.id == id)
    }

    /// The occupancy grid of the fleet's leveled scans at their optimized poses.
    pub fn grid(&self, params: &slam::GridParams) -> Result<slam::OccupancyGrid, slam::GridError> {
        slam::OccupancyGrid::from_fans_made_again(
            || {
                self.poses
                    .iter()
                    .copied()
                    .zip(self.nodes.iter().map(|n| n.fan()))
            },
            params,
        )
    }
}
