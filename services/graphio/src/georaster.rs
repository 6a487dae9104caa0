//! The occupancy grid on the Earth: resampled onto a WGS84 latitude/longitude lattice and
//! written as a GeoTIFF (EPSG:4326) that GDAL, rasterio and QGIS read, with the trinary grey
//! levels of [`crate::gridmap`] and unknown as the raster's no-data value.
//!
//! The grid lies in the east-north frame of the map's datum (`slam::geodesy`), whose axes
//! are not the lattice's: each pixel takes the state of the cell under its centre, converted
//! exactly through the ellipsoid, and every occupied cell is then drawn on the pixel under
//! its own centre, so that no obstacle is lost where the two lattices do not line up. Web
//! tiles ([`crate::webtiles`]) are sampled the same way.

use crate::EncodeError;
use crate::gridmap::{FREE, OCCUPIED, UNKNOWN, check_grid};

mod tiff;
use slam::geodesy::{GeoDatum, Geodetic};
use slam::grid::{CellState, OccupancyGrid};
use slam::nalgebra::Vector3;

/// A grid on a north-up latitude/longitude lattice: pixel (col, row) covers longitudes
/// `west_deg + col·pixel_deg[0]` to the next, latitudes `north_deg − row·pixel_deg[1]` down
/// to the next.
#[derive(Clone, Debug, PartialEq)]
pub struct GeoRaster {
    /// Pixels across.
    pub width: usize,
    /// Pixels down.
    pub height: usize,
    /// Longitude of the raster's western edge (degrees).
    pub west_deg: f64,
    /// Latitude of its northern edge (degrees).
    pub north_deg: f64,
    /// A pixel's size: degrees of longitude, degrees of latitude.
    pub pixel_deg: [f64; 2],
    /// Grey levels, one a pixel, top row first: [`FREE`], [`OCCUPIED`], or [`UNKNOWN`] (the
    /// no-data value).
    pub pixels: Vec<u8>,
}

/// The grey level of a state (map_saver's, as in the PGM).
fn grey(state: CellState) -> u8 {
    match state {
        CellState::Free => FREE,
        CellState::Occupied => OCCUPIED,
        CellState::Unknown => UNKNOWN,
    }
}

/// The east-north point (m) of a WGS84 position at the datum's height.
pub(crate) fn enu_of(datum: &GeoDatum, latitude_deg: f64, longitude_deg: f64) -> [f64; 2] {
    let enu = datum.geodetic_to_enu(&Geodetic {
        latitude_deg,
        longitude_deg,
        height_m: datum.origin.height_m,
    });
    [enu.x, enu.y]
}

/// A lattice of `width × height` pixels, sampled from `grid`: `centre(col, row)` is a pixel's
/// centre as (latitude, longitude), `pixel_of(latitude, longitude)` the pixel holding a
/// position, if any. Unknown outside the grid.
pub(crate) fn sample(
    grid: &OccupancyGrid,
    datum: &GeoDatum,
    (width, height): (usize, usize),
    centre: impl Fn(usize, usize) -> (f64, f64),
    pixel_of: impl Fn(f64, f64) -> Option<(usize, usize)>,
) -> Vec<CellState> {
    let mut states = Vec::with_capacity(width * height);
    for row in 0..height {
        for col in 0..width {
            let (lat, lon) = centre(col, row);
            let state = grid
                .cell_at(enu_of(datum, lat, lon))
                .map_or(CellState::Unknown, |(ix, iy)| grid.state(ix, iy));
            states.push(state);
        }
    }
    for iy in 0..grid.height {
        for ix in 0..grid.width {
            if grid.state(ix, iy) != CellState::Occupied {
                continue;
            }
            let [e, n] = grid.cell_center(ix, iy);
            let g = datum.enu_to_geodetic(&Vector3::new(e, n, 0.0));
            if let Some((col, row)) = pixel_of(g.latitude_deg, g.longitude_deg) {
                states[row * width + col] = CellState::Occupied;
            }
        }
    }
    states
}

impl GeoRaster {
    /// `grid` (in the east-north frame of `datum`) on the latitude/longitude lattice that
    /// holds its four corners, with pixels as tall and as wide as its cells at the datum.
    pub fn from_grid(grid: &OccupancyGrid, datum: &GeoDatum) -> Result<GeoRaster, EncodeError> {
        check_grid(grid)?;
        let geodetic = |e: f64, n: f64| datum.enu_to_geodetic(&Vector3::new(e, n, 0.0));
        let [x0, y0] = grid.origin_m;
        let x1 = x0 + grid.width as f64 * grid.resolution_m;
        let y1 = y0 + grid.height as f64 * grid.resolution_m;
        let corners = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)].map(|(e, n)| geodetic(e, n));
        let [west, south, east, north] =
            corners
                .iter()
                .fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, g| {
                    let (lon, lat) = (g.longitude_deg, g.latitude_deg);
                    [b[0].min(lon), b[1].min(lat), b[2].max(lon), b[3].max(lat)]
                });
        // Degrees per metre at the datum, from a kilometre east and north.
        let o = datum.origin;
        let r = grid.resolution_m;
        let pixel_deg = [
            (geodetic(1000.0, 0.0).longitude_deg - o.longitude_deg) / 1000.0 * r,
            (geodetic(0.0, 1000.0).latitude_deg - o.latitude_deg) / 1000.0 * r,
        ];
        let width = ((east - west) / pixel_deg[0]).ceil().max(1.0) as usize;
        let height = ((north - south) / pixel_deg[1]).ceil().max(1.0) as usize;
        if width.saturating_mul(height) > 4 * grid.cells.len() + 16 {
            // Only a grid far from its datum (where the frame bends) could come here.
            return Err(EncodeError::GridTooLarge {
                width: grid.width,
                height: grid.height,
            });
        }
        let states = sample(
            grid,
            datum,
            (width, height),
            |col, row| {
                (
                    north - (row as f64 + 0.5) * pixel_deg[1],
                    west + (col as f64 + 0.5) * pixel_deg[0],
                )
            },
            |lat, lon| {
                let col = ((lon - west) / pixel_deg[0]).floor();
                let row = ((north - lat) / pixel_deg[1]).floor();
                (col >= 0.0 && row >= 0.0 && col < width as f64 && row < height as f64)
                    .then_some((col as usize, row as usize))
            },
        );
        Ok(GeoRaster {
            width,
            height,
            west_deg: west,
            north_deg: north,
            pixel_deg,
            pixels: states.into_iter().map(grey).collect(),
        })
    }

    /// The raster as a GeoTIFF: one 8-bit band, Deflate strips, EPSG:4326 (WGS84 latitude
    /// and longitude), the pixel-is-area transform from its western and northern edges, and
    /// [`UNKNOWN`] as GDAL's no-data value.
    pub fn to_geotiff(&self) -> Vec<u8> {
        tiff::geotiff_epsg4326(self)
    }
}

/// What the tests of the map products on the Earth share.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::*;

    /// A datum near Hannover (the simulated park's).
    pub(crate) fn datum() -> GeoDatum {
        GeoDatum {
            origin: Geodetic {
                latitude_deg: 52.39,
                longitude_deg: 9.71,
                height_m: 55.0,
            },
        }
    }

    /// A free grid of 0.1 m cells, `size` cells from `origin_m`, with one occupied cell at
    /// `post` (m).
    pub(crate) fn free_grid_with_post(
        origin_m: [f64; 2],
        (width, height): (usize, usize),
        post: [f64; 2],
    ) -> OccupancyGrid {
        let mut grid = OccupancyGrid {
            resolution_m: 0.1,
            origin_m,
            width,
            height,
            cells: vec![0; width * height],
            occupied_percent: 65,
            free_percent: 35,
        };
        let (ix, iy) = grid.cell_at(post).expect("the post is on the grid");
        grid.cells[iy * width + ix] = 100;
        grid
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use super::fixtures::{datum, free_grid_with_post};

    /// A free 60 m × 40 m grid at 0.1 m with one occupied cell at (`e`, `n`).
    fn grid_with_post(e: f64, n: f64) -> OccupancyGrid {
        free_grid_with_post([-20.0, -15.0], (600, 400), [e, n])
    }

    #[test]
    fn a_post_lands_on_its_wgs84_place() {
        let d = datum();
        let (e, n) = (31.23, -7.48);
        let raster = GeoRaster::from_grid(&grid_with_post(e, n), &d).unwrap();
        // The lattice is as fine as the grid: about 600 × 400 pixels.
        assert!((600..=603).contains(&raster.width), "{}", raster.width);
        assert!((400..=403).contains(&raster.height), "{}", raster.height);
        let occupied: Vec<usize> = (0..raster.pixels.len())
            .filter(|&i| raster.pixels[i] == OCCUPIED)
            .collect();
        assert!(!occupied.is_empty() && occupied.len() <= 2, "{occupied:?}");
        let truth = d.enu_to_geodetic(&Vector3::new(e, n, 0.0));
        for i in occupied {
            let (col, row) = (i % raster.width, i / raster.width);
            let lon = raster.west_deg + (col as f64 + 0.5) * raster.pixel_deg[0];
            let lat = raster.north_deg - (row as f64 + 0.5) * raster.pixel_deg[1];
            let [pe, pn] = enu_of(&d, lat, lon);
            let [te, tn] = enu_of(&d, truth.latitude_deg, truth.longitude_deg);
            assert!(
                (pe - te).hypot(pn - tn) < 0.15,
                "{pe} {pn} against {te} {tn}"
            );
        }
        // Free inside, unknown (no data) only at the margin the lattice adds.
        let free = raster.pixels.iter().filter(|&&p| p == FREE).count();
        assert!(free as f64 > 0.98 * 600.0 * 400.0, "{free}");
    }

    #[test]
    fn a_broken_grid_is_an_error_not_a_panic() {
        let mut grid = grid_with_post(0.0, 0.0);
        grid.cells.pop();
        assert!(GeoRaster::from_grid(&grid, &datum()).is_err());
        let mut grid = grid_with_post(0.0, 0.0);
        grid.resolution_m = f64::NAN;
        assert!(GeoRaster::from_grid(&grid, &datum()).is_err());
    }
}
