//! The pose network: nodes, edges and GPS residuals (rows or columns), as g2o, and marginal
//! covariances of nodes.

use super::{Api, ApiError, Reply};
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::IntoResponse;
use fleetmap::FleetView;
use serde::{Deserialize, Serialize};
use slam::nalgebra::Matrix3;
use slam::{EdgeKind, Pose2};
use utoipa::{IntoParams, ToSchema};

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct GraphQuery {
    /// Include each edge's information matrix.
    #[serde(default)]
    information: bool,
    /// One array per field instead of one object per item, positions rounded to the millimetre
    /// (a fifth of the size, for the dashboard's big maps).
    #[serde(default)]
    columns: bool,
}

/// A node of the network at its optimized pose.
#[derive(Serialize, ToSchema)]
pub(super) struct GraphNode {
    id: usize,
    robot: String,
    node_seq: u64,
    stamp_ns: u64,
    pose: Pose2,
}

/// A relative edge.
#[derive(Serialize, ToSchema)]
pub(super) struct GraphEdge {
    from: usize,
    to: usize,
    kind: EdgeKind,
    measurement: Pose2,
    /// Information matrix of (x, y, θ), 9 values column-major; only with `?information=true`.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<f64>>)]
    information: Option<Matrix3<f64>>,
}

/// A GPS edge: the fix and how far the optimized antenna is from it.
#[derive(Serialize, ToSchema)]
pub(super) struct GpsResidual {
    node: usize,
    /// East, north of the datum (m).
    position_m: [f64; 2],
    /// Antenna at the node's pose minus the fix (m).
    residual_m: [f64; 2],
}

/// The network, one object per item.
#[derive(Serialize, ToSchema)]
pub(super) struct GraphRows {
    fleet: String,
    nodes: Vec<GraphNode>,
    edges: Vec<GraphEdge>,
    gps: Vec<GpsResidual>,
}

/// The network as columns: `nodes.{robot (index into robots), node_seq, x, y, theta}`,
/// `edges.{from, to, kind (index into kinds)}`, `gps.{node, x, y, residual_x, residual_y}`.
/// Serialized straight from these vectors (no JSON tree: 10,000 nodes in a few ms).
#[derive(Serialize, ToSchema)]
pub(super) struct GraphColumns<'a> {
    fleet: &'a str,
    robots: Vec<&'a str>,
    kinds: [EdgeKind; 4],
    nodes: NodeColumns,
    edges: EdgeColumns,
    gps: GpsColumns,
}

#[derive(Serialize, ToSchema)]
pub(super) struct NodeColumns {
    robot: Vec<usize>,
    node_seq: Vec<u64>,
    x: Vec<f64>,
    y: Vec<f64>,
    theta: Vec<f64>,
}

#[derive(Serialize, ToSchema)]
pub(super) struct EdgeColumns {
    from: Vec<usize>,
    to: Vec<usize>,
    kind: Vec<usize>,
}

#[derive(Serialize, ToSchema)]
pub(super) struct GpsColumns {
    node: Vec<usize>,
    x: Vec<f64>,
    y: Vec<f64>,
    residual_x: Vec<f64>,
    residual_y: Vec<f64>,
}

/// Either form of the network (for the document: the route answers one).
#[derive(Serialize, ToSchema)]
#[serde(untagged)]
#[allow(dead_code, clippy::large_enum_variant)]
pub(super) enum Graph<'a> {
    Rows(GraphRows),
    #[schema(value_type = GraphColumns)]
    Columns(GraphColumns<'a>),
}

/// Metres (and radians) to the millimetre (milliradian), as JSON writes them short.
fn milli(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

fn graph_columns(v: &FleetView) -> GraphColumns<'_> {
    let residuals: Vec<_> = v.gps.iter().map(|g| g.error_at(&v.poses[g.node])).collect();
    let kind_index = |k: &EdgeKind| {
        EdgeKind::ALL
            .iter()
            .position(|a| a == k)
            .expect("every kind listed")
    };
    GraphColumns {
        fleet: &v.id,
        robots: v.robots.iter().map(|r| r.id.as_str()).collect(),
        kinds: EdgeKind::ALL,
        nodes: NodeColumns {
            robot: v.nodes.iter().map(|n| n.robot).collect(),
            node_seq: v.nodes.iter().map(|n| n.node_seq).collect(),
            x: v.poses.iter().map(|p| milli(p.x)).collect(),
            y: v.poses.iter().map(|p| milli(p.y)).collect(),
            theta: v.poses.iter().map(|p| milli(p.theta)).collect(),
        },
        edges: EdgeColumns {
            from: v.edges.iter().map(|e| e.from).collect(),
            to: v.edges.iter().map(|e| e.to).collect(),
            kind: v.edges.iter().map(|e| kind_index(&e.kind)).collect(),
        },
        gps: GpsColumns {
            node: v.gps.iter().map(|g| g.node).collect(),
            x: v.gps.iter().map(|g| milli(g.position_m.x)).collect(),
            y: v.gps.iter().map(|g| milli(g.position_m.y)).collect(),
            residual_x: residuals.iter().map(|r| milli(r.x)).collect(),
            residual_y: residuals.iter().map(|r| milli(r.y)).collect(),
        },
    }
}

fn graph_rows(v: &FleetView, information: bool) -> GraphRows {
    GraphRows {
        fleet: v.id.clone(),
        nodes: v
            .nodes
            .iter()
            .zip(&v.poses)
            .enumerate()
            .map(|(id, (n, p))| GraphNode {
                id,
                robot: v.robots[n.robot].id.clone(),
                node_seq: n.node_seq,
                stamp_ns: n.stamp_ns,
                pose: *p,
            })
            .collect(),
        edges: v
            .edges
            .iter()
            .map(|e| GraphEdge {
                from: e.from,
                to: e.to,
                kind: e.kind,
                measurement: e.measurement,
                information: information.then_some(e.information),
            })
            .collect(),
        gps: v
            .gps
            .iter()
            .map(|g| {
                let r = g.error_at(&v.poses[g.node]);
                GpsResidual {
                    node: g.node,
                    position_m: [g.position_m.x, g.position_m.y],
                    residual_m: [r.x, r.y],
                }
            })
            .collect(),
    }
}

#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/graph", tag = "graph",
    params(("fleet" = String, Path, description = "Fleet id"), GraphQuery),
    responses(
        (status = 200, description = "Nodes, edges and GPS residuals", body = Graph),
        (status = 404, description = "No such fleet", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn graph(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GraphQuery>,
) -> Reply {
    let v = api.view(&fleet)?;
    // Serialized as heavy work: megabytes of JSON for a big map.
    let json = api
        .limits
        .heavy(move || {
            let json = if q.columns {
                serde_json::to_vec(&graph_columns(&v))
            } else {
                serde_json::to_vec(&graph_rows(&v, q.information))
            };
            json.map_err(ApiError::internal)
        })
        .await?;
    Ok(([(header::CONTENT_TYPE, "application/json")], json).into_response())
}

/// The network as g2o (`VERTEX_SE2`, `EDGE_SE2`), as g2o and GTSAM read it.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/graph.g2o", tag = "graph",
    params(("fleet" = String, Path, description = "Fleet id")),
    responses(
        (status = 200, description = "g2o text", content_type = "text/plain", body = String),
        (status = 404, description = "No such fleet", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn graph_g2o(State(api): State<Api>, Path(fleet): Path<String>) -> Reply {
    let v = api.view(&fleet)?;
    let text = api
        .limits
        .heavy(move || {
            let graph = slam::PoseGraph {
                poses: v.poses.to_vec(),
                edges: v.edges.to_vec(),
                gps: Vec::new(),
            };
            let ids: Vec<i64> = (0..v.poses.len() as i64).collect();
            Ok(graphio::posegraph::to_g2o(&graph, &ids))
        })
        .await?;
    Ok(([(header::CONTENT_TYPE, "text/plain")], text).into_response())
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct CovarianceQuery {
    /// Node ids, comma-separated (at most 500).
    nodes: String,
}

/// Most nodes one covariance query may ask for.
const MAX_COVARIANCE_NODES: usize = 500;

/// Marginal covariances of nodes.
#[derive(Serialize, ToSchema)]
pub(super) struct Covariances {
    fleet: String,
    nodes: Vec<usize>,
    /// Per node, its (x, y, θ) covariance, 3 × 3 row-major; null for the node that fixes
    /// the gauge.
    covariance: Vec<Option<[[f64; 3]; 3]>>,
}

/// Marginal covariances of nodes' (x, y, θ) at the current poses: each the inverse of the
/// normal matrix at that node.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/covariances", tag = "graph",
    params(("fleet" = String, Path, description = "Fleet id"), CovarianceQuery),
    responses(
        (status = 200, description = "Covariances of the nodes asked for", body = Covariances),
        (status = 400, description = "Unreadable or too many node ids", body = String),
        (status = 404, description = "No such fleet or node", body = String),
        (status = 422, description = "The network cannot be factorized", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn covariances(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<CovarianceQuery>,
) -> Reply<Json<Covariances>> {
    let v = api.view(&fleet)?;
    let nodes: Vec<usize> = q
        .nodes
        .split(',')
        .filter(|s| !s.is_empty())
        .map(|s| s.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            ApiError::BadRequest(format!(
                "nodes={:?}: want node ids, comma-separated",
                q.nodes
            ))
        })?;
    if nodes.len() > MAX_COVARIANCE_NODES {
        return Err(ApiError::BadRequest(format!(
            "{} nodes asked for, at most {MAX_COVARIANCE_NODES} at once",
            nodes.len()
        )));
    }
    if let Some(n) = nodes.iter().find(|&&n| n >= v.poses.len()) {
        return Err(ApiError::NotFound(format!(
            "no node {n} in fleet {fleet:?}"
        )));
    }
    let marginals = api.marginals.clone();
    let (nodes, covs) = api
        .limits
        .heavy(move || {
            let covs = marginals
                .of(&v, &nodes)
                .map_err(|e| ApiError::Unprocessable(e.to_string()))?;
            Ok((nodes, covs))
        })
        .await?;
    let rows = |m: &Matrix3<f64>| -> [[f64; 3]; 3] {
        std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
    };
    Ok(Json(Covariances {
        fleet,
        nodes,
        covariance: covs.iter().map(|c| c.as_ref().map(rows)).collect(),
    }))
}
