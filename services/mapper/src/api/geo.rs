//! The map on the Earth, for GIS and web maps: the grid as a GeoTIFF (EPSG:4326) and as XYZ
//! web tiles (Web Mercator). Both need the fleet's GPS datum.

use super::map::GridQuery;
use super::{Api, ApiError, Reply};
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::IntoResponse;
use fleetmap::FleetView;
use graphio::webtiles::TileId;
use slam::geodesy::GeoDatum;
use std::sync::OnceLock;

/// The fleet's datum, or 404 naming why there is none.
pub(super) fn datum_of(v: &FleetView) -> Reply<GeoDatum> {
    v.datum.ok_or_else(|| {
        ApiError::NotFound(format!(
            "fleet {:?} has no GPS datum yet: no fix, none configured",
            v.id
        ))
    })
}

/// The occupancy grid as a GeoTIFF: one 8-bit band (0 occupied, 254 free, 205 unknown and
/// the no-data value), EPSG:4326, pixels as large as the grid's cells at the datum. GDAL,
/// rasterio and QGIS place it on the Earth.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/map.tif", tag = "map",
    params(("fleet" = String, Path, description = "Fleet id"), GridQuery),
    responses(
        (status = 200, description = "GeoTIFF", content_type = "image/tiff", body = Vec<u8>),
        (status = 400, description = "A bad bbox", body = String),
        (status = 404, description = "No such fleet, or no GPS datum yet", body = String),
        (status = 422, description = "Too many cells (use max_cells)", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn map_tif(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    Query(q): Query<GridQuery>,
) -> Reply {
    let v = api.view(&fleet)?;
    let datum = datum_of(&v)?;
    let params = q.params()?;
    let tif = api
        .limits
        .heavy(move || {
            let grid = v
                .grid(&params)
                .map_err(|e| ApiError::Unprocessable(e.to_string()))?;
            let raster = graphio::georaster::GeoRaster::from_grid(&grid, &datum)
                .map_err(|e| ApiError::Unprocessable(e.to_string()))?;
            Ok(raster.to_geotiff())
        })
        .await?;
    Ok(([(header::CONTENT_TYPE, "image/tiff")], tif).into_response())
}

/// The cell size a tile's grid is made at (`fleetmap::tiles::resolution_for_pixels`).
fn grid_resolution(tile: &TileId, datum: &GeoDatum) -> f64 {
    fleetmap::tiles::resolution_for_pixels(tile.pixel_m(datum.origin.latitude_deg))
}

/// The fleet's map as an XYZ web tile (`{z}/{x}/{y}.png`, Web Mercator, 256 px): Leaflet,
/// MapLibre and QGIS ("XYZ Tiles") show it over a base map. Occupied black, free translucent
/// white, unknown transparent. Cut from the same cached grid tiles as the windows around
/// robots, at the finest of 0.1 m × 2^k not finer than the tile's pixels; a tile outside the
/// map is transparent.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/tiles/{z}/{x}/{y}", tag = "map",
    params(
        ("fleet" = String, Path, description = "Fleet id"),
        ("z" = u32, Path, description = "Zoom level, 0 to 24"),
        ("x" = u32, Path, description = "Column, less than 2^z"),
        ("y" = String, Path, description = "Row, less than 2^z, with or without `.png` (`17.png`)"),
    ),
    responses(
        (status = 200, description = "PNG, grey and alpha", content_type = "image/png", body = Vec<u8>),
        (status = 400, description = "No such tile", body = String),
        (status = 404, description = "No such fleet, or no GPS datum yet", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn map_tile(
    State(api): State<Api>,
    Path((fleet, z, x, y)): Path<(String, String, String, String)>,
) -> Reply {
    let bad = || {
        ApiError::BadRequest(format!(
            "tiles/{z}/{x}/{y}: want numbers z/x/y or z/x/y.png"
        ))
    };
    let number = |s: &str| s.parse::<u32>().map_err(|_| bad());
    let tile = TileId::new(
        number(&z)?,
        number(&x)?,
        number(y.strip_suffix(".png").unwrap_or(&y))?,
    )
    .map_err(|e| ApiError::BadRequest(e.to_string()))?;
    let v = api.view(&fleet)?;
    let datum = datum_of(&v)?;
    let b = tile.enu_box(&datum);
    let apart = |m: [f64; 4]| b[2] < m[0] || b[0] > m[2] || b[3] < m[1] || b[1] > m[3];
    if fleetmap::tiles::reach_box(&v).is_none_or(apart) {
        static EMPTY: OnceLock<Vec<u8>> = OnceLock::new();
        let png = EMPTY.get_or_init(graphio::webtiles::empty_tile).clone();
        return Ok(([(header::CONTENT_TYPE, "image/png")], png).into_response());
    }
    let res = grid_resolution(&tile, &datum);
    let center = [0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])];
    let radius = 0.5 * (b[2] - b[0]).max(b[3] - b[1]) + res;
    let tiles = api.tiles.clone();
    let view = v.clone();
    let (png, stale) = api
        .limits
        .heavy(move || {
            let (grid, stale, _) = tiles
                .window(&view, center, radius, res)
                .map_err(|e| ApiError::Unprocessable(e.to_string()))?;
            let png = tile.render(&grid, &datum).map_err(ApiError::internal)?;
            Ok((png, stale))
        })
        .await?;
    super::window::refresh_stale(&api, v, stale);
    Ok(([(header::CONTENT_TYPE, "image/png")], png).into_response())
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam::geodesy::Geodetic;

    #[test]
    fn a_tiles_grid_is_not_finer_than_its_pixels() {
        let datum = GeoDatum {
            origin: Geodetic {
                latitude_deg: 52.39,
                longitude_deg: 9.71,
                height_m: 55.0,
            },
        };
        let at = |z| grid_resolution(&TileId::new(z, 0, 0).unwrap(), &datum);
        // At 52.39° a pixel is 0.047 m at z 21, 0.094 at z 20, 0.19 at z 19, 0.37 at z 18.
        assert_eq!([at(21), at(20), at(19), at(18)], [0.1, 0.1, 0.2, 0.4]);
    }
}
