//! The map around a point, from cached tiles: a fleet's grid cut into squares of
//! [`TILE_CELLS`]² cells on a fixed lattice (cell (0, 0) of tile (0, 0) at the map's origin),
//! each made once from the scans that reach it and kept, so that a window (`GET
//! …/robots/{robot}/map.png`) is cut from a few tiles in milliseconds however large the map.
//! A tile made before the map last changed is still served (its age says so) and is made again
//! in the background, at most every [`REFRESH`]. A tile's cells are the whole map's at the
//! same resolution: the same scans, in the same order, ray cast into a window.

use crate::view::FleetView;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Cells along a tile's edge.
pub const TILE_CELLS: usize = 256;
/// Tiles kept, at most (64 KiB each): the least recently used go first.
pub const MAX_TILES: usize = 512;
/// A stale tile is made again at most this often.
pub const REFRESH: Duration = Duration::from_secs(1);

/// A tile: which fleet, cell size (µm) and lattice position.
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
pub struct TileKey {
    /// The fleet whose map it cuts.
    pub fleet: String,
    resolution_um: u64,
    i: i64,
    j: i64,
}

/// A made tile.
#[derive(Debug)]
pub struct Tile {
    /// Row-major from the tile's lowest row, −1 unknown, else 0–100.
    cells: Vec<i8>,
    /// The view it was made from (`FleetView::updated_ns`).
    view_ns: u64,
    made: Instant,
    occupied_percent: i8,
    free_percent: i8,
}

#[derive(Debug)]
struct Entry {
    tile: Arc<Tile>,
    used: Instant,
    refreshing: bool,
}

/// The tiles of every fleet.
#[derive(Debug, Default)]
pub struct TileCache {
    entries: Mutex<HashMap<TileKey, Entry>>,
}

/// What a window took: the tiles made for it, and the oldest tile's age.
#[derive(Clone, Copy, Debug, Default)]
pub struct WindowStats {
    /// Tiles made now (a cold cache).
    pub made: usize,
    /// Tiles served from the cache.
    pub cached: usize,
    /// Stale tiles served (made again in the background).
    pub stale: usize,
}

/// The cell size of the grid behind a picture whose pixels are `pixel_m` wide (a web tile at
/// some zoom): the finest of the map's cell × 2^k that is not finer than a pixel, so the
/// pictures of one scale share their tiles, and an obstacle is a cell at any scale.
pub fn resolution_for_pixels(pixel_m: f64) -> f64 {
    let finest = slam::GridParams::default().resolution_m;
    let k = (pixel_m / finest).log2().ceil().max(0.0);
    finest * k.exp2()
}

/// The box the scans of `view` can reach, `[min_x, min_y, max_x, max_y]` (m): their poses
/// grown by the grid's range. None before the first node.
pub fn reach_box(view: &FleetView) -> Option<[f64; 4]> {
    let reach = slam::GridParams::default().max_range_m;
    let first = view.poses.first()?;
    let b = view
        .poses
        .iter()
        .fold([first.x, first.y, first.x, first.y], |b, p| {
            [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)]
        });
    Some([b[0] - reach, b[1] - reach, b[2] + reach, b[3] + reach])
}

fn grid_params(resolution_m: f64, window_m: [f64; 4]) -> slam::GridParams {
    slam::GridParams {
        resolution_m,
        window_m: Some(window_m),
        ..slam::GridParams::default()
    }
}

/// Makes one tile from the scans that can reach it.
fn make_tile(view: &FleetView, key: &TileKey) -> Result<Tile, slam::GridError> {
    let res = key.resolution_um as f64 * 1e-6;
    let edge = TILE_CELLS as f64 * res;
    let (x0, y0) = (key.i as f64 * edge, key.j as f64 * edge);
    let params = grid_params(res, [x0, y0, x0 + edge, y0 + edge]);
    // Scans farther than their range from the tile cannot reach it.
    let reach = params.max_range_m + edge;
    let (cx, cy) = (x0 + 0.5 * edge, y0 + 0.5 * edge);
    let near: Vec<usize> = (0..view.poses.len())
        .filter(|&k| {
            let p = view.poses[k];
            (p.x - cx).abs() <= reach && (p.y - cy).abs() <= reach
        })
        .collect();
    let mut cells = vec![-1i8; TILE_CELLS * TILE_CELLS];
    let defaults = slam::GridParams::default();
    let (mut occupied_percent, mut free_percent) = (
        (defaults.occupied_threshold * 100.0).round() as i8,
        (defaults.free_threshold * 100.0).round() as i8,
    );
    if !near.is_empty() {
        let grid = slam::OccupancyGrid::from_fans_made_again(
            || near.iter().map(|&k| (view.poses[k], view.nodes[k].fan())),
            &params,
        )?;
        (occupied_percent, free_percent) = (grid.occupied_percent, grid.free_percent);
        // The window's grid has a margin and may be smaller than the tile: cells by their
        // lattice index.
        let gx = (grid.origin_m[0] / res).round() as i64 - (x0 / res).round() as i64;
        let gy = (grid.origin_m[1] / res).round() as i64 - (y0 / res).round() as i64;
        for row in 0..grid.height {
            let ty = gy + row as i64;
            if !(0..TILE_CELLS as i64).contains(&ty) {
                continue;
            }
            for col in 0..grid.width {
                let tx = gx + col as i64;
                if (0..TILE_CELLS as i64).contains(&tx) {
                    cells[ty as usize * TILE_CELLS + tx as usize] =
                        grid.cells[row * grid.width + col];
                }
            }
        }
    }
    Ok(Tile {
        cells,
        view_ns: view.updated_ns,
        made: Instant::now(),
        occupied_percent,
        free_percent,
    })
}

impl TileCache {
    /// The tile at `key`: cached, or made now. The second value: a stale tile to make again.
    fn tile(
        &self,
        view: &FleetView,
        key: &TileKey,
        stats: &mut WindowStats,
    ) -> Result<(Arc<Tile>, bool), slam::GridError> {
        {
            let mut entries = self.entries.lock().expect("tiles lock");
            if let Some(e) = entries.get_mut(key) {
                e.used = Instant::now();
                let stale = e.tile.view_ns != view.updated_ns;
                let refresh = stale && !e.refreshing && e.tile.made.elapsed() >= REFRESH;
                if refresh {
                    e.refreshing = true;
                }
                stats.cached += 1;
                stats.stale += usize::from(stale);
                return Ok((e.tile.clone(), refresh));
            }
        }
        let tile = Arc::new(make_tile(view, key)?);
        stats.made += 1;
        self.put(key.clone(), tile.clone());
        Ok((tile, false))
    }

    fn put(&self, key: TileKey, tile: Arc<Tile>) {
        let mut entries = self.entries.lock().expect("tiles lock");
        if entries.len() >= MAX_TILES && !entries.contains_key(&key) {
            let oldest = entries
                .iter()
                .min_by_key(|(_, e)| e.used)
                .map(|(k, _)| k.clone());
            if let Some(k) = oldest {
                entries.remove(&k);
            }
        }
        entries.insert(
            key,
            Entry {
                tile,
                used: Instant::now(),
                refreshing: false,
            },
        );
    }

    /// Makes a stale tile again from `view` (on a blocking thread: the caller's choice); on
    /// an error the stale tile stays, to be made again later.
    pub fn refresh(&self, view: &FleetView, key: &TileKey) -> Result<(), slam::GridError> {
        match make_tile(view, key) {
            Ok(tile) => {
                self.put(key.clone(), Arc::new(tile));
                Ok(())
            }
            Err(e) => {
                if let Some(entry) = self.entries.lock().expect("tiles lock").get_mut(key) {
                    entry.refreshing = false;
                }
                Err(e)
            }
        }
    }

    /// The grid of the square `center ± radius_m` at `resolution_m`, cut from tiles; the
    /// stale tiles to make again.
    pub fn window(
        &self,
        view: &FleetView,
        center: [f64; 2],
        radius_m: f64,
        resolution_m: f64,
    ) -> Result<(slam::OccupancyGrid, Vec<TileKey>, WindowStats), slam::GridError> {
        let res = resolution_m;
        let resolution_um = (res * 1e6).round() as u64;
        let lo = [
            ((center[0] - radius_m) / res).floor() as i64,
            ((center[1] - radius_m) / res).floor() as i64,
        ];
        let size = ((2.0 * radius_m) / res).ceil() as usize;
        let tile_of = |cell: i64| cell.div_euclid(TILE_CELLS as i64);
        let mut cells = vec![-1i8; size * size];
        let mut stale = Vec::new();
        let mut stats = WindowStats::default();
        let mut thresholds = None;
        for j in tile_of(lo[1])..=tile_of(lo[1] + size as i64 - 1) {
            for i in tile_of(lo[0])..=tile_of(lo[0] + size as i64 - 1) {
                let key = TileKey {
                    fleet: view.id.clone(),
                    resolution_um,
                    i,
                    j,
                };
                let (tile, refresh) = self.tile(view, &key, &mut stats)?;
                thresholds.get_or_insert((tile.occupied_percent, tile.free_percent));
                let (tx0, ty0) = (i * TILE_CELLS as i64, j * TILE_CELLS as i64);
                for row in 0..size {
                    let wy = lo[1] + row as i64 - ty0;
                    if !(0..TILE_CELLS as i64).contains(&wy) {
                        continue;
                    }
                    let from = (lo[0] - tx0).max(0);
                    let to = (lo[0] + size as i64 - tx0).min(TILE_CELLS as i64);
                    if from >= to {
                        continue;
                    }
                    let src = &tile.cells[wy as usize * TILE_CELLS..][from as usize..to as usize];
                    let dst_col = (tx0 + from - lo[0]) as usize;
                    cells[row * size + dst_col..][..src.len()].copy_from_slice(src);
                }
                if refresh {
                    stale.push(key);
                }
            }
        }
        let (occupied_percent, free_percent) = thresholds.unwrap_or((65, 35));
        let grid = slam::OccupancyGrid {
            resolution_m: res,
            origin_m: [lo[0] as f64 * res, lo[1] as f64 * res],
            width: size,
            height: size,
            cells,
            occupied_percent,
            free_percent,
        };
        Ok((grid, stale, stats))
    }
}
