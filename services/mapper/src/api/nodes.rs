//! One node of the network: what it came with, and its segmented 3D cloud.

use super::{Api, ApiError, Reply};
use axum::Json;
use axum::extract::{Path, State};
use fleetmap::FleetView;
use fleetmap::NodeRecord;
use leveling::ClassCounts;
use serde::Serialize;
use slam::{EdgeKind, Pose2};
use std::sync::Arc;
use utoipa::ToSchema;
use wire::Message;

/// Points per class of a scan.
#[derive(Serialize, ToSchema)]
pub(super) struct Counts {
    points: usize,
    invalid: usize,
    ground: usize,
    landmark: usize,
    overhang: usize,
}

impl From<&ClassCounts> for Counts {
    fn from(c: &ClassCounts) -> Counts {
        Counts {
            points: c.invalid + c.ground + c.landmark + c.overhang,
            invalid: c.invalid,
            ground: c.ground,
            landmark: c.landmark,
            overhang: c.overhang,
        }
    }
}

/// A GPS fix of the node as the network took it.
#[derive(Serialize, ToSchema)]
pub(super) struct NodeGps {
    /// East, north of the datum (m).
    position_m: [f64; 2],
    /// The antenna in the node's scan frame (m).
    lever_arm_m: [f64; 2],
}

/// The leveled scan: bearings (rad) and ranges (m, 0 = no return).
#[derive(Serialize, ToSchema)]
pub(super) struct PolarScan {
    bearing_rad: Vec<f32>,
    range_m: Vec<f32>,
}

/// An edge at the node.
#[derive(Serialize, ToSchema)]
pub(super) struct EdgeRef {
    from: usize,
    to: usize,
    kind: EdgeKind,
}

/// One node with what it came with.
#[derive(Serialize, ToSchema)]
pub(super) struct NodeDetail {
    /// Whether the store holds its segmented 3D cloud.
    cloud: bool,
    id: usize,
    robot: String,
    node_seq: u64,
    stamp_ns: u64,
    /// Optimized pose of the scan frame.
    pose: Pose2,
    /// The scan frame's pose in the robot's odometry frame.
    odometry: Pose2,
    gps: Vec<NodeGps>,
    counts: Option<Counts>,
    scan: PolarScan,
    edges: Vec<EdgeRef>,
}

fn node(v: &FleetView, node: usize) -> Reply<&Arc<NodeRecord>> {
    v.nodes
        .get(node)
        .ok_or_else(|| ApiError::NotFound(format!("no node {node} in fleet {:?}", v.id)))
}

#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/nodes/{node}", tag = "nodes",
    params(("fleet" = String, Path, description = "Fleet id"), ("node" = usize, Path, description = "Node index in the map")),
    responses(
        (status = 200, description = "The node: pose, odometry, GPS, counts, scan, edges", body = NodeDetail),
        (status = 404, description = "No such fleet or node", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn node_detail(
    State(api): State<Api>,
    Path((fleet, id)): Path<(String, usize)>,
) -> Reply<Json<NodeDetail>> {
    let v = api.view(&fleet)?;
    let n = node(&v, id)?;
    let cloud = stored_cloud(&api, &fleet, id).await?.is_some();
    Ok(Json(NodeDetail {
        cloud,
        id,
        robot: v.robots[n.robot].id.clone(),
        node_seq: n.node_seq,
        stamp_ns: n.stamp_ns,
        pose: v.poses[id],
        odometry: n.odometry,
        gps: n
            .gps
            .iter()
            .map(|g| NodeGps {
                position_m: [g.position_m.x, g.position_m.y],
                lever_arm_m: [g.lever_arm_m.x, g.lever_arm_m.y],
            })
            .collect(),
        counts: n.counts.as_ref().map(Counts::from),
        scan: {
            let (bearing_rad, range_m) = n.scan.polar();
            PolarScan {
                bearing_rad,
                range_m,
            }
        },
        edges: v
            .edges
            .iter()
            .filter(|e| e.from == id || e.to == id)
            .map(|e| EdgeRef {
                from: e.from,
                to: e.to,
                kind: e.kind,
            })
            .collect(),
    }))
}

/// A node's encoded cloud from the store (a disk read: heavy work), or from the clouds
/// shared beyond it when the store lacks it ([`crate::blobs`]).
async fn stored_cloud(api: &Api, fleet: &str, node: usize) -> Reply<Option<Vec<u8>>> {
    // 503 for as long as commits fail, whether or not the file is open between attempts.
    if let Some(fault) = api.shared.store_fault() {
        return Err(super::Degraded::store(fault));
    }
    let (store, name) = (api.store.clone(), fleet.to_owned());
    let stored = api
        .limits
        .heavy(move || Ok(store.cloud(&name, node as u64)))
        .await?
        .map_err(|e| api.store_error(e))?;
    match stored {
        // In cluster mode, a node mapped on another host before this one took the site over.
        None => api
            .blobs
            .cloud(fleet, node as u64)
            .await
            .map_err(ApiError::Unavailable),
        stored => Ok(stored),
    }
}

/// Points per class of a cloud.
#[derive(Serialize, ToSchema)]
pub(super) struct CloudCounts {
    ground: usize,
    landmark: usize,
    overhang: usize,
}

impl From<&ClassCounts> for CloudCounts {
    fn from(c: &ClassCounts) -> CloudCounts {
        CloudCounts {
            ground: c.ground,
            landmark: c.landmark,
            overhang: c.overhang,
        }
    }
}

/// A node's segmented 3D cloud.
#[derive(Serialize, ToSchema)]
pub(super) struct NodeCloud {
    fleet: String,
    id: usize,
    robot: String,
    node_seq: u64,
    /// Always `leveled`: the leveled frame of the node's scan.
    frame: &'static str,
    /// Points (m), flat x, y, z.
    points: Vec<f64>,
    /// The class of each point: 1 ground, 2 landmark, 3 overhang.
    #[schema(value_type = Vec<u8>)]
    classes: Vec<u8>,
    counts: CloudCounts,
    /// Points kept by the robot's reduction.
    kept: usize,
    /// Valid points of the 3D scan before the reduction.
    source_points: u64,
    /// The scan's points per class before the reduction, when the robot sent its counts.
    source_counts: Option<CloudCounts>,
    /// Voxel edge of the reduction (m).
    voxel_m: f64,
    max_points: u32,
}

/// The node's segmented 3D cloud: points in the leveled frame of its scan, the class of
/// each, counts per class, and how the robot reduced it. Read from the store on request (no
/// view holds clouds).
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/nodes/{node}/cloud", tag = "nodes",
    params(("fleet" = String, Path, description = "Fleet id"), ("node" = usize, Path, description = "Node index in the map")),
    responses(
        (status = 200, description = "The node's cloud", body = NodeCloud),
        (status = 404, description = "No such fleet or node, or the node has no cloud", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn node_cloud(
    State(api): State<Api>,
    Path((fleet, id)): Path<(String, usize)>,
) -> Reply<Json<NodeCloud>> {
    let v = api.view(&fleet)?;
    node(&v, id)?;
    // The read is the heavy work (and 503 while the store fails); decoding 6,000 points is not.
    let bytes = stored_cloud(&api, &fleet, id).await?;
    Ok(Json(node_cloud_of(&v, id, bytes)?))
}

/// The node's cloud from its stored bytes (none: 404 with the reason).
fn node_cloud_of(v: &FleetView, id: usize, bytes: Option<Vec<u8>>) -> Reply<NodeCloud> {
    let n = node(v, id)?;
    let robot = v.robots[n.robot].id.clone();
    let bytes = bytes.ok_or_else(|| {
        ApiError::NotFound(format!(
            "node {id} of fleet {:?} has no 3D cloud: robot {robot} sent none (edge config \
             [cloud] keep = false, or a fixed 2D scanner)",
            v.id
        ))
    })?;
    let cloud = wire::v1::SegmentedCloud::decode(bytes.as_slice()).map_err(ApiError::internal)?;
    // Checked when the node came; checked again, as the store is a file.
    let counts = wire::validate_cloud(&cloud).map_err(ApiError::internal)?;
    Ok(NodeCloud {
        fleet: v.id.clone(),
        id,
        robot,
        node_seq: n.node_seq,
        frame: "leveled",
        points: cloud.xyz_cm.iter().map(|&c| f64::from(c) / 100.0).collect(),
        kept: cloud.classes.len(),
        classes: cloud.classes,
        counts: CloudCounts::from(&counts),
        source_points: cloud.source_points,
        source_counts: n.counts.as_ref().map(CloudCounts::from),
        // The f32's shortest decimal (0.1, not 0.10000000149011612).
        voxel_m: cloud.voxel_m.to_string().parse::<f64>().unwrap_or(0.0),
        max_points: cloud.max_points,
    })
}
