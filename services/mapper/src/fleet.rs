//! One fleet's shared map: nodes from the wire into one pose network (pure, no I/O).
//!
//! Each robot's nodes must arrive in node_seq order without gaps; a duplicate (a re-send) or
//! a node after a gap is not taken, and the sender learns the highest node taken from the ack.

use serde::Serialize;
use slam::geodesy::{GeoDatum, Geodetic};
use slam::matching::Scan2;
use slam::nalgebra::{Matrix2, UnitQuaternion, Vector2, Vector3};
use slam::{GpsObservation, Mapper2d, Mapper2dParams, MapperStats, OptimizeReport, Pose2};
use std::collections::HashMap;
use std::sync::Arc;
use wire::v1;

/// Standard deviation (m) of a fix that carries no covariance, by status.
fn default_sigma_m(status: v1::FixStatus) -> Option<f64> {
    match status {
        v1::FixStatus::Unspecified | v1::FixStatus::NoFix => None,
        v1::FixStatus::Fix => Some(3.0),
        v1::FixStatus::Dgps => Some(1.0),
        v1::FixStatus::RtkFloat => Some(0.3),
        v1::FixStatus::RtkFixed => Some(0.03),
    }
}

/// Where a node stands against its robot's sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sequence {
    /// The next node of the robot (or its first).
    Next,
    /// Taken already (a re-send): re-ack.
    Duplicate,
    /// Nodes are missing before it: not taken until they come.
    Gap { expected: u64 },
}

/// A node of the map with what it came with.
#[derive(Clone, Debug)]
pub struct NodeRecord {
    pub robot: usize,
    pub node_seq: u64,
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
    pub counts: Option<v1::SegmentationCounts>,
    /// The leveled scan: bearings (rad) and ranges (m, 0 = no return).
    pub bearings_rad: Vec<f32>,
    pub ranges_m: Vec<f32>,
}

/// A robot of the fleet.
#[derive(Clone, Debug, Serialize)]
pub struct RobotRecord {
    pub id: String,
    /// Highest node_seq taken.
    pub last_node_seq: u64,
    /// Map nodes of this robot, in order.
    pub nodes: Vec<usize>,
}

/// Where a node went in the map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ingested {
    pub node: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    #[error("node {node_seq} of {robot}: {problem}")]
    Sequence {
        robot: String,
        node_seq: u64,
        problem: String,
    },
    #[error("node of {robot}: {source}")]
    Wire {
        robot: String,
        source: wire::WireError,
    },
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

    pub fn id(&self) -> &str {
        &self.id
    }

    pub fn datum(&self) -> Option<&GeoDatum> {
        self.datum.as_ref()
    }

    pub fn robots(&self) -> &[RobotRecord] {
        &self.robots
    }

    pub fn robot_index(&self, id: &str) -> Option<usize> {
        self.by_id.get(id).copied()
    }

    pub fn nodes(&self) -> &[Arc<NodeRecord>] {
        &self.nodes
    }

    pub fn poses(&self) -> &[Pose2] {
        &self.mapper.graph().poses
    }

    pub fn graph(&self) -> &slam::PoseGraph {
        self.mapper.graph()
    }

    pub fn stats(&self) -> MapperStats {
        self.mapper.stats()
    }

    pub fn last_optimization(&self) -> Option<&OptimizeReport> {
        self.mapper.last_optimization()
    }

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

    /// Adds a node that [`wire::decode_node`] accepted, of this fleet.
    pub fn ingest(&mut self, node: &v1::Node) -> Result<Ingested, IngestError> {
        let header = node.header.as_ref().expect("a validated node has a header");
        let robot_id = header.robot_id.clone();
        let wire_err = |source| IngestError::Wire {
            robot: robot_id.clone(),
            source,
        };
        match self.sequence(&robot_id, node.node_seq) {
            Sequence::Next => {}
            Sequence::Duplicate => {
                return Err(IngestError::Sequence {
                    robot: robot_id.clone(),
                    node_seq: node.node_seq,
                    problem: "taken already".into(),
                });
            }
            Sequence::Gap { expected } => {
                return Err(IngestError::Sequence {
                    robot: robot_id.clone(),
                    node_seq: node.node_seq,
                    problem: format!("out of order, expected {expected}"),
                });
            }
        }
        let scan_msg = node.scan.as_ref().expect("validated");
        let leveled = wire::leveled_scan_from_wire(scan_msg).map_err(wire_err)?;
        let odometry = wire::odometry_from_wire(node.odometry.as_ref().expect("validated"))
            .map_err(wire_err)?;
        let robot_odometry = Pose2::from_isometry3(&odometry.pose);
        let scan_origin = node
            .scan_origin_in_robot
            .as_ref()
            .map_or(Pose2::IDENTITY, |p| Pose2::new(p.x_m, p.y_m, p.yaw_rad));
        let scan_frame = robot_odometry.compose(&scan_origin);
        let (bearings, ranges): (Vec<f32>, Vec<f32>) = leveled.returns().unzip();
        let scan =
            Scan2::from_polar(&bearings, &ranges, self.max_range_m).expect("returns come in pairs");
        let gps: Vec<GpsObservation> = node
            .earlier_gps
            .iter()
            .chain(&node.gps)
            .filter_map(|fix| {
                self.gps_observation(
                    fix,
                    &odometry.pose.rotation,
                    robot_odometry.theta,
                    &scan_origin,
                )
            })
            .collect();

        let robot = match self.by_id.get(&robot_id) {
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
            stamp_ns: header.stamp_ns,
            odometry: scan_frame,
            robot_odometry,
            scan_origin,
            gps,
            counts: scan_msg.counts,
            bearings_rad: scan_msg.bearing_rad.clone(),
            ranges_m: scan_msg.range_m.clone(),
        }));
        Ok(Ingested { node: index })
    }

    /// A fix as a GPS observation of the node's scan frame; `None` for a fix without
    /// position (no fix, no covariance nor a status that implies one). The antenna offset is
    /// in the (tilted) robot frame: the robot's roll and pitch turn it into the horizontal
    /// lever arm (on a 10° slope a 1 m mast leans 0.17 m).
    fn gps_observation(
        &mut self,
        fix: &v1::GpsFix,
        attitude: &UnitQuaternion<f64>,
        heading_rad: f64,
        scan_origin: &Pose2,
    ) -> Option<GpsObservation> {
        let status = v1::FixStatus::try_from(fix.status).unwrap_or(v1::FixStatus::Unspecified);
        let covariance = if fix.position_covariance_m2.len() == 9 {
            let c = &fix.position_covariance_m2;
            Matrix2::new(c[0], c[1], c[3], c[4])
        } else {
            let s = default_sigma_m(status)?;
            Matrix2::identity() * (s * s)
        };
        if matches!(status, v1::FixStatus::NoFix) {
            return None;
        }
        let geodetic = Geodetic {
            latitude_deg: fix.latitude_deg,
            longitude_deg: fix.longitude_deg,
            height_m: fix.altitude_m,
        };
        let datum = *self.datum.get_or_insert(GeoDatum { origin: geodetic });
        let enu = datum.geodetic_to_enu(&geodetic);
        let offset = fix
            .antenna_offset_m
            .as_ref()
            .map_or(Vector3::zeros(), |v| Vector3::new(v.x, v.y, v.z));
        let heading = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading_rad);
        let leveled = heading.inverse() * (attitude * offset);
        let lever = scan_origin
            .inverse()
            .transform_point([leveled.x, leveled.y]);
        Some(GpsObservation {
            position_m: Vector2::new(enu.x, enu.y),
            covariance_m2: covariance,
            lever_arm_m: Vector2::new(lever[0], lever[1]),
        })
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
