//! Fleets: which have a map, each one's summary, its robots (live), a robot's trajectory,
//! and the operator's re-optimization.

use super::access::authorized;
use super::{Api, ApiError, Reply};
use crate::inbox::{OptimizeError, Work};
use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use fleetmap::{FleetView, RobotView};
use runtime::session::now_ns;
use serde::Serialize;
use slam::geodesy::Geodetic;
use slam::{MapperStats, OptimizeReport, Pose2};
use utoipa::ToSchema;

/// Fleets with a map, and those whose stored map did not replay.
#[derive(Serialize, ToSchema)]
pub(super) struct FleetList {
    /// Fleets with a map, sorted.
    fleets: Vec<String>,
    /// Fleets quarantined at start (their routes answer 503), sorted, with the reason.
    quarantined: Vec<QuarantinedFleet>,
}

/// A fleet whose stored map did not replay.
#[derive(Serialize, ToSchema)]
pub(super) struct QuarantinedFleet {
    fleet: String,
    /// Why its rows did not replay.
    reason: String,
}

#[utoipa::path(get, path = "/api/v1/fleets", tag = "fleets", responses(
    (status = 200, description = "Fleets with a map, and quarantined fleets, sorted", body = FleetList),
))]
pub(super) async fn fleets(State(api): State<Api>) -> Json<FleetList> {
    let mut fleets: Vec<String> = api
        .shared
        .fleets
        .read()
        .expect("views lock")
        .keys()
        .cloned()
        .collect();
    fleets.sort();
    let quarantined = api
        .shared
        .quarantined_fleets()
        .into_iter()
        .map(|(fleet, reason)| QuarantinedFleet {
            fleet: fleet.clone(),
            reason: reason.clone(),
        })
        .collect();
    Json(FleetList {
        fleets,
        quarantined,
    })
}

/// A fleet's map in numbers.
#[derive(Serialize, ToSchema)]
pub(super) struct Summary {
    fleet: String,
    robots: usize,
    nodes: usize,
    edges: usize,
    gps_edges: usize,
    loop_closures: usize,
    inter_robot_closures: usize,
    stats: MapperStats,
    last_optimization: Option<OptimizeReport>,
    /// Time the last batch of nodes took to map (ms).
    last_ingest_ms: f64,
    /// The GPS datum: origin of the map's east-north frame.
    datum: Option<Geodetic>,
    updated_ns: u64,
}

#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/summary", tag = "fleets",
    params(("fleet" = String, Path, description = "Fleet id")),
    responses(
        (status = 200, description = "Nodes, edges, closures, last optimization", body = Summary),
        (status = 404, description = "No such fleet", body = String),
    ))]
pub(super) async fn summary(
    State(api): State<Api>,
    Path(fleet): Path<String>,
) -> Reply<Json<Summary>> {
    let v = api.view(&fleet)?;
    Ok(Json(Summary {
        fleet: v.id.clone(),
        robots: v.robots.len(),
        nodes: v.poses.len(),
        edges: v.edges.len(),
        gps_edges: v.gps.len(),
        loop_closures: v.stats.loop_closures,
        inter_robot_closures: v.stats.inter_robot_closures,
        stats: v.stats,
        last_optimization: v.last_optimization,
        last_ingest_ms: v.last_ingest_ms,
        datum: v.datum.map(|d| d.origin),
        updated_ns: v.updated_ns,
    }))
}

/// A robot on the map now.
#[derive(Serialize, ToSchema)]
pub(super) struct RobotState {
    id: String,
    /// Its map pose: live odometry since its last node composed onto that node's pose.
    pub(super) pose: Pose2,
    /// Stamp of the live odometry used (0: none yet).
    stamp_ns: u64,
    /// When that odometry arrived (0: none yet).
    last_seen_ns: u64,
    /// The map pose of the robot's odometry frame (ROS's map→odom): `pose` is this composed
    /// with the live odometry pose. The robot's edge publishes the same on `/tf` (`[ros2_out]`).
    map_from_odometry: Pose2,
    nodes: usize,
    /// Highest node_seq taken of its newest chain.
    last_node_seq: u64,
    /// Its chains of nodes, one per outbox it sent from (a robot whose outbox was lost starts
    /// a new one), oldest first.
    chains: Vec<fleetmap::ChainView>,
}

/// The robot's pose on the map now: live odometry since its last node, or the node itself.
pub(super) fn robot_state(api: &Api, v: &FleetView, robot: &RobotView) -> RobotState {
    let (pose, stamp_ns, last_seen_ns) = api.shared.robot_pose(v, robot);
    RobotState {
        id: robot.id.clone(),
        pose,
        stamp_ns,
        last_seen_ns,
        map_from_odometry: robot.map_from_odometry(),
        nodes: robot.nodes,
        last_node_seq: robot.last_node_seq,
        chains: robot.chains.clone(),
    }
}

/// A fleet's robots.
#[derive(Serialize, ToSchema)]
pub(super) struct RobotList {
    fleet: String,
    now_ns: u64,
    robots: Vec<RobotState>,
}

#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/robots", tag = "fleets",
    params(("fleet" = String, Path, description = "Fleet id")),
    responses(
        (status = 200, description = "Robots with live map pose and last-seen time", body = RobotList),
        (status = 404, description = "No such fleet", body = String),
    ))]
pub(super) async fn robots(
    State(api): State<Api>,
    Path(fleet): Path<String>,
) -> Reply<Json<RobotList>> {
    let v = api.view(&fleet)?;
    let robots = v.robots.iter().map(|r| robot_state(&api, &v, r)).collect();
    Ok(Json(RobotList {
        fleet: v.id.clone(),
        now_ns: now_ns(),
        robots,
    }))
}

pub(super) fn robot<'a>(v: &'a FleetView, robot: &str) -> Reply<&'a RobotView> {
    v.robot(robot)
        .ok_or_else(|| ApiError::NotFound(format!("no robot {robot:?} in fleet {:?}", v.id)))
}

#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/robots/{robot}/pose", tag = "fleets",
    params(("fleet" = String, Path, description = "Fleet id"), ("robot" = String, Path, description = "Robot id")),
    responses(
        (status = 200, description = "One robot's live map pose", body = RobotState),
        (status = 404, description = "No such fleet or robot", body = String),
    ))]
pub(super) async fn robot_pose(
    State(api): State<Api>,
    Path((fleet, id)): Path<(String, String)>,
) -> Reply<Json<RobotState>> {
    let v = api.view(&fleet)?;
    let r = robot(&v, &id)?;
    Ok(Json(robot_state(&api, &v, r)))
}

/// The robot's node poses as a TUM trajectory (`t x y z qx qy qz qw`, t in s), as evo reads it.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/robots/{robot}/trajectory.tum", tag = "fleets",
    params(("fleet" = String, Path, description = "Fleet id"), ("robot" = String, Path, description = "Robot id")),
    responses(
        (status = 200, description = "TUM trajectory", content_type = "text/plain", body = String),
        (status = 404, description = "No such fleet or robot", body = String),
    ))]
pub(super) async fn trajectory_tum(
    State(api): State<Api>,
    Path((fleet, id)): Path<(String, String)>,
) -> Reply {
    let v = api.view(&fleet)?;
    robot(&v, &id)?;
    let r = v
        .robots
        .iter()
        .position(|r| r.id == id)
        .expect("found above");
    let poses = v
        .nodes
        .iter()
        .zip(&v.poses)
        .filter(|(n, _)| n.robot == r)
        .map(|(n, p)| (n.stamp_ns as f64 * 1e-9, *p));
    let text = graphio::trajectory::to_tum(poses).map_err(ApiError::internal)?;
    Ok(([(header::CONTENT_TYPE, "text/plain")], text).into_response())
}

/// Re-optimizes the fleet's network now (needs the bearer token).
#[utoipa::path(post, path = "/api/v1/fleets/{fleet}/optimize", tag = "fleets",
    params(("fleet" = String, Path, description = "Fleet id")),
    security(("bearer" = [])),
    responses(
        (status = 200, description = "The optimizer's report", body = OptimizeReport),
        (status = 401, description = "No valid bearer token", body = String),
        (status = 403, description = "Write routes are off, or the token only reads", body = String),
        (status = 404, description = "No such fleet, or not solvable yet", body = String),
        (status = 503, description = "The mapper is stopping or busy", body = String),
    ))]
pub(super) async fn optimize(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    headers: HeaderMap,
) -> Reply<Response> {
    authorized(&api, &headers)?;
    api.available(&fleet)?;
    match Work::optimize(&api.work, &fleet).await {
        Ok(report) => Ok(Json(report).into_response()),
        Err(OptimizeError::Stopped) => Err(ApiError::Unavailable("mapper stopping".into())),
        Err(OptimizeError::Busy) => Err(ApiError::Unavailable("mapper busy, retry".into())),
        Err(OptimizeError::Refused(why)) => Err(ApiError::NotFound(why)),
        Err(OptimizeError::StoreFailed(why)) => Err(super::Degraded::store(why)),
    }
}
