//! One fleet's shared map: nodes from the wire into one pose network (pure, no I/O).
//!
//! Each robot's nodes must arrive in node_seq order without gaps; a duplicate (a re-send) or
//! a node after a gap is not taken, and the sender learns the highest node taken from the ack.

use leveling::ClassCounts;
use serde::Serialize;
use slam::geodesy::GeoDatum;
use slam::matching::Scan2;
use slam::{GpsObservation, Mapper2d, Mapper2dParams, MapperStats, OptimizeReport, Pose2};
use std::collections::HashMap;
use std::sync::Arc;
use wire::NodeInput;

/// Where a node stands against its robot's sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sequence {
    /// The next node of the robot (or its first).
    Next,
    /// Taken already (a re-send): re-ack.
    Duplicate,
    /// Nodes are missing before it: not taken until they come.
    Gap {
        /// The node the robot must send next.
        expected: u64,
    },
}

/// A node of the map with what it came with.
#[derive(Clone, Debug)]
pub struct NodeRecord {
    /// Index of its robot in [`FleetMap::robots`].
    pub robot: usize,
    /// Its number in its robot's sequence.
    pub node_seq: u64,
    /// The scan's start (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// The scan frame's pose in the robot's odometry frame.
    pub odometry: Pose2,
    /// The robot's planar odometry pose at the scan's start.
    pub robot_odometry: Pose2,
    /// The scan's frame in the robot's planar frame.
    pub scan_origin: Pose2,
    /// Its GPS fixes as the mapper took them (`Node.earlier_gps` then `Node.gps`: oldest
    /// first), each an edge of the network.
    pub gps: Vec<GpsObservation>,
    /// The scan's points per class, when the robot sent them.
    pub counts: Option<ClassCounts>,
    /// The leveled scan: bearings (rad) and ranges (m, 0 = no return).
    pub bearings_rad: Vec<f32>,
    /// Range per bearing (m, 0 = no return).
    pub ranges_m: Vec<f32>,
}

impl NodeRecord {
    /// Every return of the leveled scan, however far (the map shows what the robot saw;
    /// matching cuts at the mapper's `max_range_m`).
    pub fn scan(&self) -> Scan2 {
        let (bearings, ranges): (Vec<f32>, Vec<f32>) = self
            .bearings_rad
            .iter()
            .zip(&self.ranges_m)
            .filter(|(_, r)| **r > 0.0)
            .map(|(b, r)| (*b, *r))
            .unzip();
        Scan2::from_polar(&bearings, &ranges, f32::MAX).expect("returns come in pairs")
    }
}

/// A robot of the fleet.
#[derive(Clone, Debug, Serialize)]
pub struct RobotRecord {
    /// The robot's id.
    pub id: String,
    /// Highest node_seq taken.
    pub last_node_seq: u64,
    /// Map nodes of this robot, in order.
    pub nodes: Vec<usize>,
}

/// Where a node went in the map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ingested {
    /// The node's index in the map.
    pub node: usize,
}

/// Why a node was not added.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// Not the robot's next node.
    #[error("node {node_seq} of {robot}: {problem}")]
    Sequence {
        /// The robot.
        robot: String,
        /// The node's number.
        node_seq: u64,
        /// What is wrong with its number.
        problem: String,
    },
    /// The network refused it.
    #[error("the pose network: {0}")]
    Graph(#[from] slam::GraphError),
}

/// One fleet's map.
#[derive(Debug)]
pub struct FleetMap {
    id: String,
    mapper: Mapper2d,
    datum: Option<GeoDatum>,
    max_range_m: f32,
    robots: Vec<RobotRecord>,
    by_id: HashMap<String, usize>,
    nodes: Vec<Arc<NodeRecord>>,
}

impl FleetMap {
    /// A map whose GPS frame is east-north around `datum`; without one, the first fix sets it.
    pub fn new(
        id: &str,
        params: Mapper2dParams,
        datum: Option<GeoDatum>,
        max_range_m: f32,
    ) -> FleetMap {
        // Robots decide where nodes are: every node sent becomes a network node. The owner
        // decides when to solve (`optimize_pending`).
        let params = Mapper2dParams {
            node_distance_m: 0.0,
            node_rotation_rad: 0.0,
            defer_optimization: true,
            ..params
        };
        FleetMap {
            id: id.to_owned(),
            mapper: Mapper2d::new(params),
            datum,
            max_range_m,
            robots: Vec::new(),
            by_id: HashMap::new(),
            nodes: Vec::new(),
        }
    }

    /// The fleet's id.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// The GPS datum, once configured or set by the first fix.
    pub fn datum(&self) -> Option<&GeoDatum> {
        self.datum.as_ref()
    }

    /// The robots, in the order they first sent a node.
    pub fn robots(&self) -> &[RobotRecord] {
        &self.robots
    }

    /// A robot's index in [`Self::robots`].
    pub fn robot_index(&self, id: &str) -> Option<usize> {
        self.by_id.get(id).copied()
    }

    /// Every node with what it came with, in map order.
    pub fn nodes(&self) -> &[Arc<NodeRecord>] {
        &self.nodes
    }

    /// The nodes' poses (scan frames in the map frame), as last solved or placed.
    pub fn poses(&self) -> &[Pose2] {
        &self.mapper.graph().poses
    }

    /// The pose network.
    pub fn graph(&self) -> &slam::PoseGraph {
        self.mapper.graph()
    }

    /// What the mapping did so far.
    pub fn stats(&self) -> MapperStats {
        self.mapper.stats()
    }

    /// The last solve's report.
    pub fn last_optimization(&self) -> Option<&OptimizeReport> {
        self.mapper.last_optimization()
    }

    /// A node's scan as matching uses it (cut at `max_range_m`).
    pub fn node_scan(&self, node: usize) -> &Scan2 {
        self.mapper.node_scan(node)
    }

    /// Where node `node_seq` of `robot` stands against what the map took.
    pub fn sequence(&self, robot: &str, node_seq: u64) -> Sequence {
        match self.by_id.get(robot).map(|&r| self.robots[r].last_node_seq) {
            None => Sequence::Next,
            Some(last) if node_seq <= last => Sequence::Duplicate,
            Some(last) if node_seq == last + 1 => Sequence::Next,
            Some(last) => Sequence::Gap { expected: last + 1 },
        }
    }

    /// Adds a node of this fleet.
    pub fn ingest(&mut self, node: &NodeInput) -> Result<Ingested, IngestError> {
        let robot_id = &node.robot;
        let problem = match self.sequence(robot_id, node.node_seq) {
            Sequence::Next => None,
            Sequence::Duplicate => Some("taken already".to_owned()),
            Sequence::Gap { expected } => Some(format!("out of order, expected {expected}")),
        };
        if let Some(problem) = problem {
            return Err(IngestError::Sequence {
                robot: robot_id.clone(),
                node_seq: node.node_seq,
                problem,
            });
        }
        let robot_odometry = Pose2::from_isometry3(&node.odometry.pose);
        let scan_frame = robot_odometry.compose(&node.scan_origin);
        let (bearings_rad, ranges_m) = node.polar();
        let (bearings, ranges): (Vec<f32>, Vec<f32>) = node.scan.returns().unzip();
        let scan =
            Scan2::from_polar(&bearings, &ranges, self.max_range_m).expect("returns come in pairs");
        let attitude = node.odometry.pose.rotation;
        let gps: Vec<GpsObservation> = node
            .gps
            .iter()
            .filter(|fix| fix.has_position())
            .filter_map(|fix| {
                // The first fix sets the datum when none is configured.
                let datum = *self.datum.get_or_insert(GeoDatum {
                    origin: fix.position,
                });
                fix.observation(&datum, &attitude, robot_odometry.theta, &node.scan_origin)
            })
            .collect();

        let robot = match self.by_id.get(robot_id) {
            Some(&r) => r,
            None => {
                self.robots.push(RobotRecord {
                    id: robot_id.clone(),
                    last_node_seq: node.node_seq,
                    nodes: Vec::new(),
                });
                self.by_id.insert(robot_id.clone(), self.robots.len() - 1);
                self.robots.len() - 1
            }
        };
        let placed = self.mapper.add_robot_scan(robot, scan_frame, scan, &gps)?;
        let slam::Placed::Node(index) = placed else {
            unreachable!("node distance 0: every scan is a node")
        };
        let record = &mut self.robots[robot];
        record.last_node_seq = node.node_seq;
        record.nodes.push(index);
        self.nodes.push(Arc::new(NodeRecord {
            robot,
            node_seq: node.node_seq,
            stamp_ns: node.stamp_ns,
            odometry: scan_frame,
            robot_odometry,
            scan_origin: node.scan_origin,
            gps,
            counts: node.counts,
            bearings_rad,
            ranges_m,
        }));
        Ok(Ingested { node: index })
    }

    /// Solves the network if the nodes added since the last solve call for it (a loop
    /// closure, a GPS fix); returns whether it ran.
    pub fn optimize_pending(&mut self) -> Result<bool, IngestError> {
        Ok(self.mapper.optimize_pending()?)
    }

    /// Solves the network now, pending or not (an operator's request, a final export);
    /// returns whether it ran (not while a part of the network is unanchored).
    pub fn optimize_now(&mut self) -> Result<bool, IngestError> {
        Ok(self.mapper.optimize_now()?)
    }
}
