//! From 3D scans with odometry and GPS to the nodes a robot sends (pure, no I/O): a node
//! every few metres or degrees, its scan leveled (paper 2.1–3.2), every GPS fix since the
//! previous node carried to the scan's start, and, when kept, the segmented 3D cloud reduced
//! ([`crate::cloud`]).

use crate::cloud::{self, CloudParams};
use leveling::nalgebra::{Isometry3, Matrix3, Vector3};
use leveling::{DeskewError, Leveler, PoseTrack, Scan3d, SegmentParams, leveled_frame};
use serde::{Deserialize, Serialize};
use slam::Pose2;
use slam::geodesy::Geodetic;
use slam::gnss::{FixStatus, GpsFix, carry_antenna_to_node};
use wire::{LiveScan, Node, NodeParts};

/// When the robot starts a new node.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NodeParams {
    /// A new node after this much travel since the last one (m)…
    pub node_distance_m: f64,
    /// …or this much rotation (deg).
    pub node_rotation_deg: f64,
    /// A node carries every GPS fix since the previous node (a 1 Hz receiver and a node every
    /// 4 s: four), up to this many, the latest kept: a robot standing still makes no node,
    /// and its fixes meanwhile, from one spot, are not independent.
    pub max_gps_fixes: usize,
}

impl Default for NodeParams {
    fn default() -> Self {
        NodeParams {
            node_distance_m: 1.0,
            node_rotation_deg: 20.0,
            max_gps_fixes: 10,
        }
    }
}

/// One GPS fix as the source reads it, with dead reckoning at the fix's time.
#[derive(Clone, Debug, PartialEq)]
pub struct GpsReading {
    /// When the receiver measured it (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// WGS84 latitude (deg, north positive).
    pub latitude_deg: f64,
    /// WGS84 longitude (deg, east positive).
    pub longitude_deg: f64,
    /// Height above the WGS84 ellipsoid (m).
    pub altitude_m: f64,
    /// The receiver's standard deviations, horizontal and vertical (m).
    pub sigma_horizontal_m: f64,
    /// The vertical one (m).
    pub sigma_vertical_m: f64,
    /// The receiver's kind of solution.
    pub status: FixStatus,
    /// The antenna in the robot frame (m).
    pub antenna_in_robot_m: Vector3<f64>,
    /// The dead-reckoning pose at `stamp_ns` (odometry frame).
    pub odometry_at_fix: Isometry3<f64>,
}

/// One 3D scan from a source, ready for leveling. Times are ns since the Unix epoch.
#[derive(Clone, Debug)]
pub struct SensorScan {
    /// The scan in the sensor frame, columns stamped.
    pub raw: Scan3d,
    /// Dead reckoning covering the scan's columns (odometry frame).
    pub track: PoseTrack,
    /// The sensor's mount on the robot.
    pub sensor_in_robot: Isometry3<f64>,
    /// The GPS fixes since the previous scan, at or before this scan's start, oldest first
    /// (none when the receiver had none).
    pub gps: Vec<GpsReading>,
}

/// A scan of a fixed (not leveled) 2D scanner.
#[derive(Clone, Debug)]
pub struct PlanarScan {
    /// The scan's time (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// Bearing of each beam (rad, counter-clockwise from x).
    pub bearings_rad: Vec<f32>,
    /// Range per bearing (m); 0 = no return.
    pub ranges_m: Vec<f32>,
    /// Dead reckoning at the scan (odometry frame).
    pub robot_at_start: Isometry3<f64>,
    /// The scanner's mount on the robot.
    pub sensor_in_robot: Isometry3<f64>,
    /// As [`SensorScan::gps`].
    pub gps: Vec<GpsReading>,
}

/// Why a scan gave no node.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The node fails the wire's checks (the mapper's own, [`wire::Node::new`]): it is not
    /// numbered, and goes to quarantine instead of blocking the nodes after it.
    #[error("the node fails the wire's checks ({}): {error}", error.reason())]
    Invalid {
        /// The node as built.
        node: Box<NodeParts>,
        /// What the check found.
        error: wire::WireError,
    },
    /// The scan has no columns.
    #[error("scan has no columns")]
    Empty,
    /// Dead reckoning does not reach the scan's start.
    #[error("dead reckoning does not cover the scan's start ({stamp_ns} ns)")]
    NoOdometry {
        /// The scan's start (ns since the Unix epoch).
        stamp_ns: u64,
    },
    /// Motion compensation failed.
    #[error("motion compensation: {0:?}")]
    Deskew(DeskewError),
}

/// Turns scans into nodes, numbering them from `first_node_seq` without gaps.
#[derive(Debug)]
pub struct NodeBuilder {
    fleet: String,
    robot: String,
    params: NodeParams,
    leveler: Leveler,
    next_node_seq: u64,
    /// `Node.chain_id` of every node.
    chain_id: u64,
    /// The robot's planar odometry pose at the last node.
    last: Option<Pose2>,
    /// GPS fixes since the last node, oldest first, for the next one.
    pending_gps: Vec<GpsReading>,
    /// The stamp of the latest fix taken (a fix a source repeats is taken once).
    last_gps_ns: Option<u64>,
    /// How the segmented cloud is reduced, when nodes carry it.
    cloud: Option<CloudParams>,
}

impl NodeBuilder {
    /// A builder for `robot` of `fleet`, its first node numbered `first_node_seq`.
    pub fn new(
        fleet: &str,
        robot: &str,
        params: NodeParams,
        segment: SegmentParams,
        first_node_seq: u64,
    ) -> NodeBuilder {
        NodeBuilder {
            fleet: fleet.to_owned(),
            robot: robot.to_owned(),
            params,
            leveler: Leveler::new(segment),
            next_node_seq: first_node_seq,
            chain_id: 0,
            last: None,
            pending_gps: Vec::new(),
            last_gps_ns: None,
            cloud: None,
        }
    }

    /// Nodes belong to chain `chain_id` (the outbox's; without this call, 0).
    pub fn in_chain(mut self, chain_id: u64) -> NodeBuilder {
        self.chain_id = chain_id;
        self
    }

    /// Nodes of leveled scans carry their segmented cloud, reduced by `params`, when
    /// `params.keep` (without this call, none do).
    pub fn with_cloud(mut self, params: &CloudParams) -> NodeBuilder {
        self.cloud = params.keep.then(|| params.clone());
        self
    }

    /// The node of `scan` when the robot moved far enough since the last node (or there is
    /// none yet); `None` otherwise, without leveling the scan. The scan's GPS fixes go with
    /// the next node either way.
    pub fn offer(&mut self, scan: &SensorScan) -> Result<Option<Node>, NodeError> {
        self.take_gps(&scan.gps);
        let start_ns = scan.raw.columns.first().ok_or(NodeError::Empty)?.stamp_ns;
        let robot_at_start = scan
            .track
            .at(start_ns)
            .ok_or(NodeError::NoOdometry { stamp_ns: start_ns })?;
        if !self.moved_enough(&robot_at_start) {
            return Ok(None);
        }
        let leveled = self
            .leveler
            .level(&scan.raw, &scan.track, &scan.sensor_in_robot)
            .map_err(NodeError::Deskew)?;
        let scan_frame =
            Pose2::from_isometry3(&leveled_frame(&robot_at_start, &scan.sensor_in_robot).inverse());
        let cloud = self
            .cloud
            .as_ref()
            .map(|params| cloud::reduce(&leveled.cloud, &leveled.classes, params));
        let mut node = self.assemble(&robot_at_start, scan_frame, leveled.scan);
        node.counts = Some(leveled.counts);
        node.cloud = cloud;
        self.number(node).map(Some)
    }

    /// The live leveled scan of `scan` (for live views, not a node): leveled as a node's
    /// would be, with the robot's odometry at its start.
    pub fn live_scan(&mut self, scan: &SensorScan) -> Result<LiveScan, NodeError> {
        let start_ns = scan.raw.columns.first().ok_or(NodeError::Empty)?.stamp_ns;
        let robot_at_start = scan
            .track
            .at(start_ns)
            .ok_or(NodeError::NoOdometry { stamp_ns: start_ns })?;
        let leveled = self
            .leveler
            .level(&scan.raw, &scan.track, &scan.sensor_in_robot)
            .map_err(NodeError::Deskew)?;
        let scan_frame =
            Pose2::from_isometry3(&leveled_frame(&robot_at_start, &scan.sensor_in_robot).inverse());
        let robot2 = Pose2::from_isometry3(&robot_at_start);
        Ok(LiveScan {
            fleet: self.fleet.clone(),
            robot: self.robot.clone(),
            stamp_ns: start_ns,
            scan: leveled.scan,
            counts: Some(leveled.counts),
            odometry: leveling::TimedPose {
                stamp_ns: start_ns,
                pose: robot_at_start,
            },
            scan_origin: robot2.between(&scan_frame),
        })
    }

    /// The node of a scan from a fixed 2D scanner (no leveling: its frame tilts with the
    /// robot), by the same rule as [`Self::offer`]. For comparisons with the paper's baseline.
    pub fn offer_planar(&mut self, scan: &PlanarScan) -> Result<Option<Node>, NodeError> {
        self.take_gps(&scan.gps);
        if !self.moved_enough(&scan.robot_at_start) {
            return Ok(None);
        }
        let scan_frame = Pose2::from_isometry3(&(scan.robot_at_start * scan.sensor_in_robot));
        let planar = leveling::LeveledScan {
            stamp_ns: scan.stamp_ns,
            beams: scan
                .bearings_rad
                .iter()
                .zip(&scan.ranges_m)
                .map(|(&bearing_rad, &r)| leveling::Beam {
                    bearing_rad,
                    range_m: (r != 0.0).then_some(r),
                    sensor_xy_m: [0.0, 0.0],
                    ground_to_m: None,
                })
                .collect(),
        };
        let node = self.assemble(&scan.robot_at_start, scan_frame, planar);
        self.number(node).map(Some)
    }

    /// Gives a node its number once it passes the mapper's checks; a node that fails them
    /// takes none, so the chain has no gap.
    fn number(&mut self, parts: NodeParts) -> Result<Node, NodeError> {
        let node = Node::new(parts.clone()).map_err(|error| NodeError::Invalid {
            node: Box::new(parts),
            error,
        })?;
        self.next_node_seq += 1;
        Ok(node)
    }

    /// Keeps the fixes newer than the last one taken for the next node.
    fn take_gps(&mut self, readings: &[GpsReading]) {
        for g in readings {
            if self.last_gps_ns.is_none_or(|t| g.stamp_ns > t) {
                self.last_gps_ns = Some(g.stamp_ns);
                self.pending_gps.push(g.clone());
            }
        }
    }

    fn moved_enough(&self, robot_at_start: &Isometry3<f64>) -> bool {
        let Some(last) = self.last else {
            return true;
        };
        let d = last.between(&Pose2::from_isometry3(robot_at_start));
        d.x.hypot(d.y) >= self.params.node_distance_m
            || d.theta.abs() >= self.params.node_rotation_deg.to_radians()
    }

    /// The node of `scan` (counts and cloud unset), its fixes taken.
    fn assemble(
        &mut self,
        robot_at_start: &Isometry3<f64>,
        scan_frame: Pose2,
        scan: leveling::LeveledScan,
    ) -> NodeParts {
        let start_ns = scan.stamp_ns;
        let robot2 = Pose2::from_isometry3(robot_at_start);
        // Fixes after the scan's start wait for the next node; of the others the latest
        // max_gps_fixes go, the last one as Node.gps.
        let later = self.pending_gps.partition_point(|g| g.stamp_ns <= start_ns);
        let rest = self.pending_gps.split_off(later);
        let taken = std::mem::replace(&mut self.pending_gps, rest);
        let skipped = taken.len().saturating_sub(self.params.max_gps_fixes);
        let gps = taken[skipped..]
            .iter()
            .map(|g| carried_fix(g, robot_at_start))
            .collect();
        let node = NodeParts {
            fleet: self.fleet.clone(),
            robot: self.robot.clone(),
            node_seq: self.next_node_seq,
            chain_id: self.chain_id,
            // Set at each send, from the outbox.
            held_from_seq: 0,
            stamp_ns: start_ns,
            scan,
            counts: None,
            odometry: leveling::TimedPose {
                stamp_ns: start_ns,
                pose: *robot_at_start,
            },
            odometry_delta: self.last.map(|last| last.between(&robot2)),
            scan_origin: robot2.between(&scan_frame),
            gps,
            cloud: None,
        };
        self.last = Some(robot2);
        node
    }
}

/// The fix, carried to the scan's start by dead reckoning
/// ([`slam::gnss::carry_antenna_to_node`]; see `Node.gps` in node.proto).
fn carried_fix(g: &GpsReading, robot_at_start: &Isometry3<f64>) -> GpsFix {
    let (h, v) = (g.sigma_horizontal_m.powi(2), g.sigma_vertical_m.powi(2));
    GpsFix {
        stamp_ns: g.stamp_ns,
        position: Geodetic {
            latitude_deg: g.latitude_deg,
            longitude_deg: g.longitude_deg,
            height_m: g.altitude_m,
        },
        covariance_m2: Some(Matrix3::from_diagonal(&Vector3::new(h, h, v))),
        status: g.status,
        antenna_offset_m: carry_antenna_to_node(
            &g.antenna_in_robot_m,
            &g.odometry_at_fix,
            robot_at_start,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use leveling::nalgebra::Translation3;

    const S: u64 = 1_000_000_000;

    /// A robot driving east at 1 m/s from x = 0 at time 0, the antenna 0.5 m behind it.
    fn robot_at(t_ns: u64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(t_ns as f64 / S as f64, 0.0, 0.0),
            Default::default(),
        )
    }

    fn fix(t_ns: u64) -> GpsReading {
        GpsReading {
            stamp_ns: t_ns,
            latitude_deg: 52.0,
            longitude_deg: 9.0,
            altitude_m: 60.0,
            sigma_horizontal_m: 0.5,
            sigma_vertical_m: 1.0,
            status: FixStatus::Fix,
            antenna_in_robot_m: Vector3::new(-0.5, 0.0, 1.0),
            odometry_at_fix: robot_at(t_ns),
        }
    }

    fn scan(t_ns: u64, gps: Vec<GpsReading>) -> PlanarScan {
        PlanarScan {
            stamp_ns: t_ns,
            bearings_rad: vec![0.0, 0.1],
            ranges_m: vec![5.0, 0.0],
            robot_at_start: robot_at(t_ns),
            sensor_in_robot: Isometry3::identity(),
            gps,
        }
    }

    fn stamps(node: &Node) -> Vec<u64> {
        node.gps.iter().map(|g| g.stamp_ns / S).collect()
    }

    #[test]
    fn a_node_the_mapper_would_refuse_takes_no_number() {
        let mut builder =
            NodeBuilder::new("park", "r0", NodeParams::default(), Default::default(), 4)
                .in_chain(9);
        let mut absurd = scan(0, Vec::new());
        absurd.ranges_m[0] = 2000.0;
        let Err(NodeError::Invalid { node, error }) = builder.offer_planar(&absurd) else {
            panic!("a 2 km range is not plausible");
        };
        assert_eq!((node.node_seq, error.reason()), (4, "implausible_range"));
        let next = builder.offer_planar(&scan(S, Vec::new())).unwrap().unwrap();
        assert_eq!(
            (next.node_seq, next.chain_id),
            (4, 9),
            "no gap in the chain"
        );
    }

    #[test]
    fn a_node_carries_every_fix_since_the_previous_node() {
        let params = NodeParams {
            node_distance_m: 3.0,
            max_gps_fixes: 5,
            ..NodeParams::default()
        };
        let mut builder = NodeBuilder::new("park", "r0", params, SegmentParams::default(), 0);
        let first = builder
            .offer_planar(&scan(0, vec![fix(0)]))
            .unwrap()
            .unwrap();
        assert_eq!(stamps(&first), [0]);
        // 2 m: no node, its fixes wait; the fix at 2 s comes again and is taken once.
        let waiting = scan(2 * S, vec![fix(S), fix(2 * S)]);
        assert!(builder.offer_planar(&waiting).unwrap().is_none());
        let node = builder
            .offer_planar(&scan(4 * S, vec![fix(2 * S), fix(3 * S), fix(4 * S)]))
            .unwrap()
            .unwrap();
        assert_eq!(stamps(&node), [1, 2, 3, 4]);
        // Each carried to the node: where the antenna was at the fix's time, in the robot
        // frame at the scan's start (4 s, x = 4 m).
        let offset = |g: &GpsFix| g.antenna_offset_m.x;
        assert!((offset(&node.gps[0]) - (1.0 - 0.5 - 4.0)).abs() < 1e-12);
        assert!((offset(node.gps.last().unwrap()) + 0.5).abs() < 1e-12);
        // At most max_gps_fixes, the latest; none: no fix on the node.
        let many = (5..12).map(|t| fix(t * S)).collect();
        let node = builder.offer_planar(&scan(11 * S, many)).unwrap().unwrap();
        assert_eq!(stamps(&node), [7, 8, 9, 10, 11]);
        let node = builder
            .offer_planar(&scan(15 * S, Vec::new()))
            .unwrap()
            .unwrap();
        assert!(node.gps.is_empty());
    }

    #[test]
    #[cfg(feature = "sim")]
    fn nodes_of_the_simulated_robot_carry_their_cloud_when_kept() {
        use crate::{SimSource, SimSourceConfig, Source, SourceEvent};
        let mut source = SimSource::new(&SimSourceConfig::default(), 0, 10.0).unwrap();
        let new = || NodeBuilder::new("park", "robot0", Default::default(), Default::default(), 0);
        let mut with = new().with_cloud(&CloudParams::default());
        let mut without = new();
        let mut plain = new().with_cloud(&CloudParams {
            keep: false,
            ..CloudParams::default()
        });
        let (mut sizes, mut nodes) = (Vec::new(), 0);
        while nodes < 3 {
            let Some(SourceEvent::Scan(scan)) = source.next_event() else {
                continue;
            };
            let node = with.offer(&scan).unwrap();
            let bare = without.offer(&scan).unwrap();
            assert_eq!(plain.offer(&scan).unwrap(), bare, "keep = false: no cloud");
            let (Some(node), Some(bare)) = (node, bare) else {
                continue;
            };
            nodes += 1;
            assert!(bare.cloud.is_none());
            let cloud = node.cloud.as_ref().unwrap();
            let kept = cloud.counts();
            // Every class is there, the cap holds, and nothing else differs.
            assert!(
                kept.ground > 0 && kept.landmark > 0 && kept.overhang > 0,
                "{kept:?}"
            );
            assert!(cloud.classes.len() <= 6000);
            let counts = node.counts.unwrap();
            assert_eq!(
                cloud.source_points,
                (counts.ground + counts.landmark + counts.overhang) as u64
            );
            let mut without_cloud = node.clone().into_parts();
            without_cloud.cloud = None;
            assert_eq!(Node::new(without_cloud).unwrap(), bare);
            let bytes = node.encode();
            // The wire keeps a cloud to the centimetre.
            let sent = wire::decode_node(&bytes)
                .unwrap()
                .into_parts()
                .cloud
                .unwrap();
            assert_eq!(sent.classes, cloud.classes);
            let off =
                |(a, b): (&[f32; 3], &[f32; 3])| (0..3).all(|k| (a[k] - b[k]).abs() <= 0.0051);
            assert!(sent.points_m.iter().zip(&cloud.points_m).all(off));
            sizes.push((bare.encode().len(), bytes.len(), cloud.classes.len()));
        }
        // Well under 100 KB a node with its cloud (printed with --nocapture).
        eprintln!("node bytes without cloud, with cloud, cloud points: {sizes:?}");
        assert!(sizes.iter().all(|&(_, with, _)| with < 60_000), "{sizes:?}");
    }
}
