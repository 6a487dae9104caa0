//! The map products: the occupancy grid (PNG, Nav2's PGM + YAML, its placement as JSON) and
//! the nodes and trajectories as GeoJSON; the grid on the Earth is `geo`'s.

use super::{Api, ApiError, Reply};
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::IntoResponse;
use fleetmap::FleetView;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(crate) struct GridQuery {
    /// Cell size (m); the grid's default when absent.
    resolution_m: Option<f64>,
    /// Only this part of the map: `min_x,min_y,max_x,max_y` (m).
    bbox: Option<String>,
    /// At most this many cells: coarser cells than `resolution_m` when the map needs more
    /// (without it, such a map is refused with 422).
    max_cells: Option<usize>,
    /// How map_server is to read the picture (`map.png` and `map.yaml`): `trinary` (the
    /// default: free, occupied, unknown) or `scale` (each known cell's evidence as its grey,
    /// unknown transparent, `mode: scale` in the YAML).
    mode: Option<String>,
}

/// The map_server mode a query asks for (`mode=`): trinary when absent.
pub(super) fn map_mode(mode: Option<&str>) -> Reply<graphio::gridmap::MapMode> {
    mode.map_or(Ok(graphio::gridmap::MapMode::Trinary), str::parse)
        .map_err(ApiError::BadRequest)
}

impl GridQuery {
    /// The map_server mode asked for.
    fn mode(&self) -> Reply<graphio::gridmap::MapMode> {
        map_mode(self.mode.as_deref())
    }

    pub(super) fn params(&self) -> Reply<slam::GridParams> {
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
                ApiError::BadRequest(format!(
                    "bbox={bbox:?}: want min_x,min_y,max_x,max_y in metres"
                ))
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

/// Where a grid lies: cell size, the world position of the lower-left corner of cell (0, 0),
/// size in cells, and how many nodes it was made from.
#[derive(Serialize, ToSchema)]
pub(super) struct GridPlacement {
    resolution_m: f64,
    origin_m: [f64; 2],
    width: usize,
    height: usize,
    nodes: usize,
}

impl GridPlacement {
    pub(super) fn of(g: &slam::OccupancyGrid, nodes: usize) -> GridPlacement {
        GridPlacement {
            resolution_m: g.resolution_m,
            origin_m: g.origin_m,
            width: g.width,
            height: g.height,
            nodes,
        }
    }
}

/// The occupancy grid of the fleet's leveled scans at their optimized poses.
fn grid(v: &FleetView, params: &slam::GridParams) -> Reply<slam::OccupancyGrid> {
    v.grid(params)
        .map_err(|e| ApiError::Unprocessable(e.to_string()))
}

/// How a grid is written out.
type Encode = fn(&slam::OccupancyGrid) -> Result<Vec<u8>, graphio::EncodeError>;

/// The fleet's grid in one of the formats users' tools read, its placement in the
/// `Levelmap-Grid` header (for clients that fetch the picture alone: the dashboard). Made and
/// encoded as heavy work.
async fn grid_reply(
    api: &Api,
    fleet: &str,
    q: GridQuery,
    content_type: &'static str,
    encode: Encode,
) -> Reply {
    let v = api.view(fleet)?;
    let params = q.params()?;
    let (bytes, placement) = api
        .limits
        .heavy(move || {
            let g = grid(&v, &params)?;
            let bytes = encode(&g).map_err(ApiError::internal)?;
            let placement = GridPlacement::of(&g, v.poses.len());
            Ok((
                bytes,
                serde_json::to_string(&placement).expect("serializes"),
            ))
        })
        .await?;
    Ok((
        [
            (header::CONTENT_TYPE, content_type),
            (header::HeaderName::from_static("levelmap-grid"), &placement),
        ],
        bytes,
    )
        .into_response())
}

/// The occupancy grid as a PNG picture (white free, black occupied, grey unknown; with
/// `mode=scale`, map_server's scale mode: the evidence as grey, unknown transparent).
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/map.png", tag = "map",
    params(("fleet" = String, Path, description = "Fleet id"), GridQuery),
    responses(
        (status = 200, description = "PNG; its placement in the Levelmap-Grid header (JSON)", content_type = "image/png", body = Vec<u8>),
        (status = 400, description = "A bad bbox", body = String),
        (status = 404, description = "No such fleet", body = String),
        (status = 422, description = "Too many cells (use max_cells)", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn map_png(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    let png: Encode = match q.mode()? {
        graphio::gridmap::MapMode::Trinary => graphio::gridmap::to_png,
        graphio::gridmap::MapMode::Scale => graphio::gridmap::to_png_scale,
    };
    grid_reply(&api, &fleet, q, "image/png", png).await
}

/// The occupancy grid as Nav2's map_server PGM.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/map.pgm", tag = "map",
    params(("fleet" = String, Path, description = "Fleet id"), GridQuery),
    responses(
        (status = 200, description = "PGM (P5)", content_type = "image/x-portable-graymap", body = Vec<u8>),
        (status = 404, description = "No such fleet", body = String),
        (status = 422, description = "Too many cells", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn map_pgm(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    let pgm: Encode = graphio::gridmap::to_pgm;
    grid_reply(&api, &fleet, q, "image/x-portable-graymap", pgm).await
}

/// The map_server YAML beside `map.pgm` (same query, same grid); with `mode=scale`, beside
/// `map.png?mode=scale`.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/map.yaml", tag = "map",
    params(("fleet" = String, Path, description = "Fleet id"), GridQuery),
    responses(
        (status = 200, description = "map_server YAML", content_type = "application/yaml", body = String),
        (status = 404, description = "No such fleet", body = String),
        (status = 422, description = "Too many cells", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn map_yaml(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    // In scale mode the picture is the PNG: a PGM has no alpha for the unknown cells.
    let yaml: Encode = match q.mode()? {
        graphio::gridmap::MapMode::Trinary => {
            |g| Ok(graphio::gridmap::to_map_yaml(g, "map.pgm").into_bytes())
        }
        graphio::gridmap::MapMode::Scale => |g| {
            let mode = graphio::gridmap::MapMode::Scale;
            Ok(graphio::gridmap::to_map_yaml_with(g, "map.png", mode).into_bytes())
        },
    };
    grid_reply(&api, &fleet, q, "application/yaml", yaml).await
}

/// The grid's placement beside `map.png` (same query, same grid).
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/map.json", tag = "map",
    params(("fleet" = String, Path, description = "Fleet id"), GridQuery),
    responses(
        (status = 200, description = "Where the grid lies", body = GridPlacement),
        (status = 404, description = "No such fleet", body = String),
        (status = 422, description = "Too many cells", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn map_json(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply<Json<GridPlacement>> {
    let v = api.view(&fleet)?;
    let params = q.params()?;
    let placement = api
        .limits
        .heavy(move || Ok(GridPlacement::of(&grid(&v, &params)?, v.poses.len())))
        .await?;
    Ok(Json(placement))
}

/// Nodes and per-robot trajectories in WGS84 (needs the map's GPS datum).
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/map.geojson", tag = "map",
    params(("fleet" = String, Path, description = "Fleet id")),
    responses(
        (status = 200, description = "A GeoJSON FeatureCollection", content_type = "application/geo+json", body = Object),
        (status = 404, description = "No such fleet, or no GPS datum yet", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn map_geojson(State(api): State<Api>, Path(fleet): Path<String>) -> Reply {
    let v = api.view(&fleet)?;
    let datum = super::geo::datum_of(&v)?;
    let geojson = api
        .limits
        .heavy(move || {
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
            let geojson =
                graphio::geojson::to_geojson(&datum, &nodes).map_err(ApiError::internal)?;
            Ok(geojson.to_string())
        })
        .await?;
    let content_type = [(header::CONTENT_TYPE, "application/geo+json")];
    Ok((content_type, geojson).into_response())
}
