//! The map around a robot, cut from cached tiles ([`fleetmap::tiles`]).

use super::map::GridPlacement;
use super::{Api, ApiError, Reply};
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::IntoResponse;
use fleetmap::tiles::TileKey;
use serde::Deserialize;
use utoipa::IntoParams;

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct WindowQuery {
    /// Half the window's edge (m): 20 when absent, at most 200.
    radius_m: Option<f64>,
    /// Cell size (m): 0.1 when absent, 0.02 to 2.
    resolution_m: Option<f64>,
    /// As `map.png`'s: `trinary` (the default) or `scale` (each known cell's evidence as its
    /// grey, unknown transparent: the colours of the dashboard's map and follow view).
    mode: Option<String>,
}

/// Cells of a window, at most (2000 × 2000).
const MAX_WINDOW_CELLS: f64 = 4e6;

/// The occupancy grid of the square around the robot's live map pose, as a PNG (white free,
/// black occupied, grey unknown; or in map_server's scale mode), cut from tiles the mapper
/// keeps: the first window over a part of the map makes its tiles, the next ones cost a few
/// milliseconds; a tile made before the map last changed is served and made again in the background (at most every second).
/// Its placement in the `Levelmap-Grid` header (as `map.json`); the tiles it took in
/// `Levelmap-Tiles` (`{"made", "cached", "stale"}`).
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/robots/{robot}/map.png", tag = "map",
    params(("fleet" = String, Path, description = "Fleet id"), ("robot" = String, Path, description = "Robot id"), WindowQuery),
    responses(
        (status = 200, description = "PNG; its placement in the Levelmap-Grid header (JSON)", content_type = "image/png", body = Vec<u8>),
        (status = 400, description = "A radius, resolution or mode out of range", body = String),
        (status = 404, description = "No such fleet or robot", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn robot_map_png(
    State(api): State<Api>,
    Path((fleet, id)): Path<(String, String)>,
    Query(q): Query<WindowQuery>,
) -> Reply {
    let v = api.view(&fleet)?;
    let robot = super::fleets::robot(&v, &id)?;
    let center = super::fleets::robot_state(&api, &v, robot).pose;
    let radius = q.radius_m.unwrap_or(20.0);
    let res = q.resolution_m.unwrap_or(0.1);
    let in_range = radius > 0.0 && radius <= 200.0 && (0.02..=2.0).contains(&res);
    if !in_range {
        return Err(ApiError::BadRequest(format!(
            "radius_m={radius}, resolution_m={res}: want 0 < radius_m ≤ 200 and 0.02 ≤ resolution_m ≤ 2"
        )));
    }
    if (2.0 * radius / res).powi(2) > MAX_WINDOW_CELLS {
        return Err(ApiError::BadRequest(format!(
            "a window of {radius} m at {res} m has more than {MAX_WINDOW_CELLS} cells"
        )));
    }
    let mode = super::map::map_mode(q.mode.as_deref())?;
    let tiles = api.tiles.clone();
    let view = v.clone();
    let (bytes, placement, stats, stale) = api
        .limits
        .heavy(move || {
            let (grid, stale, stats) = tiles
                .window(&view, [center.x, center.y], radius, res)
                .map_err(|e| ApiError::Unprocessable(e.to_string()))?;
            let fast = graphio::gridmap::PngSpeed::Fast;
            let bytes = match mode {
                graphio::gridmap::MapMode::Trinary => graphio::gridmap::to_png_with(&grid, fast),
                graphio::gridmap::MapMode::Scale => {
                    graphio::gridmap::to_png_scale_with(&grid, fast)
                }
            }
            .map_err(ApiError::internal)?;
            let placement = serde_json::to_string(&GridPlacement::of(&grid, view.poses.len()))
                .expect("serializes");
            Ok((bytes, placement, stats, stale))
        })
        .await?;
    refresh_stale(&api, v, stale);
    let stats = format!(
        r#"{{"made":{},"cached":{},"stale":{}}}"#,
        stats.made, stats.cached, stats.stale
    );
    Ok((
        [
            (header::CONTENT_TYPE, "image/png".to_owned()),
            (header::HeaderName::from_static("levelmap-grid"), placement),
            (header::HeaderName::from_static("levelmap-tiles"), stats),
        ],
        bytes,
    )
        .into_response())
}

/// Makes the `stale` tiles of `view` again in the background (a served window or web tile
/// took them as they were).
pub(super) fn refresh_stale(
    api: &Api,
    view: std::sync::Arc<fleetmap::FleetView>,
    stale: Vec<TileKey>,
) {
    if stale.is_empty() {
        return;
    }
    let tiles = api.tiles.clone();
    tokio::task::spawn_blocking(move || {
        for key in &stale {
            if let Err(e) = tiles.refresh(&view, key) {
                tracing::warn!(fleet = %key.fleet, "tile not made again: {e}");
            }
        }
    });
}
