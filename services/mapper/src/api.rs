//! The HTTP API (`/api/v1`, JSON): thin handlers over the current fleet views. Routes and
//! their shapes are listed in the OpenAPI document served at `/api/v1/openapi.json`.

use crate::server::Work;
use crate::state::{FleetView, Shared};
use crate::store::Store;
use axum::Router;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use wire::Message;
use wire::session::now_ns;

#[derive(Clone)]
struct Api {
    shared: Arc<Shared>,
    work: mpsc::Sender<Work>,
    /// Per fleet, the optimizer that answers covariance queries: it keeps the network's
    /// symbolic factorization while the structure stays the same.
    marginals: Arc<std::sync::Mutex<std::collections::HashMap<String, slam::Optimizer>>>,
    /// Read for the nodes' clouds, which no view holds.
    store: Arc<Store>,
}

pub fn router(shared: Arc<Shared>, work: mpsc::Sender<Work>, store: Arc<Store>) -> Router {
    Router::new()
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/api/v1/openapi.json", get(openapi))
        .route("/api/v1/fleets", get(fleets))
        .route("/api/v1/auth", get(auth))
        .route("/api/v1/fleets/{fleet}/summary", get(summary))
        .route("/api/v1/fleets/{fleet}/robots", get(robots))
        .route(
            "/api/v1/fleets/{fleet}/robots/{robot}/pose",
            get(robot_pose),
        )
        .route(
            "/api/v1/fleets/{fleet}/robots/{robot}/trajectory.tum",
            get(trajectory_tum),
        )
        .route("/api/v1/fleets/{fleet}/map.png", get(map_png))
        .route("/api/v1/fleets/{fleet}/map.pgm", get(map_pgm))
        .route("/api/v1/fleets/{fleet}/map.yaml", get(map_yaml))
        .route("/api/v1/fleets/{fleet}/map.geojson", get(map_geojson))
        .route("/api/v1/fleets/{fleet}/graph", get(graph))
        .route("/api/v1/fleets/{fleet}/graph.g2o", get(graph_g2o))
        .route("/api/v1/fleets/{fleet}/nodes/{node}", get(node_detail))
        .route("/api/v1/fleets/{fleet}/covariances", get(covariances))
        .route("/api/v1/fleets/{fleet}/optimize", post(optimize))
        .route("/api/v1/events", get(events))
        .route("/api/v1/fleets/{fleet}/map.json", get(map_json))
        .route("/api/v1/fleets/{fleet}/nodes/{node}/cloud", get(node_cloud))
        .route("/", get(web_index))
        .route("/web/{file}", get(web_file))
        .with_state(Api {
            shared,
            work,
            marginals: Arc::default(),
            store,
        })
}

type Reply = Result<Response, (StatusCode, String)>;

fn not_found(what: String) -> (StatusCode, String) {
    (StatusCode::NOT_FOUND, what)
}

fn view(api: &Api, fleet: &str) -> Result<Arc<FleetView>, (StatusCode, String)> {
    api.shared
        .fleet(fleet)
        .ok_or_else(|| not_found(format!("no fleet {fleet:?} (no node received yet?)")))
}

fn json_reply(value: Value) -> Reply {
    Ok(axum::Json(value).into_response())
}

async fn healthz(State(api): State<Api>) -> (StatusCode, &'static str) {
    if api.shared.healthy.load(Ordering::Relaxed) {
        (StatusCode::OK, "ok\n")
    } else {
        (
            StatusCode::SERVICE_UNAVAILABLE,
            "the store failed: restart the mapper\n",
        )
    }
}

async fn metrics(State(api): State<Api>) -> Response {
    let m = &api.shared.metrics;
    let mut out = String::new();
    let counters = [
        (
            "levelmap_nodes_accepted_total",
            "Nodes mapped and stored.",
            &m.nodes_accepted,
        ),
        (
            "levelmap_nodes_duplicate_total",
            "Re-sent nodes taken already (re-acked).",
            &m.nodes_duplicate,
        ),
        (
            "levelmap_odometry_received_total",
            "Live odometry messages taken.",
            &m.odometry_received,
        ),
        ("levelmap_acks_sent_total", "Acks published.", &m.acks_sent),
        (
            "levelmap_optimizations_total",
            "Network optimizations run.",
            &m.optimizations,
        ),
    ];
    for (name, help, value) in counters {
        let _ = writeln!(
            out,
            "# HELP {name} {help}\n# TYPE {name} counter\n{name} {}",
            value.load(Ordering::Relaxed)
        );
    }
    let _ = writeln!(
        out,
        "# HELP levelmap_rejected_total Messages rejected, by topic and reason.\n# TYPE levelmap_rejected_total counter"
    );
    for ((topic, reason), n) in m.rejected.lock().expect("metrics lock").iter() {
        let _ = writeln!(
            out,
            "levelmap_rejected_total{{topic=\"{topic}\",reason=\"{reason}\"}} {n}"
        );
    }
    let fleets = api.shared.fleets.read().expect("views lock").clone();
    let _ = writeln!(
        out,
        "# HELP levelmap_map_nodes Nodes in a fleet's map.\n# TYPE levelmap_map_nodes gauge"
    );
    for (id, v) in &fleets {
        let _ = writeln!(
            out,
            "levelmap_map_nodes{{fleet=\"{id}\"}} {}",
            v.poses.len()
        );
    }
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out).into_response()
}

async fn fleets(State(api): State<Api>) -> Reply {
    let fleets = api.shared.fleets.read().expect("views lock").clone();
    let mut ids: Vec<&String> = fleets.keys().collect();
    ids.sort();
    json_reply(json!({ "fleets": ids }))
}

async fn summary(State(api): State<Api>, Path(fleet): Path<String>) -> Reply {
    let v = view(&api, &fleet)?;
    json_reply(json!({
        "fleet": v.id,
        "robots": v.robots.len(),
        "nodes": v.poses.len(),
        "edges": v.edges.len(),
        "gps_edges": v.gps.len(),
        "loop_closures": v.stats.loop_closures,
        "inter_robot_closures": v.stats.inter_robot_closures,
        "stats": v.stats,
        "last_optimization": v.last_optimization,
        "last_ingest_ms": v.last_ingest_ms,
        "datum": v.datum.map(|d| d.origin),
        "updated_ns": v.updated_ns,
    }))
}

/// The robot's pose on the map now: live odometry since its last node, or the node itself.
fn robot_json(api: &Api, v: &FleetView, robot: &crate::state::RobotView) -> Value {
    let live = api
        .shared
        .live
        .lock()
        .expect("live lock")
        .get(&(v.id.clone(), robot.id.clone()))
        .copied();
    let (pose, stamp_ns, last_seen_ns) = match live {
        Some(l) => (robot.live_pose(&l.odometry), l.stamp_ns, l.received_ns),
        None => (robot.map_pose_at_last_node, 0, 0),
    };
    json!({
        "id": robot.id,
        "pose": pose,
        "stamp_ns": stamp_ns,
        "last_seen_ns": last_seen_ns,
        "nodes": robot.nodes,
        "last_node_seq": robot.last_node_seq,
    })
}

async fn robots(State(api): State<Api>, Path(fleet): Path<String>) -> Reply {
    let v = view(&api, &fleet)?;
    let robots: Vec<Value> = v.robots.iter().map(|r| robot_json(&api, &v, r)).collect();
    json_reply(json!({ "fleet": v.id, "now_ns": now_ns(), "robots": robots }))
}

async fn robot_pose(State(api): State<Api>, Path((fleet, robot)): Path<(String, String)>) -> Reply {
    let v = view(&api, &fleet)?;
    let r = v
        .robot(&robot)
        .ok_or_else(|| not_found(format!("no robot {robot:?} in fleet {fleet:?}")))?;
    json_reply(robot_json(&api, &v, r))
}

#[derive(Deserialize)]
struct GraphQuery {
    /// Include each edge's information matrix.
    #[serde(default)]
    information: bool,
    /// One array per field instead of one object per item, positions rounded to the millimetre
    /// (a tenth of the size, for the dashboard's big maps).
    #[serde(default)]
    columns: bool,
}

/// Metres (and radians) to the millimetre (milliradian), as JSON writes them short.
fn milli(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// The graph as columns: `nodes.{robot (index into robots), node_seq, x, y, theta}`,
/// `edges.{from, to, kind (index into kinds)}`, `gps.{node, x, y, residual_x, residual_y}`.
/// Serialized straight from these vectors (no JSON tree: 10,000 nodes in a few ms).
#[derive(Serialize)]
struct GraphColumns<'a> {
    fleet: &'a str,
    robots: Vec<&'a str>,
    kinds: [slam::EdgeKind; 4],
    nodes: NodeColumns,
    edges: EdgeColumns,
    gps: GpsColumns,
}

#[derive(Serialize)]
struct NodeColumns {
    robot: Vec<usize>,
    node_seq: Vec<u64>,
    x: Vec<f64>,
    y: Vec<f64>,
    theta: Vec<f64>,
}

#[derive(Serialize)]
struct EdgeColumns {
    from: Vec<usize>,
    to: Vec<usize>,
    kind: Vec<usize>,
}

#[derive(Serialize)]
struct GpsColumns {
    node: Vec<usize>,
    x: Vec<f64>,
    y: Vec<f64>,
    residual_x: Vec<f64>,
    residual_y: Vec<f64>,
}

fn graph_columns(v: &FleetView) -> GraphColumns<'_> {
    let residuals: Vec<[f64; 2]> = v
        .gps
        .iter()
        .map(|g| {
            let antenna = v.poses[g.node].transform_point([g.lever_arm_m.x, g.lever_arm_m.y]);
            [antenna[0] - g.position_m.x, antenna[1] - g.position_m.y]
        })
        .collect();
    GraphColumns {
        fleet: &v.id,
        robots: v.robots.iter().map(|r| r.id.as_str()).collect(),
        kinds: slam::EdgeKind::ALL,
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
            kind: v
                .edges
                .iter()
                .map(|e| {
                    slam::EdgeKind::ALL
                        .iter()
                        .position(|k| *k == e.kind)
                        .expect("every kind listed")
                })
                .collect(),
        },
        gps: GpsColumns {
            node: v.gps.iter().map(|g| g.node).collect(),
            x: v.gps.iter().map(|g| milli(g.position_m.x)).collect(),
            y: v.gps.iter().map(|g| milli(g.position_m.y)).collect(),
            residual_x: residuals.iter().map(|r| milli(r[0])).collect(),
            residual_y: residuals.iter().map(|r| milli(r[1])).collect(),
        },
    }
}

async fn graph(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GraphQuery>,
) -> Reply {
    let v = view(&api, &fleet)?;
    if q.columns {
        return Ok(axum::Json(graph_columns(&v)).into_response());
    }
    let nodes: Vec<Value> = v
        .nodes
        .iter()
        .zip(&v.poses)
        .enumerate()
        .map(|(i, (n, p))| {
            json!({
                "id": i,
                "robot": v.robots[n.robot].id,
                "node_seq": n.node_seq,
                "stamp_ns": n.stamp_ns,
                "pose": p,
            })
        })
        .collect();
    let edges: Vec<Value> = v
        .edges
        .iter()
        .map(|e| {
            let mut edge = json!({
                "from": e.from,
                "to": e.to,
                "kind": e.kind,
                "measurement": e.measurement,
            });
            if q.information {
                edge["information"] = json!(e.information);
            }
            edge
        })
        .collect();
    let gps: Vec<Value> = v
        .gps
        .iter()
        .map(|g| {
            let p = v.poses[g.node];
            let antenna = p.transform_point([g.lever_arm_m.x, g.lever_arm_m.y]);
            json!({
                "node": g.node,
                "position_m": [g.position_m.x, g.position_m.y],
                "residual_m": [antenna[0] - g.position_m.x, antenna[1] - g.position_m.y],
            })
        })
        .collect();
    json_reply(json!({ "fleet": v.id, "nodes": nodes, "edges": edges, "gps": gps }))
}

async fn graph_g2o(State(api): State<Api>, Path(fleet): Path<String>) -> Reply {
    let v = view(&api, &fleet)?;
    let graph = slam::PoseGraph {
        poses: v.poses.clone(),
        edges: v.edges.clone(),
        gps: Vec::new(),
    };
    let ids: Vec<i64> = (0..v.poses.len() as i64).collect();
    Ok((
        [(header::CONTENT_TYPE, "text/plain")],
        graphio::posegraph::to_g2o(&graph, &ids),
    )
        .into_response())
}

async fn node_detail(State(api): State<Api>, Path((fleet, node)): Path<(String, usize)>) -> Reply {
    let v = view(&api, &fleet)?;
    let n = v
        .nodes
        .get(node)
        .ok_or_else(|| not_found(format!("no node {node} in fleet {fleet:?}")))?;
    let cloud = stored_cloud(&api, &fleet, node).await?.is_some();
    json_reply(json!({
        "cloud": cloud,
        "id": node,
        "robot": v.robots[n.robot].id,
        "node_seq": n.node_seq,
        "stamp_ns": n.stamp_ns,
        "pose": v.poses[node],
        "odometry": n.odometry,
        "gps": n.gps.iter().map(|g| json!({
            "position_m": [g.position_m.x, g.position_m.y],
            "lever_arm_m": [g.lever_arm_m.x, g.lever_arm_m.y],
        })).collect::<Vec<_>>(),
        "counts": n.counts.map(|c| json!({
            "points": c.points, "invalid": c.invalid, "ground": c.ground,
            "landmark": c.landmark, "overhang": c.overhang,
        })),
        "scan": { "bearing_rad": n.bearings_rad, "range_m": n.ranges_m },
        "edges": v.edges.iter().filter(|e| e.from == node || e.to == node)
            .map(|e| json!({"from": e.from, "to": e.to, "kind": e.kind})).collect::<Vec<_>>(),
    }))
}

#[derive(Deserialize)]
struct CovarianceQuery {
    /// Node ids, comma-separated.
    nodes: String,
}

/// Most nodes one covariance query may ask for.
const MAX_COVARIANCE_NODES: usize = 500;

/// Marginal covariances of nodes' (x, y, θ) at the current poses, 3 × 3 row-major, null for
/// the node that fixes the gauge. Each is the inverse of the normal matrix at that node.
async fn covariances(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<CovarianceQuery>,
) -> Reply {
    let v = view(&api, &fleet)?;
    let bad = |why: String| (StatusCode::BAD_REQUEST, why);
    let nodes: Vec<usize> = q
        .nodes
        .split(',')
        .filter(|s| !s.is_empty())
        .map(|s| s.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            bad(format!(
                "nodes={:?}: want node ids, comma-separated",
                q.nodes
            ))
        })?;
    if nodes.len() > MAX_COVARIANCE_NODES {
        return Err(bad(format!(
            "{} nodes asked for, at most {MAX_COVARIANCE_NODES} at once",
            nodes.len()
        )));
    }
    if let Some(n) = nodes.iter().find(|&&n| n >= v.poses.len()) {
        return Err(not_found(format!("no node {n} in fleet {fleet:?}")));
    }
    let marginals = api.marginals.clone();
    let covs = tokio::task::spawn_blocking(move || {
        let graph = slam::PoseGraph {
            poses: v.poses.clone(),
            edges: v.edges.clone(),
            gps: v.gps.clone(),
        };
        let mut all = marginals.lock().expect("marginals lock");
        let optimizer = all.entry(v.id.clone()).or_default();
        optimizer
            .marginal_covariances(&graph, &nodes)
            .map(|c| (nodes, c))
    })
    .await
    .map_err(internal)?
    .map_err(|e| (StatusCode::UNPROCESSABLE_ENTITY, e.to_string()))?;
    let (nodes, covs) = covs;
    let rows = |m: &slam::nalgebra::Matrix3<f64>| -> [[f64; 3]; 3] {
        std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
    };
    json_reply(json!({
        "fleet": fleet,
        "nodes": nodes,
        "covariance": covs.iter().map(|c| c.as_ref().map(rows)).collect::<Vec<_>>(),
    }))
}

/// A node's encoded cloud from the store (a blocking read, off the async threads).
async fn stored_cloud(
    api: &Api,
    fleet: &str,
    node: usize,
) -> Result<Option<Vec<u8>>, (StatusCode, String)> {
    let (store, fleet) = (api.store.clone(), fleet.to_owned());
    tokio::task::spawn_blocking(move || store.cloud(&fleet, node as u64))
        .await
        .map_err(internal)?
        .map_err(internal)
}

/// The node's segmented 3D cloud: points in the leveled frame of its scan (m, flat x, y, z),
/// the class of each (1 ground, 2 landmark, 3 overhang), counts per class, and how the robot
/// reduced it. Read from the store on request (no view holds clouds).
async fn node_cloud(State(api): State<Api>, Path((fleet, node)): Path<(String, usize)>) -> Reply {
    let v = view(&api, &fleet)?;
    let n = v
        .nodes
        .get(node)
        .ok_or_else(|| not_found(format!("no node {node} in fleet {fleet:?}")))?;
    let bytes = stored_cloud(&api, &fleet, node).await?.ok_or_else(|| {
        not_found(format!(
            "node {node} of fleet {fleet:?} has no 3D cloud: robot {} sent none (edge config \
             [cloud] keep = false, or a fixed 2D scanner)",
            v.robots[n.robot].id
        ))
    })?;
    let cloud = wire::v1::SegmentedCloud::decode(bytes.as_slice()).map_err(internal)?;
    // Checked when the node came; checked again, as the store is a file.
    let counts = wire::validate_cloud(&cloud).map_err(internal)?;
    let points: Vec<f64> = cloud.xyz_cm.iter().map(|&c| f64::from(c) / 100.0).collect();
    json_reply(json!({
        "fleet": v.id,
        "id": node,
        "robot": v.robots[n.robot].id,
        "node_seq": n.node_seq,
        "frame": "leveled",
        "points": points,
        "classes": cloud.classes,
        "counts": {"ground": counts.ground, "landmark": counts.landmark, "overhang": counts.overhang},
        "kept": cloud.classes.len(),
        "source_points": cloud.source_points,
        // The scan's points per class before the reduction, when the robot sent its counts.
        "source_counts": n.counts.map(|c| json!({
            "ground": c.ground, "landmark": c.landmark, "overhang": c.overhang,
        })),
        // The f32's shortest decimal (0.1, not 0.10000000149011612).
        "voxel_m": cloud.voxel_m.to_string().parse::<f64>().unwrap_or(0.0),
        "max_points": cloud.max_points,
    }))
}

/// The robot's node poses as a TUM trajectory (`t x y z qx qy qz qw`, t in s), as evo reads it.
async fn trajectory_tum(
    State(api): State<Api>,
    Path((fleet, robot)): Path<(String, String)>,
) -> Reply {
    let v = view(&api, &fleet)?;
    let r = v
        .robots
        .iter()
        .position(|r| r.id == robot)
        .ok_or_else(|| not_found(format!("no robot {robot:?} in fleet {fleet:?}")))?;
    let poses = v
        .nodes
        .iter()
        .zip(&v.poses)
        .filter(|(n, _)| n.robot == r)
        .map(|(n, p)| (n.stamp_ns as f64 * 1e-9, *p));
    let text = graphio::trajectory::to_tum(poses).map_err(internal)?;
    Ok(([(header::CONTENT_TYPE, "text/plain")], text).into_response())
}

fn internal(e: impl std::fmt::Display) -> (StatusCode, String) {
    (StatusCode::INTERNAL_SERVER_ERROR, e.to_string())
}

#[derive(Deserialize)]
struct GridQuery {
    /// Cell size (m); the grid's default when absent.
    resolution_m: Option<f64>,
    /// Only this part of the map: `min_x,min_y,max_x,max_y` (m).
    bbox: Option<String>,
    /// At most this many cells: coarser cells than `resolution_m` when the map needs more
    /// (without it, such a map is refused with 422).
    max_cells: Option<usize>,
}

impl GridQuery {
    fn params(&self) -> Result<slam::GridParams, (StatusCode, String)> {
        let mut params = slam::GridParams::default();
        if let Some(res) = self.resolution_m {
            params.resolution_m = res;
        }
        if let Some(n) = self.max_cells {
            // Never more than the server's own cap.
            params.max_cells = n.clamp(1, params.max_cells);
            params.coarsen_to_fit = true;
        }
        if let Some(bbox) = &self.bbox {
            let bad = || {
                (
                    StatusCode::BAD_REQUEST,
                    format!("bbox={bbox:?}: want min_x,min_y,max_x,max_y in metres"),
                )
            };
            let v: Vec<f64> = bbox
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad())?;
            let [x0, y0, x1, y1] = v[..] else {
                return Err(bad());
            };
            if !(x0 < x1 && y0 < y1) || v.iter().any(|x| !x.is_finite()) {
                return Err(bad());
            }
            params.window_m = Some([x0, y0, x1, y1]);
        }
        Ok(params)
    }
}

/// The occupancy grid of the fleet's leveled scans at their optimized poses (CPU work: off the
/// async threads).
async fn grid(
    v: Arc<FleetView>,
    q: GridQuery,
) -> Result<slam::OccupancyGrid, (StatusCode, String)> {
    let params = q.params()?;
    tokio::task::spawn_blocking(move || {
        let scans: Vec<slam::matching::Scan2> = v
            .nodes
            .iter()
            .map(|n| {
                let (b, r): (Vec<f32>, Vec<f32>) = n
                    .bearings_rad
                    .iter()
                    .zip(&n.ranges_m)
                    .filter(|(_, r)| **r > 0.0)
                    .map(|(b, r)| (*b, *r))
                    .unzip();
                slam::matching::Scan2::from_polar(&b, &r, f32::MAX).expect("pairs")
            })
            .collect();
        slam::OccupancyGrid::from_scans(v.poses.iter().copied().zip(&scans), &params)
            .map_err(|e| (StatusCode::UNPROCESSABLE_ENTITY, e.to_string()))
    })
    .await
    .map_err(internal)?
}

/// The fleet's grid in one of the formats users' tools read.
async fn grid_reply(
    api: &Api,
    fleet: &str,
    q: GridQuery,
    content_type: &'static str,
    encode: impl FnOnce(&slam::OccupancyGrid) -> Result<Vec<u8>, graphio::EncodeError>,
) -> Reply {
    let v = view(api, fleet)?;
    let nodes = v.poses.len();
    let g = grid(v, q).await?;
    let bytes = encode(&g).map_err(internal)?;
    // Where the picture lies, for clients that fetch it alone (the dashboard).
    let placement = grid_placement(&g, nodes).to_string();
    Ok((
        [
            (header::CONTENT_TYPE, content_type),
            (header::HeaderName::from_static("levelmap-grid"), &placement),
        ],
        bytes,
    )
        .into_response())
}

async fn map_png(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    grid_reply(&api, &fleet, q, "image/png", graphio::gridmap::to_png).await
}

async fn map_pgm(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    let pgm = graphio::gridmap::to_pgm;
    grid_reply(&api, &fleet, q, "image/x-portable-graymap", pgm).await
}

/// The map_server YAML beside `map.pgm` (same query, same grid).
async fn map_yaml(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    let yaml =
        |g: &slam::OccupancyGrid| Ok(graphio::gridmap::to_map_yaml(g, "map.pgm").into_bytes());
    grid_reply(&api, &fleet, q, "application/yaml", yaml).await
}

/// Nodes and per-robot trajectories in WGS84 (needs the map's GPS datum).
async fn map_geojson(State(api): State<Api>, Path(fleet): Path<String>) -> Reply {
    let v = view(&api, &fleet)?;
    let datum = v.datum.ok_or_else(|| {
        not_found(format!(
            "fleet {fleet:?} has no GPS datum yet: no fix, none configured"
        ))
    })?;
    let nodes: Vec<graphio::geojson::GeoNode> = v
        .nodes
        .iter()
        .zip(&v.poses)
        .enumerate()
        .map(|(i, (n, p))| graphio::geojson::GeoNode {
            robot: &v.robots[n.robot].id,
            node: i,
            seq: Some(n.node_seq),
            pose: *p,
        })
        .collect();
    let geojson = graphio::geojson::to_geojson(&datum, &nodes).map_err(internal)?;
    Ok((
        [(header::CONTENT_TYPE, "application/geo+json")],
        geojson.to_string(),
    )
        .into_response())
}

/// The grid's placement beside `map.png` (same query, same grid): cell size, the world position
/// of the lower-left corner of cell (0, 0), size in cells, and how many nodes it was made from.
async fn map_json(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    let v = view(&api, &fleet)?;
    let nodes = v.poses.len();
    let g = grid(v, q).await?;
    json_reply(grid_placement(&g, nodes))
}

fn grid_placement(g: &slam::OccupancyGrid, nodes: usize) -> Value {
    json!({
        "resolution_m": g.resolution_m,
        "origin_m": g.origin_m,
        "width": g.width,
        "height": g.height,
        "nodes": nodes,
    })
}

/// The dashboard (`web/`), compiled in: file name, content type, content.
const WEB_FILES: &[(&str, &str, &str)] = &[
    (
        "index.html",
        "text/html; charset=utf-8",
        include_str!("../../../web/index.html"),
    ),
    (
        "app.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/app.js"),
    ),
    (
        "cloud.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/cloud.js"),
    ),
    (
        "geo.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/geo.js"),
    ),
    (
        "panel.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/panel.js"),
    ),
    (
        "view.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/view.js"),
    ),
    (
        "style.css",
        "text/css; charset=utf-8",
        include_str!("../../../web/style.css"),
    ),
];

/// Set to a `web/` folder, the dashboard's files are read from it on every request instead
/// of the compiled-in copies (for working on the page without rebuilding the mapper).
pub const WEB_DIR_ENV: &str = "LEVELMAP_WEB_DIR";

fn web_reply(file: &str) -> Reply {
    if let Some(dir) = std::env::var_os(WEB_DIR_ENV) {
        return web_reply_from_disk(std::path::Path::new(&dir), file);
    }
    let (_, content_type, body) = WEB_FILES
        .iter()
        .find(|(name, _, _)| *name == file)
        .ok_or_else(|| not_found(format!("no file {file:?} in the dashboard")))?;
    Ok((
        [
            (header::CONTENT_TYPE, *content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body.to_string(),
    )
        .into_response())
}

/// A page file read from `dir` (any `.html`, `.js` or `.css` name in it, so a new module
/// works before it is compiled in).
fn web_reply_from_disk(dir: &std::path::Path, file: &str) -> Reply {
    let content_type = [
        (".html", "text/html; charset=utf-8"),
        (".js", "text/javascript; charset=utf-8"),
        (".css", "text/css; charset=utf-8"),
    ]
    .iter()
    .find(|(ext, _)| file.ends_with(ext))
    .map(|(_, t)| *t)
    .filter(|_| !file.contains(['/', '\\']) && !file.starts_with('.'))
    .ok_or_else(|| not_found(format!("no file {file:?} in the dashboard")))?;
    let body = std::fs::read_to_string(dir.join(file))
        .map_err(|e| not_found(format!("{WEB_DIR_ENV}: {file}: {e}")))?;
    Ok((
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response())
}

async fn web_index() -> Reply {
    web_reply("index.html")
}

async fn web_file(Path(file): Path<String>) -> Reply {
    web_reply(&file)
}

fn authorized(api: &Api, headers: &HeaderMap) -> Result<(), (StatusCode, String)> {
    let token = &api.shared.token;
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    if token.is_empty() {
        return Err((
            StatusCode::FORBIDDEN,
            "write routes are off: no token in the mapper's config".into(),
        ));
    }
    if given != Some(token.as_str()) {
        return Err((
            StatusCode::UNAUTHORIZED,
            "a valid bearer token is needed".into(),
        ));
    }
    Ok(())
}

/// Whether the request's bearer token would be taken by the write routes, asked without
/// writing (a page checks its stored token this way instead of meeting a 401).
async fn auth(State(api): State<Api>, headers: HeaderMap) -> Reply {
    let verdict = authorized(&api, &headers);
    json_reply(json!({
        "write_routes": !api.shared.token.is_empty(),
        "authorized": verdict.is_ok(),
        "reason": verdict.err().map(|(_, why)| why),
    }))
}

async fn optimize(State(api): State<Api>, Path(fleet): Path<String>, headers: HeaderMap) -> Reply {
    authorized(&api, &headers)?;
    let (reply, answer) = tokio::sync::oneshot::channel();
    api.work
        .send(Work::Optimize { fleet, reply })
        .map_err(|_| (StatusCode::SERVICE_UNAVAILABLE, "mapper stopping".into()))?;
    match answer.await {
        Ok(Ok(report)) => json_reply(report),
        Ok(Err(e)) => Err((StatusCode::NOT_FOUND, e)),
        Err(_) => Err((StatusCode::SERVICE_UNAVAILABLE, "mapper stopping".into())),
    }
}

/// Server-sent events: `node` (a node mapped) and `optimized` (poses changed), as JSON.
async fn events(State(api): State<Api>) -> impl IntoResponse {
    let rx = api.shared.events.subscribe();
    let stream = futures_util::stream::unfold(rx, |mut rx| async move {
        loop {
            match rx.recv().await {
                Ok(text) => {
                    return Some((
                        Ok::<_, std::convert::Infallible>(Event::default().data(text)),
                        rx,
                    ));
                }
                Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => continue,
                Err(tokio::sync::broadcast::error::RecvError::Closed) => return None,
            }
        }
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}

/// The JSON shape of a planar pose (`slam::Pose2`).
fn pose_schema() -> Value {
    json!({"type": "object", "properties": {
        "x": {"type": "number"}, "y": {"type": "number"}, "theta": {"type": "number"}}})
}

async fn openapi() -> Reply {
    let get_json = |summary: &str| json!({"get": {"summary": summary, "responses": {"200": {"description": "JSON"}, "404": {"description": "unknown fleet, robot or node"}}}});
    json_reply(json!({
        "openapi": "3.1.0",
        "info": {"title": "levelmap mapping server", "version": env!("CARGO_PKG_VERSION")},
        "components": {
            "schemas": {"Pose2": pose_schema()},
            "securitySchemes": {"bearer": {"type": "http", "scheme": "bearer"}}
        },
        "paths": {
            "/healthz": {"get": {"summary": "Liveness", "responses": {"200": {"description": "ok"}}}},
            "/metrics": {"get": {"summary": "Prometheus text: accepted, duplicate and rejected messages by reason", "responses": {"200": {"description": "text"}}}},
            "/api/v1/fleets": get_json("Fleets with a map"),
            "/api/v1/auth": {"get": {"summary": "Whether the bearer token sent would be taken by the write routes: write_routes (a token is configured), authorized, reason", "security": [{"bearer": []}], "responses": {"200": {"description": "JSON"}}}},
            "/api/v1/fleets/{fleet}/summary": get_json("Map summary: nodes, edges, closures, last optimization"),
            "/api/v1/fleets/{fleet}/robots": get_json("Robots with live map pose and last-seen time"),
            "/api/v1/fleets/{fleet}/robots/{robot}/pose": get_json("One robot's live map pose"),
            "/api/v1/fleets/{fleet}/robots/{robot}/trajectory.tum": {"get": {"summary": "The robot's node poses as TUM text (evo)", "responses": {"200": {"description": "text"}}}},
            "/api/v1/fleets/{fleet}/graph": get_json("Pose network: nodes, edges by kind (?information=true for information matrices), GPS residuals; ?columns=true gives one array per field, to the millimetre"),
            "/api/v1/fleets/{fleet}/map.png": {"get": {"summary": "Occupancy grid as PNG (free 254, occupied 0, unknown 205); ?resolution_m=, ?bbox=min_x,min_y,max_x,max_y (m) for a part, ?max_cells= for coarser cells instead of 422 on a big map. The Levelmap-Grid header holds map.json's placement", "responses": {"200": {"description": "image/png"}, "422": {"description": "too many cells, or the bbox misses the map"}}}},
            "/api/v1/fleets/{fleet}/map.pgm": {"get": {"summary": "Occupancy grid as PGM for ROS map_server (with map.yaml)", "responses": {"200": {"description": "image/x-portable-graymap"}}}},
            "/api/v1/fleets/{fleet}/map.yaml": {"get": {"summary": "map_server YAML for map.pgm", "responses": {"200": {"description": "application/yaml"}}}},
            "/api/v1/fleets/{fleet}/map.json": get_json("Where map.png lies: resolution_m, origin_m (lower-left corner of cell (0, 0)), width, height (cells), nodes"),
            "/api/v1/fleets/{fleet}/map.geojson": {"get": {"summary": "Nodes and trajectories in WGS84 (RFC 7946)", "responses": {"200": {"description": "application/geo+json"}, "404": {"description": "no datum yet"}}}},
            "/api/v1/fleets/{fleet}/graph.g2o": {"get": {"summary": "Pose network as g2o text", "responses": {"200": {"description": "text"}}}},
            "/api/v1/fleets/{fleet}/covariances": get_json("Marginal covariances of ?nodes=1,2,3 (at most 500): 3 × 3 over (x, y, θ), row-major; null for the node fixing the gauge"),
            "/api/v1/fleets/{fleet}/nodes/{node}": get_json("Node detail with its leveled scan and GPS fixes (oldest first: position and lever arm in the node frame, m)"),
            "/api/v1/fleets/{fleet}/nodes/{node}": get_json("Node detail with its leveled scan and GPS fixes (oldest first: position and lever arm in the node frame, m); cloud: whether …/cloud has its 3D cloud"),
            "/api/v1/fleets/{fleet}/nodes/{node}/cloud": {"get": {"summary": "The node's segmented 3D cloud as its robot reduced it: points (flat x, y, z in m, the leveled frame of its scan, to the cm), classes (one per point: 1 ground, 2 landmark, 3 overhang), counts per class, kept, source_points and source_counts (before the reduction), voxel_m, max_points",
                "responses": {"200": {"description": "JSON"}, "404": {"description": "unknown fleet or node, or the node has no cloud (its robot keeps none)"}}}},
            "/api/v1/fleets/{fleet}/optimize": {"post": {"summary": "Re-optimize the fleet's network now", "security": [{"bearer": []}],
                "responses": {"200": {"description": "the optimizer's report"}, "401": {"description": "no or wrong token"}, "403": {"description": "no token configured"}}}},
            "/api/v1/events": {"get": {"summary": "Server-sent events: node mapped, poses optimized (JSON data)", "responses": {"200": {"description": "text/event-stream"}}}}
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::WEB_FILES;

    /// Every page file in `web/` is compiled in, and nothing else is listed.
    #[test]
    fn web_files_match_the_folder() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../web");
        let mut on_disk: Vec<String> = std::fs::read_dir(dir)
            .expect("web/")
            .map(|e| e.expect("entry").file_name().into_string().expect("utf-8"))
            .filter(|n| [".html", ".js", ".css"].iter().any(|x| n.ends_with(x)))
            .collect();
        on_disk.sort();
        let mut listed: Vec<String> = WEB_FILES.iter().map(|(n, _, _)| n.to_string()).collect();
        listed.sort();
        assert_eq!(on_disk, listed);
    }
}
