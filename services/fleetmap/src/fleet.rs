//! One fleet's shared map: nodes from the wire into one pose network (pure, no I/O).
//!
//! A robot sends its nodes in chains (one per edge outbox: `Node.chain_id`). A chain's nodes
//! must arrive in node_seq order without gaps, from the first the robot holds
//! (`Node.held_from_seq`) when the map does not know the chain yet; a duplicate (a re-send) or
//! a node after a gap is not taken, and the sender learns from the ack the highest node taken
//! and where to re-send from. When the robot no longer holds the missing nodes (its
//! `held_from_seq` is past them: a map restored from an old backup), the chain goes on from
//! the oldest it holds. Each chain is its own odometry chain in the pose network.

use leveling::{ClassCounts, LeveledScan};
use serde::Serialize;
use slam::geodesy::GeoDatum;
use slam::matching::Scan2;
use slam::{
    BackgroundSolve, GpsObservation, Mapper2d, Mapper2dParams, MapperStats, OptimizeReport, Pose2,
    SolvedInBackground,
};
use std::collections::HashMap;
use std::sync::Arc;
use wire::Node;

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
    /// Its robot's chain (`Node.chain_id`).
    pub chain_id: u64,
    /// Its number in its chain.
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
    /// The leveled scan.
    pub scan: LeveledScan,
}

impl NodeRecord {
    /// Every beam of the leveled scan, a return or none, as the grid takes it (the map shows
    /// what the robot saw, up to the grid's `max_range_m`; matching cuts at the mapper's).
    pub fn fan(&self) -> slam::BeamFan {
        wire::grid_fan(&self.scan)
    }
}

/// The probability grid of `nodes` at `poses` (the same order): the one way a fleet's map
/// becomes a grid (the HTTP map, windows and tiles, versions, ROS 2, the lab's scores). Each
/// node's beam fan is made when the grid's pass needs it and dropped after, so a whole site's
/// grid takes the grid's memory and one node's, not every node's fan at once.
/// `nodes()` walks the nodes, the same ones in the same order each time.
pub fn grid_of<'a, I: Iterator<Item = &'a NodeRecord>>(
    nodes: impl Fn() -> I,
    poses: &[Pose2],
    params: &slam::GridParams,
) -> Result<slam::OccupancyGrid, slam::GridError> {
    slam::OccupancyGrid::from_fans_made_again(
        || poses.iter().copied().zip(nodes().map(NodeRecord::fan)),
        params,
    )
}

/// Most robots one fleet takes: per-robot state is bounded (a node of one more is rejected,
/// `too_many_robots`).
pub const MAX_ROBOTS_PER_FLEET: usize = 1024;
/// Most chains one robot may start (each a restart with a lost outbox): `too_many_chains`.
pub const MAX_CHAINS_PER_ROBOT: usize = 256;

/// One chain of a robot's nodes: what one outbox sent.
#[derive(Clone, Debug, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ChainRecord {
    /// `Node.chain_id` (0: a robot from before chains).
    pub chain_id: u64,
    /// The first node_seq taken of it.
    pub first_node_seq: u64,
    /// The highest node_seq taken of it.
    pub last_node_seq: u64,
    /// Its index among the network's odometry chains (`Mapper2d`'s robot index).
    #[serde(skip)]
    network_chain: usize,
    /// Its last node's index in the map.
    #[serde(skip)]
    last_node: usize,
}

/// Where a solve of a fleet's network was taken and where it was applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SolvePoint {
    /// Its number in the fleet, from 0.
    pub seq: u64,
    /// The arrival index of the fleet's last node when the solve was taken.
    pub taken_after: u64,
    /// The arrival index of the fleet's last node when it was applied.
    pub applied_after: u64,
}

/// A robot of the fleet.
#[derive(Clone, Debug, Serialize)]
pub struct RobotRecord {
    /// The robot's id.
    pub id: String,
    /// Highest node_seq taken of its newest chain.
    pub last_node_seq: u64,
    /// Its chains, oldest first.
    pub chains: Vec<ChainRecord>,
    /// Map nodes of this robot, in order.
    pub nodes: Vec<usize>,
}

impl RobotRecord {
    fn chain(&self, chain_id: u64) -> Option<&ChainRecord> {
        self.chains.iter().find(|c| c.chain_id == chain_id)
    }
}

/// Where a node went in the map.
#[derive(Clone, Debug, PartialEq)]
pub struct Ingested {
    /// The node's index in the map.
    pub node: usize,
    /// Set when its odometry step from the chain's last node was not plausible
    /// ([`wire::check_step`]): an odometry reset, so the node starts a new odometry chain of
    /// the network (it joins the map by GPS or scan matching) instead of being refused.
    pub odometry_break: Option<wire::WireError>,
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
    /// A bound of the fleet's state (robots, chains) or of plausibility (a step) refused it.
    #[error("node {node_seq} of {robot}: {source}")]
    Refused {
        /// The robot.
        robot: String,
        /// The node's number.
        node_seq: u64,
        /// Why, with the reason counted.
        source: wire::WireError,
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
    /// Odometry chains in the network, over every robot.
    network_chains: usize,
    /// Solves applied and numbered ([`SolvePoint`]).
    solve_points: u64,
    /// Robot chains' nodes that were localized on a map version, or passed over covered
    /// ground, instead of mapped.
    localized: localized::LocalizedChains,
    /// Each chain's last node, for the next one's prediction over covered ground.
    covers: HashMap<(String, u64), coverage::Cover>,
    /// The passes' GPS fixes that the last solve applied moved into the network, for the
    /// store to keep with its point ([`FleetMap::take_pass_fixes`]).
    pass_fixes: Vec<slam::GpsEdge>,
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
        // decides when to solve (`take_solve` for the background, `optimize_pending` here).
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
            network_chains: 0,
            solve_points: 0,
            localized: Default::default(),
            covers: HashMap::new(),
            pass_fixes: Vec::new(),
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

    /// Where `node` stands against what the map took of its robot's chain (mapped or
    /// localized).
    pub fn sequence(&self, node: &Node) -> Sequence {
        let Some(last) = self.chain_acked(&node.robot, node.chain_id) else {
            // A chain the map does not know starts where its robot says it still holds nodes
            // (0 for a new outbox): a lost first node is asked for, never skipped. Chain 0 is
            // a sender from before chains: its first node seen starts it, as it always did.
            let starts = node.chain_id == 0 || node.node_seq == node.held_from_seq;
            return match starts {
                true => Sequence::Next,
                false => Sequence::Gap {
                    expected: node.held_from_seq,
                },
            };
        };
        match node.node_seq {
            seq if seq <= last => Sequence::Duplicate,
            seq if seq == last + 1 => Sequence::Next,
            // The robot no longer holds the nodes after `last` (a map restored from a backup
            // older than what its outbox keeps): they are lost, and the chain goes on from the
            // oldest it holds rather than wait for them for good.
            seq if node.held_from_seq > last + 1 => match seq == node.held_from_seq {
                true => Sequence::Next,
                false => Sequence::Gap {
                    expected: node.held_from_seq,
                },
            },
            _ => Sequence::Gap { expected: last + 1 },
        }
    }

    /// The highest node_seq taken of a robot's chain (mapped or localized), if any.
    pub fn chain_acked(&self, robot: &str, chain_id: u64) -> Option<u64> {
        let mapped = self.chain_mapped(robot, chain_id);
        let localized = self.localized.last_seq(robot, chain_id);
        mapped.max(localized)
    }

    /// [`Self::chain_acked`] of each of `robot`'s chains, in its order: what every view of the
    /// map reads, so each chain costs one look-up.
    pub fn chains_acked<'a>(&'a self, robot: &'a RobotRecord) -> impl Iterator<Item = u64> + 'a {
        let localized = self.localized.last_seqs_of(&robot.id);
        (robot.chains.iter()).map(move |c| c.last_node_seq.max(localized(c.chain_id).unwrap_or(0)))
    }

    /// The network's odometry chain that a robot's chain goes on in, once it has a node.
    fn network_chain_of(&self, robot: &str, chain_id: u64) -> Option<usize> {
        let r = *self.by_id.get(robot)?;
        Some(self.robots[r].chain(chain_id)?.network_chain)
    }

    /// The highest node_seq mapped of a robot's chain, if any.
    fn chain_mapped(&self, robot: &str, chain_id: u64) -> Option<u64> {
        let r = *self.by_id.get(robot)?;
        Some(self.robots[r].chain(chain_id)?.last_node_seq)
    }

    /// The robot's index and its chain's index in it for `node` (the next of its chain),
    /// making them if new (bounded by [`MAX_ROBOTS_PER_FLEET`] and [`MAX_CHAINS_PER_ROBOT`]);
    /// and whether the step from the chain's last node broke odometry ([`wire::check_step`]).
    fn chain_for(
        &mut self,
        node: &Node,
    ) -> Result<(usize, usize, Option<wire::WireError>), IngestError> {
        let refused = |source| IngestError::Refused {
            robot: node.robot.clone(),
            node_seq: node.node_seq,
            source,
        };
        let too_many = |what: &'static str, count: usize, reason| {
            refused(wire::WireError::Implausible {
                field: what,
                index: None,
                value: (count + 1) as f64,
                limit: count as f64,
                reason,
            })
        };
        let robot = match self.by_id.get(&node.robot) {
            Some(&r) => r,
            None if self.robots.len() >= MAX_ROBOTS_PER_FLEET => {
                return Err(too_many("robots", MAX_ROBOTS_PER_FLEET, "too_many_robots"));
            }
            None => {
                self.robots.push(RobotRecord {
                    id: node.robot.clone(),
                    last_node_seq: node.node_seq,
                    chains: Vec::new(),
                    nodes: Vec::new(),
                });
                self.by_id.insert(node.robot.clone(), self.robots.len() - 1);
                self.robots.len() - 1
            }
        };
        let record = &self.robots[robot];
        if let Some(c) = record
            .chains
            .iter()
            .position(|c| c.chain_id == node.chain_id)
        {
            // Nodes localized since the chain's last mapped one: its odometry link spans a
            // drive the network never saw, so the chain goes on as a new part of the network
            // (it joins the map by scan matching or GPS, like a robot's first node).
            if self.localized.breaks(&node.robot, node.chain_id) {
                self.robots[robot].chains[c].network_chain = self.network_chains;
                self.network_chains += 1;
                return Ok((robot, c, None));
            }
            let last = &self.nodes[record.chains[c].last_node];
            let xy = |p: &Pose2| [p.x, p.y];
            let from = (last.stamp_ns, xy(&last.robot_odometry));
            let to = (
                node.stamp_ns,
                xy(&Pose2::from_isometry3(&node.odometry.pose)),
            );
            let odometry_break = wire::check_step(from, to).err();
            if odometry_break.is_some() {
                self.robots[robot].chains[c].network_chain = self.network_chains;
                self.network_chains += 1;
            }
            return Ok((robot, c, odometry_break));
        }
        if record.chains.len() >= MAX_CHAINS_PER_ROBOT {
            return Err(too_many("chains", MAX_CHAINS_PER_ROBOT, "too_many_chains"));
        }
        self.robots[robot].chains.push(ChainRecord {
            chain_id: node.chain_id,
            first_node_seq: node.node_seq,
            last_node_seq: node.node_seq,
            network_chain: self.network_chains,
            last_node: self.nodes.len(),
        });
        self.network_chains += 1;
        Ok((robot, self.robots[robot].chains.len() - 1, None))
    }

    /// Adds a node of this fleet.
    pub fn ingest(&mut self, node: &Node) -> Result<Ingested, IngestError> {
        let robot_id = &node.robot;
        let problem = match self.sequence(node) {
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
        let (robot, chain, odometry_break) = self.chain_for(node)?;
        let (record, scan) = self.read_node(node, robot);
        let network_chain = self.robots[robot].chains[chain].network_chain;
        let placed =
            self.mapper
                .add_robot_scan(network_chain, record.odometry, scan, &record.gps)?;
        let slam::Placed::Node(index) = placed else {
            unreachable!("node distance 0: every scan is a node")
        };
        self.localized.close_span(&node.robot, node.chain_id);
        let robot_record = &mut self.robots[robot];
        robot_record.last_node_seq = node.node_seq;
        robot_record.chains[chain].last_node_seq = node.node_seq;
        robot_record.chains[chain].last_node = index;
        robot_record.nodes.push(index);
        self.nodes.push(Arc::new(record));
        Ok(Ingested {
            node: index,
            odometry_break,
        })
    }

    /// A node's GPS fixes in the map's frame, each antenna in the scan's frame (the first fix
    /// sets the datum when none is configured).
    fn gps_of(&mut self, node: &Node) -> Vec<GpsObservation> {
        let robot_odometry = Pose2::from_isometry3(&node.odometry.pose);
        let attitude = node.odometry.pose.rotation;
        node.gps
            .iter()
            .filter(|fix| fix.has_position())
            .filter_map(|fix| {
                let datum = *self.datum.get_or_insert(GeoDatum {
                    origin: fix.position,
                });
                fix.observation(&datum, &attitude, robot_odometry.theta, &node.scan_origin)
            })
            .collect()
    }

    /// What the map keeps of a node of robot `robot` (its GPS fixes in the map's frame: the
    /// first fix sets the datum when none is configured), and its scan as matching uses it.
    fn read_node(&mut self, node: &Node, robot: usize) -> (NodeRecord, Scan2) {
        let robot_odometry = Pose2::from_isometry3(&node.odometry.pose);
        let scan_frame = robot_odometry.compose(&node.scan_origin);
        let scan = node.matching_scan(self.max_range_m);
        let gps = self.gps_of(node);
        let record = NodeRecord {
            robot,
            chain_id: node.chain_id,
            node_seq: node.node_seq,
            stamp_ns: node.stamp_ns,
            odometry: scan_frame,
            robot_odometry,
            scan_origin: node.scan_origin,
            gps,
            counts: node.counts,
            scan: node.scan.clone(),
        };
        (record, scan)
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

    /// The solve of the whole network that the nodes since the last one called for (a loop
    /// closure, a GPS fix), taken out to run in the background; `None` when none is due or
    /// the last one is still out.
    pub fn take_solve(&mut self) -> Option<BackgroundSolve> {
        self.mapper.take_solve()
    }

    /// The background solve of the network as it is, due or not (an operator's request, a
    /// replay at a recorded point); `None` while the last one is out.
    pub fn take_solve_now(&mut self) -> Option<BackgroundSolve> {
        self.mapper.take_solve_now()
    }

    /// Gives back a background solve and applies it (the nodes added since move with their
    /// chains); whether it was applied (not while a part of the network is unanchored).
    /// The passes' GPS fixes waiting then go into the network ([`FleetMap::take_pass_fixes`]).
    pub fn finish_solve(&mut self, done: SolvedInBackground) -> Result<bool, IngestError> {
        let applied = self.mapper.finish_solve(done)?;
        if applied {
            let flushed = self.mapper.flush_pass_fixes();
            self.pass_fixes.extend(flushed);
        }
        Ok(applied)
    }

    /// The passes' GPS fixes that solves applied since the last call moved into the network:
    /// the store keeps them with the solve's point, and a replay gives them back there
    /// ([`FleetMap::restore_pass_fixes`]).
    pub fn take_pass_fixes(&mut self) -> Vec<slam::GpsEdge> {
        std::mem::take(&mut self.pass_fixes)
    }

    /// Stored passes' fixes, given back where the solve they came with was applied.
    pub fn restore_pass_fixes(&mut self, fixes: &[slam::GpsEdge]) {
        self.mapper.restore_pass_fixes(fixes);
    }

    /// The next solve's point: taken after the node of arrival index `taken_after`, applied
    /// now (after the map's last node).
    pub fn next_solve_point(&mut self, taken_after: u64) -> SolvePoint {
        let point = SolvePoint {
            seq: self.solve_points,
            taken_after,
            applied_after: self.nodes.len() as u64 - 1,
        };
        self.solve_points += 1;
        point
    }

    /// A replayed solve's point: the next one is numbered after it.
    pub fn count_solve(&mut self, point: &SolvePoint) {
        self.solve_points = point.seq + 1;
    }

    /// Each robot's last node among the map's first `nodes` (robot id, node_seq): where a
    /// solve taken then stood.
    pub fn last_nodes_before(&self, nodes: usize) -> Vec<(String, u64)> {
        self.robots
            .iter()
            .filter_map(|r| {
                let before = r.nodes.partition_point(|&n| n < nodes);
                let last = *r.nodes[..before].last()?;
                Some((r.id.clone(), self.nodes[last].node_seq))
            })
            .collect()
    }
}

mod coverage;
mod localized;
pub use localized::{LocalizedSpan, SpanReplay};

pub(crate) mod snapshot;
pub use snapshot::SnapshotCovers;

#[cfg(test)]
pub(crate) mod tests;
