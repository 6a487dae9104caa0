//! The grid: walls, free space, its wedges and limits, bad input.

use super::*;
use crate::matching::synthetic::{Scene, uniform_bearings};

/// A closed square room of side `side_m`, centred on the origin.
fn room(side_m: f64) -> Scene {
    let h = side_m / 2.0;
    let c = [[-h, -h], [h, -h], [h, h], [-h, h]];
    Scene {
        walls: (0..4).map(|i| [c[i], c[(i + 1) % 4]]).collect(),
        trunks: Vec::new(),
    }
}

fn scan_of(scene: &Scene, pose: Pose2) -> Scan2 {
    let bearings = uniform_bearings(720, -std::f64::consts::PI, std::f64::consts::TAU / 720.0);
    let ranges = scene.scan(&pose, &bearings, 50.0, 0.0, 1);
    Scan2::from_polar(&bearings, &ranges, 50.0).expect("same lengths")
}

#[test]
fn square_room_has_occupied_walls_free_inside_unknown_outside() {
    // A room of 6.05 m, walls at ±3.025 m: mid-cell, so each wall fills one row of
    // cells. Scanned from an off-centre, rotated pose.
    let pose = Pose2::new(0.7, -0.4, 0.5);
    let scan = scan_of(&room(6.05), pose);
    let seeing_all = GridParams {
        blind_zone_m: 0.0,
        ..GridParams::default()
    };
    let grid = OccupancyGrid::from_scans([(pose, &scan)], &seeing_all).unwrap();
    // The wall cells span −3.1 … 3.1 m, plus one cell of margin on each side.
    assert_eq!((grid.width, grid.height), (64, 64));
    assert!((grid.origin_m[0] + 3.2).abs() < 1e-9 && (grid.origin_m[1] + 3.2).abs() < 1e-9);
    let state = |x: f64, y: f64| {
        let (ix, iy) = grid.cell_at([x, y]).expect("inside");
        grid.state(ix, iy)
    };
    // Every wall cell holds a return: 4 walls × 62 cells, corners shared (a corner
    // cell holds only 2.5 cm of each wall, beams are 3–6 cm apart there: it may be missed).
    for i in 1..61 {
        let t = -3.05 + 0.1 * i as f64;
        for (x, y) in [(t, -3.025), (t, 3.025), (-3.025, t), (3.025, t)] {
            assert_eq!(state(x, y), CellState::Occupied, "wall at ({x}, {y})");
        }
    }
    let (unknown, free, occupied) = grid.counts();
    assert!((240..=244).contains(&occupied), "{occupied}");
    // Everything inside the walls is free: 60 × 60 cells; the rest was never seen.
    assert_eq!(free, 3600);
    assert_eq!(unknown, 64 * 64 - occupied - 3600);
    for i in 0..60 {
        for j in 0..60 {
            let (x, y) = (-2.95 + 0.1 * i as f64, -2.95 + 0.1 * j as f64);
            assert_eq!(state(x, y), CellState::Free, "({x}, {y})");
        }
    }
}

#[test]
fn long_beams_clear_up_to_max_range_only() {
    // One beam along +x with a return at 10 m, and max range 4 m: free to 4 m, nothing
    // occupied, nothing seen beyond.
    let scan = Scan2::from_polar(&[0.0], &[10.0], 50.0).expect("scan");
    let params = GridParams {
        max_range_m: 4.0,
        blind_zone_m: 0.0,
        ..GridParams::default()
    };
    let grid = OccupancyGrid::from_scans([(Pose2::IDENTITY, &scan)], &params).expect("grid");
    let (_, free, occupied) = grid.counts();
    assert_eq!(occupied, 0);
    // Cells 0.0–4.0 m along the beam: 40, or 41 when 4.0 m rounds into the next cell.
    assert!((40..=41).contains(&free), "{free} free");
    assert!(grid.width <= 43 && grid.height == 3);
}

#[test]
fn returns_win_over_passes_and_repeated_passes_clear() {
    let scene = room(4.0);
    let pose = Pose2::new(0.0, 0.0, 0.0);
    let scan = scan_of(&scene, pose);
    let once = OccupancyGrid::from_scans([(pose, &scan)], &GridParams::default()).unwrap();
    let thrice =
        OccupancyGrid::from_scans([(pose, &scan); 3].iter().copied(), &GridParams::default())
            .unwrap();
    let (ix, iy) = once.cell_at([1.0, 0.3]).unwrap();
    // Inside: 33 % after one scan; after three, −2.1 clamps to −2.0: 12 %.
    assert_eq!(once.occupancy(ix, iy), 33);
    assert_eq!(thrice.occupancy(ix, iy), 12);
    let (wx, wy) = once.cell_at([1.99, 0.03]).unwrap();
    assert_eq!(once.occupancy(wx, wy), 70);
    assert_eq!(thrice.occupancy(wx, wy), 93);
}

#[test]
fn bad_input_is_an_error_not_a_huge_allocation() {
    let scan = Scan2::from_polar(&[0.0], &[1.0], 50.0).unwrap();
    let p = GridParams::default();
    let none: [(Pose2, &Scan2); 0] = [];
    assert_eq!(OccupancyGrid::from_scans(none, &p), Err(GridError::NoScans));
    let far = [
        (Pose2::IDENTITY, &scan),
        (Pose2::new(1e6, -1e6, 0.0), &scan),
    ];
    let err = OccupancyGrid::from_scans(far, &p).unwrap_err();
    assert!(matches!(err, GridError::TooLarge { .. }), "{err}");
    assert!(err.to_string().contains("exceeds"), "{err}");
    let nan = [(Pose2::new(f64::NAN, 0.0, 0.0), &scan)];
    assert_eq!(
        OccupancyGrid::from_scans(nan, &p),
        Err(GridError::NonFinitePose { index: 0 })
    );
    let zero = GridParams {
        resolution_m: 0.0,
        ..GridParams::default()
    };
    assert!(matches!(
        OccupancyGrid::from_scans([(Pose2::IDENTITY, &scan)], &zero),
        Err(GridError::InvalidParams(_))
    ));
}

#[test]
fn traversal_visits_every_crossed_cell_without_the_last() {
    let mut cells = Vec::new();
    traverse([0.5, 0.5], [5.5, -1.5], |x, y| cells.push((x, y)));
    // 5 steps in x, 2 in y: 7 cells before the end cell (5, −2), 4-connected.
    assert_eq!(cells.len(), 7, "{cells:?}");
    assert_eq!(cells[0], (0, 0));
    assert!(!cells.contains(&(5, -2)));
    for w in cells.windows(2) {
        assert_eq!((w[1].0 - w[0].0).abs() + (w[1].1 - w[0].1).abs(), 1);
    }
    // The exact crossings of y = 0 (x = 1.75) and y = −1 (x = 4.25).
    assert!(
        cells.contains(&(1, -1)) && cells.contains(&(4, -2)),
        "{cells:?}"
    );
    let mut none = 0;
    traverse([3.2, 3.7], [3.9, 3.1], |_, _| none += 1);
    assert_eq!(none, 0);
}

#[test]
fn a_window_is_the_same_cells_as_the_whole_grid_there() {
    let pose = Pose2::new(0.7, -0.4, 0.5);
    let scan = scan_of(&room(6.05), pose);
    let whole = OccupancyGrid::from_scans([(pose, &scan)], &GridParams::default()).unwrap();
    let params = GridParams {
        window_m: Some([0.0, 0.0, 2.0, 5.0]),
        ..GridParams::default()
    };
    let part = OccupancyGrid::from_scans([(pose, &scan)], &params).unwrap();
    // x: 0–2 m and a cell of margin each side (−0.1–2.2 m); y: 0 m to the wall's cells.
    assert_eq!((part.width, part.height), (23, 33));
    for iy in 0..part.height {
        for ix in 0..part.width {
            let (wx, wy) = whole.cell_at(part.cell_center(ix, iy)).expect("inside");
            assert_eq!(
                part.occupancy(ix, iy),
                whole.occupancy(wx, wy),
                "({ix}, {iy})"
            );
        }
    }
    let away = GridParams {
        window_m: Some([100.0, 100.0, 110.0, 110.0]),
        ..GridParams::default()
    };
    // Beyond the map: the window, all unknown.
    let empty = OccupancyGrid::from_scans([(pose, &scan)], &away).unwrap();
    assert_eq!((empty.width, empty.height), (102, 102));
    assert_eq!(empty.counts(), (102 * 102, 0, 0));
}

#[test]
fn coarsen_to_fit_grows_the_cells_until_the_grid_fits() {
    let pose = Pose2::new(0.7, -0.4, 0.5);
    let scan = scan_of(&room(6.05), pose);
    let small = GridParams {
        max_cells: 1000,
        ..GridParams::default()
    };
    assert!(matches!(
        OccupancyGrid::from_scans([(pose, &scan)], &small),
        Err(GridError::TooLarge { .. })
    ));
    let fit = GridParams {
        coarsen_to_fit: true,
        ..small
    };
    let grid = OccupancyGrid::from_scans([(pose, &scan)], &fit).unwrap();
    assert!(
        grid.width * grid.height <= 1000,
        "{} × {}",
        grid.width,
        grid.height
    );
    // 64 × 64 cells of 0.1 m into 1000: cells about 0.2 m, not much coarser.
    assert!(
        (0.19..0.23).contains(&grid.resolution_m),
        "{}",
        grid.resolution_m
    );
    let (_, free, occupied) = grid.counts();
    assert!(
        free > 600 && occupied > 80,
        "{free} free, {occupied} occupied"
    );
}

/// The room of `side_m` seen from its centre by `beams` beams over the circle, as a fan.
fn fan_in_room(side_m: f64, beams: usize) -> BeamFan {
    let step = std::f64::consts::TAU / beams as f64;
    let bearings = uniform_bearings(beams, -std::f64::consts::PI, step);
    let ranges = room(side_m).scan(&Pose2::IDENTITY, &bearings, 50.0, 0.0, 1);
    BeamFan::new(
        bearings
            .iter()
            .zip(&ranges)
            .map(|(&b, &r)| (f64::from(b), (r > 0.0).then_some(f64::from(r)))),
    )
}

/// States of the cells whose centres lie within `inside_m` of the origin but beyond `beyond_m`.
fn states_between(grid: &OccupancyGrid, beyond_m: f64, inside_m: f64) -> (usize, usize, usize) {
    let mut n = (0, 0, 0);
    for iy in 0..grid.height {
        for ix in 0..grid.width {
            let [x, y] = grid.cell_center(ix, iy);
            let (d, inf) = (x.hypot(y), x.abs().max(y.abs()));
            if d <= beyond_m || inf >= inside_m {
                continue;
            }
            match grid.state(ix, iy) {
                CellState::Unknown => n.0 += 1,
                CellState::Free => n.1 += 1,
                CellState::Occupied => n.2 += 1,
            }
        }
    }
    n
}

#[test]
fn neighbouring_beams_fill_the_wedge_between_them() {
    // 130 beams (2.8°) in a 20 m room: at 9 m two beams are 0.43 m apart, so one line per
    // beam leaves most cells there unseen.
    let fan = fan_in_room(20.0, 130);
    let params = GridParams::default();
    let grid = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &params).unwrap();
    let (unknown, free, occupied) = states_between(&grid, 0.6, 9.7);
    assert_eq!(occupied, 0);
    assert!(
        unknown * 200 <= free,
        "{unknown} unknown of {} cells inside the walls",
        unknown + free
    );
    let lines_only = GridParams {
        max_wedge_rad: 0.0,
        ..params
    };
    let lines = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &lines_only).unwrap();
    let (unknown_lines, _, _) = states_between(&lines, 0.6, 9.7);
    assert!(
        unknown_lines > 10 * unknown.max(1),
        "{unknown_lines} vs {unknown}"
    );
    // The walls are still walls: every beam's return cell is occupied.
    assert_eq!(grid.counts().2, lines.counts().2);
}

#[test]
fn a_wedge_stops_short_of_a_wall_seen_at_a_grazing_angle() {
    // A long wall 2 m to the side, seen by beams 3° apart: between two hits far along it, the
    // filled wedge must not clear the wall's own cells.
    let bearings: Vec<f64> = (1..=20).map(|k| f64::from(k) * 3f64.to_radians()).collect();
    let fan = BeamFan::new(bearings.iter().map(|&b| (b, Some(2.0 / b.sin()))));
    let grid = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &GridParams::default()).unwrap();
    for ix in 0..grid.width {
        let [x, _] = grid.cell_center(ix, 0);
        if !(3.0..=30.0).contains(&x) {
            continue;
        }
        let (cx, cy) = grid.cell_at([x, 2.05]).expect("inside");
        assert_ne!(
            grid.state(cx, cy),
            CellState::Free,
            "wall cell at x = {x:.2} cleared"
        );
    }
}

#[test]
fn beams_without_a_return_clear_only_a_short_way() {
    // Open space all round: every beam without a return.
    let fan = BeamFan::new((0..360).map(|k| (f64::from(k).to_radians() - 3.1, None)));
    let params = GridParams::default();
    let grid = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &params).unwrap();
    let (_, free, occupied) = grid.counts();
    assert_eq!(occupied, 0);
    for iy in 0..grid.height {
        for ix in 0..grid.width {
            let [x, y] = grid.cell_center(ix, iy);
            if grid.state(ix, iy) == CellState::Free {
                let d = x.hypot(y);
                assert!(d <= params.no_return_free_m + 0.1, "free at {d:.2} m");
                assert!(
                    d >= params.blind_zone_m - 0.1,
                    "free in the blind zone ({d:.2} m)"
                );
            }
        }
    }
    // The ring from the blind zone to 5 m, filled: π (5² − 0.5²) m² is 7,775 cells of 0.1 m.
    assert!((7_300..=8_100).contains(&free), "{free}");
}

#[test]
fn the_blind_zone_stays_unknown_and_an_edge_is_not_filled() {
    let fan = fan_in_room(8.0, 720);
    let grid = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &GridParams::default()).unwrap();
    // Cells whose centres lie a cell inside the blind zone (0.5 m): the cell a ray starts in
    // is partly outside it.
    let (unknown, free, _) = states_between(&grid, 0.0, 0.28);
    assert_eq!((unknown > 0, free), (true, 0), "the blind zone is not free");
    // Two beams 1° apart, one hitting at 3 m, the other at 10 m: behind the near object the
    // wedge is not seen.
    let edge = BeamFan::new([(0.0, Some(3.0)), (1f64.to_radians(), Some(10.0))]);
    let grid =
        OccupancyGrid::from_fans([(Pose2::IDENTITY, &edge)], &GridParams::default()).unwrap();
    let half = 0.5f64.to_radians();
    let (ix, iy) = grid.cell_at([8.0 * half.cos(), 8.0 * half.sin()]).unwrap();
    assert_eq!(grid.state(ix, iy), CellState::Unknown);
    // Alike ranges fill: 10 m and 10.4 m.
    let alike = BeamFan::new([(0.0, Some(10.0)), (1f64.to_radians(), Some(10.4))]);
    let grid =
        OccupancyGrid::from_fans([(Pose2::IDENTITY, &alike)], &GridParams::default()).unwrap();
    let (ix, iy) = grid.cell_at([8.0 * half.cos(), 8.0 * half.sin()]).unwrap();
    assert_eq!(grid.state(ix, iy), CellState::Free);
}
