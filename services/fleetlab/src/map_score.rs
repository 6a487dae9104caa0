//! A fleet's grid scored against the simulator's truth (docs/slam.md, "Scored against the
//! truth"): does it show the obstacles the robots drove past, does it call any of them free,
//! and how much of the free space around the robots' paths does it call free.

use serde::Serialize;
use sim::{Part, SurfaceKind, World};
use slam::nalgebra::Point2;
use slam::{CellState, OccupancyGrid};
use std::collections::{HashMap, HashSet};

/// Obstacles are scored within this distance of a robot's path (m).
pub const OBSTACLE_REACH_M: f64 = 20.0;
/// An obstacle is found when an occupied cell's centre lies this close to its footprint (m).
pub const FOUND_WITHIN_M: f64 = 0.2;
/// Free space is scored within this distance of a robot's path (m).
pub const FREE_REACH_M: f64 = 15.0;

/// What the grid shows, against the truth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MapScore {
    /// Obstacles (trunks, posts, pillars, walls, the bridge's rails) within
    /// [`OBSTACLE_REACH_M`] of a robot's path.
    pub obstacles: usize,
    /// The share of them with an occupied cell within [`FOUND_WITHIN_M`].
    pub obstacle_recall: f64,
    /// The share of the cells wholly inside an obstacle standing on the ground (the rails,
    /// on the bridge the robots also drive under, are scored for recall only) that the map
    /// calls free.
    pub false_free: f64,
    /// The share of the truly free cells within [`FREE_REACH_M`] of a path (no solid within
    /// half a cell) that the map calls free.
    pub free_coverage: f64,
}

/// Where `robot` drives, every half second of its run (the world's frame).
pub fn path_of(robot: &sim::FleetRobot<'_>) -> Vec<[f64; 2]> {
    const STEP_NS: u64 = 500_000_000;
    (0..=robot.duration_ns() / STEP_NS)
        .map(|k| {
            let pose = robot.truth_at(k * STEP_NS);
            [pose.translation.x, pose.translation.y]
        })
        .collect()
}

/// The parts a leveled scan should show: upright solids, not the lamp heads, crowns, roof or
/// the ground.
fn is_obstacle(part: &Part) -> bool {
    let upright = !matches!(part.shape, sim::Shape::Ellipsoid(_));
    upright
        && matches!(
            part.kind,
            SurfaceKind::TreeTrunk
                | SurfaceKind::Pole
                | SurfaceKind::Wall
                | SurfaceKind::PavilionPillar
                | SurfaceKind::Railing
        )
}

/// Anything standing on the ground: what makes a cell not free.
fn is_solid(part: &Part) -> bool {
    !part.kind.is_ground()
        && !matches!(
            part.kind,
            SurfaceKind::TreeCrown | SurfaceKind::PavilionRoof
        )
}

/// Scores `grid` (in the world's frame) against `world`, the robots having driven `paths`
/// (points along each, in the world's frame, at most a metre or so apart).
pub fn score(grid: &OccupancyGrid, world: &World, paths: &[Vec<[f64; 2]>]) -> MapScore {
    let points: Vec<[f64; 2]> = paths.iter().flatten().copied().collect();
    let near_path = |part: &Part| {
        let (c, r) = part.shape.bounding_circle();
        points.iter().any(|p| {
            (p[0] - c[0]).hypot(p[1] - c[1]) <= OBSTACLE_REACH_M + r
                && part.shape.footprint_distance_m(&Point2::new(p[0], p[1])) <= OBSTACLE_REACH_M
        })
    };
    let distance = |part: &Part, (ix, iy): (usize, usize)| {
        let [x, y] = grid.cell_center(ix, iy);
        part.shape.footprint_distance_m(&Point2::new(x, y))
    };
    let half = 0.5 * grid.resolution_m;
    let wholly_inside = |part: &Part, (ix, iy): (usize, usize)| {
        let [x, y] = grid.cell_center(ix, iy);
        [(-half, -half), (half, -half), (-half, half), (half, half)]
            .iter()
            .all(|(dx, dy)| {
                part.shape
                    .footprint_distance_m(&Point2::new(x + dx, y + dy))
                    == 0.0
            })
    };
    let obstacles: Vec<&Part> = world
        .parts()
        .iter()
        .filter(|p| is_obstacle(p) && near_path(p))
        .collect();
    // Each object once (a wall of several boxes, a railing of posts and rails): found when
    // any of its parts is.
    let mut objects: HashMap<u32, bool> = HashMap::new();
    let mut inside: HashSet<(usize, usize)> = HashSet::new();
    for part in &obstacles {
        let (c, r) = part.shape.bounding_circle();
        if part.kind != SurfaceKind::Railing {
            inside.extend(cells_near(grid, c, r).filter(|&k| wholly_inside(part, k)));
        }
        let found = cells_near(grid, c, r + FOUND_WITHIN_M).any(|k| {
            grid.state(k.0, k.1) == CellState::Occupied && distance(part, k) <= FOUND_WITHIN_M
        });
        *objects.entry(part.object).or_default() |= found;
    }
    let inside_free = inside
        .iter()
        .filter(|&&(ix, iy)| grid.state(ix, iy) == CellState::Free)
        .count();
    let mut blocked = vec![false; grid.width * grid.height];
    for part in world.parts().iter().filter(|p| is_solid(p)) {
        let (c, r) = part.shape.bounding_circle();
        for k in cells_near(grid, c, r + grid.resolution_m) {
            if distance(part, k) <= 0.5 * grid.resolution_m {
                blocked[k.1 * grid.width + k.0] = true;
            }
        }
    }
    let within_reach = path_mask(grid, &points, FREE_REACH_M);
    let (mut truly_free, mut free) = (0usize, 0usize);
    for iy in 0..grid.height {
        for ix in 0..grid.width {
            let k = iy * grid.width + ix;
            if within_reach[k] && !blocked[k] {
                truly_free += 1;
                free += usize::from(grid.state(ix, iy) == CellState::Free);
            }
        }
    }
    let share = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
    MapScore {
        obstacles: objects.len(),
        obstacle_recall: share(objects.values().filter(|&&f| f).count(), objects.len()),
        false_free: share(inside_free, inside.len()),
        free_coverage: share(free, truly_free),
    }
}

/// The cells of `grid` within the square around the circle at `c` of radius `r`.
fn cells_near(
    grid: &OccupancyGrid,
    c: [f64; 2],
    r: f64,
) -> impl Iterator<Item = (usize, usize)> + use<> {
    let res = grid.resolution_m;
    let span = |centre: f64, origin: f64, n: usize| {
        let lo = ((centre - r - origin) / res).floor().max(0.0);
        let hi = ((centre + r - origin) / res).floor().min(n as f64 - 1.0);
        (lo as usize, hi as usize, lo <= hi)
    };
    let (x0, x1, xs) = span(c[0], grid.origin_m[0], grid.width);
    let (y0, y1, ys) = span(c[1], grid.origin_m[1], grid.height);
    let rows = if xs && ys { y0..y1 + 1 } else { 0..0 };
    rows.flat_map(move |iy| (x0..=x1).map(move |ix| (ix, iy)))
}

/// The cells whose centres lie within `reach_m` of one of `points`, row interval by row
/// interval.
fn path_mask(grid: &OccupancyGrid, points: &[[f64; 2]], reach_m: f64) -> Vec<bool> {
    let mut mask = vec![false; grid.width * grid.height];
    let res = grid.resolution_m;
    let row_of = |y: f64| ((y - grid.origin_m[1]) / res - 0.5).ceil();
    for p in points {
        let (first, last) = (
            row_of(p[1] - reach_m),
            row_of(p[1] + reach_m).min(grid.height as f64),
        );
        let mut iy = first.max(0.0) as usize;
        while (iy as f64) < last && iy < grid.height {
            let y = grid.origin_m[1] + (iy as f64 + 0.5) * res;
            let half = (reach_m * reach_m - (y - p[1]).powi(2)).max(0.0).sqrt();
            let x0 = ((p[0] - half - grid.origin_m[0]) / res - 0.5)
                .ceil()
                .max(0.0) as usize;
            let x1 = ((p[0] + half - grid.origin_m[0]) / res - 0.5).floor();
            if x1 >= 0.0 {
                let x1 = (x1 as usize).min(grid.width - 1);
                if x0 <= x1 {
                    mask[iy * grid.width + x0..=iy * grid.width + x1].fill(true);
                }
            }
            iy += 1;
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The park's grid at 0.1 m around robot0's loop, every cell `occupancy`.
    fn park_grid(occupancy: i8) -> (OccupancyGrid, Vec<Vec<[f64; 2]>>) {
        let robot = sim::FleetRobot::new(edge::park(), 0, 60_000_000_000, 7).expect("loop 0");
        let path = path_of(&robot);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &path {
            for d in 0..2 {
                lo[d] = lo[d].min(p[d] - 25.0);
                hi[d] = hi[d].max(p[d] + 25.0);
            }
        }
        let (width, height) = (
            ((hi[0] - lo[0]) / 0.1) as usize,
            ((hi[1] - lo[1]) / 0.1) as usize,
        );
        let grid = OccupancyGrid {
            resolution_m: 0.1,
            origin_m: lo,
            width,
            height,
            cells: vec![occupancy; width * height],
            occupied_percent: 65,
            free_percent: 35,
        };
        (grid, vec![path])
    }

    #[test]
    fn the_scores_tell_an_empty_map_from_an_all_free_one_and_the_truth() {
        let world = edge::park();
        let (unknown, paths) = park_grid(-1);
        let none = score(&unknown, world, &paths);
        assert!(none.obstacles > 20, "{none:?}");
        assert_eq!(
            (none.obstacle_recall, none.false_free, none.free_coverage),
            (0.0, 0.0, 0.0)
        );
        let (free, _) = park_grid(0);
        let all_free = score(&free, world, &paths);
        assert_eq!((all_free.obstacle_recall, all_free.false_free), (0.0, 1.0));
        assert_eq!(all_free.free_coverage, 1.0);
        // The truth itself: every cell within half a cell's diagonal of a solid occupied (so a
        // thin rail has one), the rest free.
        let mut truth = free.clone();
        for part in world.parts().iter().filter(|p| is_solid(p)) {
            let (c, r) = part.shape.bounding_circle();
            for (ix, iy) in cells_near(&truth, c, r) {
                let [x, y] = truth.cell_center(ix, iy);
                if part.shape.footprint_distance_m(&Point2::new(x, y)) <= 0.08 {
                    truth.cells[iy * truth.width + ix] = 100;
                }
            }
        }
        let perfect = score(&truth, world, &paths);
        assert_eq!(
            (perfect.obstacle_recall, perfect.false_free),
            (1.0, 0.0),
            "{perfect:?}"
        );
        assert!(perfect.free_coverage > 0.99, "{perfect:?}");
    }

    #[test]
    fn the_path_mask_is_a_disc_of_cells() {
        let grid = OccupancyGrid {
            resolution_m: 1.0,
            origin_m: [-10.0, -10.0],
            width: 20,
            height: 20,
            cells: vec![-1; 400],
            occupied_percent: 65,
            free_percent: 35,
        };
        let mask = path_mask(&grid, &[[0.0, 0.0]], 3.0);
        let inside = mask.iter().filter(|&&m| m).count();
        // Centres (k + 0.5) within 3 m of the origin: 32 cells.
        assert_eq!(inside, 32);
        for iy in 0..20 {
            for ix in 0..20 {
                let [x, y] = grid.cell_center(ix, iy);
                assert_eq!(mask[iy * 20 + ix], x.hypot(y) <= 3.0, "({x}, {y})");
            }
        }
    }
}
