//! The occupancy grid as XYZ web tiles: 256 × 256 PNG squares of the Web Mercator plane
//! (EPSG:3857, the tiling of OpenStreetMap, Leaflet, MapLibre and QGIS's "XYZ Tiles"), tile
//! (0, 0) at the north-west corner of zoom level `z`. Pixels are sampled from the grid as the
//! GeoTIFF's are ([`crate::georaster`]); unknown is transparent and free space translucent,
//! so that a base map shows under the map.

use crate::EncodeError;
use crate::georaster::{enu_of, sample};
use crate::gridmap::check_grid;
use slam::geodesy::GeoDatum;
use slam::grid::{CellState, OccupancyGrid};
use std::f64::consts::PI;

/// Pixels along a tile's edge.
pub const TILE_PX: usize = 256;
/// The deepest zoom level served: a pixel is then about 6 mm at the equator.
pub const MAX_ZOOM: u8 = 24;
/// Web Mercator's sphere radius (m), the WGS84 semi-major axis.
const EARTH_RADIUS_M: f64 = 6_378_137.0;
/// Grey and alpha of a free pixel: white, mostly opaque.
const FREE_GA: [u8; 2] = [255, 170];
/// Grey and alpha of an occupied pixel: black, opaque.
const OCCUPIED_GA: [u8; 2] = [0, 255];

/// One tile of the XYZ scheme.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TileId {
    /// Zoom level: 2^z tiles across the world.
    pub z: u8,
    /// Column, from the antimeridian eastward.
    pub x: u32,
    /// Row, from the north (85.05° N) southward.
    pub y: u32,
}

/// A tile that does not exist.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("no tile {z}/{x}/{y}: zoom must be at most {MAX_ZOOM}, x and y less than 2^zoom")]
pub struct NoSuchTile {
    z: u32,
    x: u32,
    y: u32,
}

impl TileId {
    /// The tile `z/x/y`, if the scheme has it.
    pub fn new(z: u32, x: u32, y: u32) -> Result<TileId, NoSuchTile> {
        let err = NoSuchTile { z, x, y };
        if z > u32::from(MAX_ZOOM) {
            return Err(err);
        }
        let n = 1u64 << z;
        if u64::from(x) >= n || u64::from(y) >= n {
            return Err(err);
        }
        Ok(TileId { z: z as u8, x, y })
    }

    /// Pixels across the world at this zoom.
    fn world_px(&self) -> f64 {
        (TILE_PX as f64) * (1u64 << self.z) as f64
    }

    /// (latitude, longitude) in degrees of a point `px` pixels right of and below the
    /// tile's north-west corner.
    pub fn geodetic_at(&self, px: [f64; 2]) -> (f64, f64) {
        let world = self.world_px();
        let gx = f64::from(self.x) * TILE_PX as f64 + px[0];
        let gy = f64::from(self.y) * TILE_PX as f64 + px[1];
        let lon = gx / world * 360.0 - 180.0;
        let lat = (PI * (1.0 - 2.0 * gy / world)).sinh().atan().to_degrees();
        (lat, lon)
    }

    /// Pixels right of and below the tile's north-west corner of a WGS84 position.
    pub fn pixel_at(&self, latitude_deg: f64, longitude_deg: f64) -> [f64; 2] {
        let world = self.world_px();
        let lat = latitude_deg.to_radians();
        let gx = (longitude_deg + 180.0) / 360.0 * world;
        let gy = (1.0 - (lat.tan() + 1.0 / lat.cos()).ln() / PI) / 2.0 * world;
        [
            gx - f64::from(self.x) * TILE_PX as f64,
            gy - f64::from(self.y) * TILE_PX as f64,
        ]
    }

    /// The ground size of a pixel at `latitude_deg` (m).
    pub fn pixel_m(&self, latitude_deg: f64) -> f64 {
        2.0 * PI * EARTH_RADIUS_M * latitude_deg.to_radians().cos() / self.world_px()
    }

    /// The east-north box (m) in the frame of `datum` that holds the tile:
    /// `[min_x, min_y, max_x, max_y]`.
    pub fn enu_box(&self, datum: &GeoDatum) -> [f64; 4] {
        let edge = TILE_PX as f64;
        let mut b = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
        // Corners and edge midpoints: the tile's edges bend a little in the datum's frame.
        for px in [0.0, 0.5 * edge, edge] {
            for py in [0.0, 0.5 * edge, edge] {
                let (lat, lon) = self.geodetic_at([px, py]);
                let [e, n] = enu_of(datum, lat, lon);
                b = [b[0].min(e), b[1].min(n), b[2].max(e), b[3].max(n)];
            }
        }
        b
    }

    /// The tile drawn from `grid` (in the east-north frame of `datum`), as a grey-and-alpha
    /// PNG: occupied black, free translucent white, unknown transparent.
    pub fn render(&self, grid: &OccupancyGrid, datum: &GeoDatum) -> Result<Vec<u8>, EncodeError> {
        check_grid(grid)?;
        let states = sample(
            grid,
            datum,
            (TILE_PX, TILE_PX),
            |col, row| self.geodetic_at([col as f64 + 0.5, row as f64 + 0.5]),
            |lat, lon| {
                let [px, py] = self.pixel_at(lat, lon);
                let inside =
                    (0.0..TILE_PX as f64).contains(&px) && (0.0..TILE_PX as f64).contains(&py);
                inside.then_some((px as usize, py as usize))
            },
        );
        encode(&states)
    }
}

/// A tile with nothing on it (outside every map).
pub fn empty_tile() -> Vec<u8> {
    encode(&vec![CellState::Unknown; TILE_PX * TILE_PX]).expect("a tile encodes")
}

fn encode(states: &[CellState]) -> Result<Vec<u8>, EncodeError> {
    let pixels: Vec<u8> = states
        .iter()
        .flat_map(|s| match s {
            CellState::Free => FREE_GA,
            CellState::Occupied => OCCUPIED_GA,
            CellState::Unknown => [0, 0],
        })
        .collect();
    let mut out = Vec::with_capacity(pixels.len() / 8 + 64);
    let mut encoder = png::Encoder::new(&mut out, TILE_PX as u32, TILE_PX as u32);
    encoder.set_color(png::ColorType::GrayscaleAlpha);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    encoder
        .write_header()
        .and_then(|mut writer| writer.write_image_data(&pixels))
        .map_err(|e| EncodeError::Png(e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam::nalgebra::Vector3;

    #[test]
    fn the_scheme_matches_openstreetmaps_tiles() {
        // z 0 is the whole world; London's centre (51.5074° N, 0.1278° W) is on tile
        // 10/511/340, as on openstreetmap.org.
        let world = TileId::new(0, 0, 0).unwrap();
        let (lat, lon) = world.geodetic_at([0.0, 0.0]);
        assert!((lat - 85.051_128_78).abs() < 1e-6 && lon == -180.0);
        let t = TileId::new(10, 511, 340).unwrap();
        let [px, py] = t.pixel_at(51.5074, -0.1278);
        assert!(
            (0.0..256.0).contains(&px) && (0.0..256.0).contains(&py),
            "{px} {py}"
        );
        let back = t.geodetic_at([px, py]);
        assert!((back.0 - 51.5074).abs() < 1e-9 && (back.1 + 0.1278).abs() < 1e-9);
        assert!(TileId::new(25, 0, 0).is_err() && TileId::new(3, 8, 0).is_err());
        // 2.39 m at z 16 at the equator, cos(52.37°) of it in Hannover.
        assert!((TileId::new(16, 0, 0).unwrap().pixel_m(0.0) - 2.3887).abs() < 1e-3);
    }

    #[test]
    fn a_post_is_drawn_where_it_stands() {
        let datum = crate::georaster::fixtures::datum();
        let post = [3.05, 4.05];
        let grid =
            crate::georaster::fixtures::free_grid_with_post([-20.0, -20.0], (400, 400), post);
        let g = datum.enu_to_geodetic(&Vector3::new(post[0], post[1], 0.0));
        for z in [19u32, 21] {
            let n = f64::from(1u32 << z);
            let x = ((g.longitude_deg + 180.0) / 360.0 * n) as u32;
            let lat = g.latitude_deg.to_radians();
            let y = ((1.0 - (lat.tan() + 1.0 / lat.cos()).ln() / PI) / 2.0 * n) as u32;
            let tile = TileId::new(z, x, y).unwrap();
            let png = tile.render(&grid, &datum).unwrap();
            let mut reader = png::Decoder::new(std::io::Cursor::new(png))
                .read_info()
                .unwrap();
            let mut buf = vec![0; reader.output_buffer_size().unwrap()];
            reader.next_frame(&mut buf).unwrap();
            let dark: Vec<[f64; 2]> = (0..TILE_PX * TILE_PX)
                .filter(|&i| buf[2 * i + 1] == 255)
                .map(|i| [(i % TILE_PX) as f64 + 0.5, (i / TILE_PX) as f64 + 0.5])
                .collect();
            assert!(!dark.is_empty(), "z {z}: the post is drawn");
            for px in dark {
                let (lat, lon) = tile.geodetic_at(px);
                let [e, n] = enu_of(&datum, lat, lon);
                let off = (e - post[0]).hypot(n - post[1]);
                assert!(off < 0.1 + tile.pixel_m(52.39), "z {z}: {off} m off");
            }
        }
    }
}
