//! What the mapper puts on the Zenoh bus: acks to robots, the corrected poses after a solve,
//! and the answers to `levelmap/{fleet}/map/{poses,summary}` queries (protobuf, `map.proto`).

use crate::views::{Metrics, Shared};
use fleetmap::FleetMap;
use runtime::session::now_ns;
use wire::{MapPose, Message, v1};
use zenoh::Wait;

/// What an ack tells one robot about one of its chains.
pub struct AckOf<'a> {
    /// The fleet.
    pub fleet: &'a str,
    /// The robot.
    pub robot: &'a str,
    /// The chain (`Node.chain_id`).
    pub chain_id: u64,
    /// The highest node_seq of the chain stored, if any.
    pub acked: Option<u64>,
    /// The node the mapper needs next, after a gap.
    pub resend_from: Option<u64>,
}

/// What the worker sends out as it goes: acks, localizations, corrected poses. The bus
/// ([`Bus`]) puts them on Zenoh; a test keeps them.
pub trait Outbound: Send {
    /// Tells a robot the highest node of its chain that is mapped and stored.
    fn ack(&self, metrics: &Metrics, of: &AckOf);
    /// A localizing robot's node on its map version, to the robot.
    fn localization(&self, metrics: &Metrics, message: &wire::Localized);
    /// Every robot's last node, corrected, with where the solve was taken (`solved_from`:
    /// each robot's last node_seq then).
    fn publish_poses(&self, map: &FleetMap, solved_from: &[(String, u64)]);
}

/// The mapper's side of the bus.
pub struct Bus {
    session: zenoh::Session,
}

impl Bus {
    /// The bus over the mapper's session.
    pub fn new(session: zenoh::Session) -> Bus {
        Bus { session }
    }
}

impl Outbound for Bus {
    fn ack(&self, metrics: &Metrics, of: &AckOf) {
        let ack = v1::Ack {
            header: Some(v1::Header::new(of.fleet, of.robot, 0, now_ns(), now_ns())),
            acked_node_seq: of.acked,
            chain_id: of.chain_id,
            resend_from: of.resend_from,
        };
        let (fleet, robot) = (of.fleet, of.robot);
        let Ok(key) = wire::ack_key(fleet, robot) else {
            return;
        };
        match self.session.put(key, ack.encode_to_vec()).wait() {
            Ok(()) => Metrics::bump(&metrics.acks_sent),
            Err(e) => tracing::warn!(fleet, robot, "ack not sent: {e}"),
        }
    }

    fn localization(&self, metrics: &Metrics, message: &wire::Localized) {
        let Ok(key) = wire::localization_key(&message.fleet, &message.robot) else {
            return;
        };
        let bytes = wire::localization_to_wire(message).encode_to_vec();
        match self.session.put(key, bytes).wait() {
            Ok(()) => Metrics::bump(&metrics.localizations_sent),
            Err(e) => tracing::warn!(robot = message.robot, "localization not sent: {e}"),
        }
    }

    /// On `levelmap/{fleet}/map/poses`.
    fn publish_poses(&self, map: &FleetMap, solved_from: &[(String, u64)]) {
        let poses: Vec<MapPose> = map
            .robots()
            .iter()
            .filter_map(|r| {
                let &last = r.nodes.last()?;
                // Its last mapped node: nodes localized since are not in the map.
                Some(MapPose {
                    robot: r.id.clone(),
                    node_seq: map.nodes()[last].node_seq,
                    pose: map.poses()[last],
                })
            })
            .collect();
        let mut message = wire::map_poses_to_wire(map.id(), &poses, now_ns());
        message.solved_from = solved_from
            .iter()
            .map(|(robot, node_seq)| v1::NodeRef {
                robot_id: robot.clone(),
                node_seq: *node_seq,
            })
            .collect();
        let body = message.encode_to_vec();
        if let Ok(key) = wire::map_key(map.id(), "poses")
            && let Err(e) = self.session.put(key, body).wait()
        {
            tracing::warn!(fleet = map.id(), "poses not published: {e}");
        }
    }
}

/// Answers `levelmap/{fleet}/map/summary` or `…/poses` (every node) from the current view;
/// nothing for an unknown fleet or item.
pub fn answer_map_query(shared: &Shared, query: &zenoh::query::Query) {
    let key = query.key_expr().as_str();
    let mut chunks = key.split('/').skip(1);
    let (Some(fleet), Some(_map), Some(item)) = (chunks.next(), chunks.next(), chunks.next())
    else {
        return;
    };
    let Some(view) = shared.fleet(fleet) else {
        return;
    };
    let body = match item {
        "summary" => v1::MapSummary {
            version: wire::WIRE_VERSION,
            fleet_id: view.id.clone(),
            sent_ns: now_ns(),
            robots: u32::try_from(view.robots.len()).unwrap_or(u32::MAX),
            nodes: view.poses.len() as u64,
            edges: view.edges.len() as u64,
            loop_closures: view.stats.loop_closures as u64,
            inter_robot_closures: view.stats.inter_robot_closures as u64,
        }
        .encode_to_vec(),
        "poses" => {
            let poses: Vec<MapPose> = view
                .nodes
                .iter()
                .zip(&view.poses)
                .map(|(n, p)| MapPose {
                    robot: view.robots[n.robot].id.clone(),
                    node_seq: n.node_seq,
                    pose: *p,
                })
                .collect();
            wire::map_poses_to_wire(&view.id, &poses, now_ns()).encode_to_vec()
        }
        _ => return,
    };
    let _ = query.reply(key, body).wait();
}

pub mod feeds;
pub mod odometry;
pub mod recording;
pub mod ros_out;
