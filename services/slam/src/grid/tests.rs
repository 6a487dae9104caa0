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
    // Inside the walls 60 × 60 cells. The ring of cells beside the walls takes a quarter of
    // a pass per scan (`miss_weight_beside_return`): one scan leaves it undecided, the
    // 58 × 58 cells within it are free; the rest was never seen.
    assert_eq!(free, 58 * 58);
    assert_eq!(unknown, 64 * 64 - occupied - 58 * 58);
    for i in 0..60 {
        for j in 0..60 {
            let (x, y) = (-2.95 + 0.1 * i as f64, -2.95 + 0.1 * j as f64);
            let beside_wall = i == 0 || j == 0 || i == 59 || j == 59;
            let expected = if beside_wall {
                CellState::Unknown
            } else {
                CellState::Free
            };
            assert_eq!(state(x, y), expected, "({x}, {y})");
        }
    }
    // Four scans weigh one clean pass: then the ring is free too.
    let four = OccupancyGrid::from_scans([(pose, &scan); 4], &seeing_all).unwrap();
    assert_eq!(four.counts().1, 60 * 60);
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
    // Four scans, so that the cells beside the walls are cleared too.
    let grid = OccupancyGrid::from_scans([(pose, &scan); 4], &fit).unwrap();
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
fn neighbouring_beams_fill_the_wedge_between_them_while_they_are_close() {
    // 360 beams (1°) in a 20 m room: at 8 m two beams are 0.14 m apart, so one line per
    // beam leaves cells unseen between them. The wedges are filled as far as the beams are
    // `wedge_max_width_m` (0.15 m) apart: 8.6 m.
    let fan = fan_in_room(20.0, 360);
    let params = GridParams::default();
    let grid = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &params).unwrap();
    // The square of half-side 6 m lies within 8.5 m.
    let (unknown, free, occupied) = states_between(&grid, 0.6, 6.0);
    assert_eq!(occupied, 0);
    assert!(
        unknown * 200 <= free,
        "{unknown} unknown of {} cells within 6 m",
        unknown + free
    );
    let lines_only = GridParams {
        max_wedge_rad: 0.0,
        ..params.clone()
    };
    let lines = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &lines_only).unwrap();
    let (unknown_lines, _, _) = states_between(&lines, 0.6, 6.0);
    assert!(
        unknown_lines > 10 * unknown.max(1),
        "{unknown_lines} vs {unknown}"
    );
    // Beyond 8.6 m only the lines: a lamp post could stand there between two beams.
    let far = |g: &OccupancyGrid| {
        let (u, f, _) = states_between(g, 9.0, 9.7);
        (u, f)
    };
    let (far_unknown, far_free) = far(&grid);
    assert!(
        far_unknown * 10 > far_unknown + far_free,
        "{far_unknown} unknown, {far_free} free beyond the wedges' reach"
    );
    assert_eq!(far(&grid), far(&lines));
    // The walls are still walls: every beam's return cell is occupied.
    assert_eq!(grid.counts().2, lines.counts().2);
}

/// A long wall along y = 2 m seen from `pose` by 20 beams `step_deg` apart, from `step_deg`
/// on: the grid.
fn wall_seen_at_grazing_angles(step_deg: f64, pose: Pose2) -> OccupancyGrid {
    let bearings: Vec<f64> = (1..=20)
        .map(|k| f64::from(k) * step_deg.to_radians())
        .collect();
    let fan = BeamFan::new(bearings.iter().map(|&b| (b, Some(2.0 / b.sin()))));
    OccupancyGrid::from_fans([(pose, &fan)], &GridParams::default()).unwrap()
}

/// No cell of the wall's row (y in [2, 2.1)) from x = 3 m to 30 m is free.
fn assert_wall_row_kept(grid: &OccupancyGrid) {
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
fn a_wedge_stops_short_of_a_wall_seen_at_a_grazing_angle() {
    // Beams 3° apart: between two hits far along the wall, the filled wedge must not clear
    // the wall's own cells.
    assert_wall_row_kept(&wall_seen_at_grazing_angles(3.0, Pose2::IDENTITY));
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

#[test]
fn a_beam_clears_from_where_it_was_seen() {
    // A scan taken while driving: its last column was measured 3 m along x from the start,
    // looking left, and hit something 2 m away, at (3, 2).
    let fan = BeamFan::new([FanBeam {
        from_m: [3.0, 0.0],
        bearing_rad: std::f64::consts::FRAC_PI_2,
        range_m: Some(2.0),
        free_to_m: None,
    }]);
    let grid = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &GridParams::default()).unwrap();
    let state = |x: f64, y: f64| {
        let (ix, iy) = grid.cell_at([x, y]).expect("inside");
        grid.state(ix, iy)
    };
    assert_eq!(state(3.05, 2.05), CellState::Occupied);
    for y in [0.65, 1.05, 1.55] {
        assert_eq!(state(3.05, y), CellState::Free, "y = {y}");
    }
    // Not along the line from the scan's start: nothing was seen there.
    for (x, y) in [(1.05, 0.75), (2.05, 1.35)] {
        assert_eq!(state(x, y), CellState::Unknown, "({x}, {y})");
    }
}

#[test]
fn a_grazing_return_stops_short_across_the_surface_not_along_the_beam() {
    // A wall along y = 2 m seen at 2.5°…50° by a scan whose pose is 6 cm off towards it:
    // the returns land 6 cm inside the wall's row of cells. Stopping 0.1 m short along a beam
    // that meets the wall at 5° is 1 cm across it: the beams would clear the wall's cells.
    let off = Pose2::new(0.0, 0.06, 0.0);
    assert_wall_row_kept(&wall_seen_at_grazing_angles(2.5, off));
}

#[test]
fn a_beam_without_a_return_clears_as_far_as_its_column_saw_the_ground() {
    let beam = |free_to_m| FanBeam {
        from_m: [0.0, 0.0],
        bearing_rad: 0.0,
        range_m: None,
        free_to_m,
    };
    let free_up_to = |free_to_m: Option<f64>| {
        let fan = BeamFan::new([beam(free_to_m)]);
        let grid =
            OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &GridParams::default()).unwrap();
        (0..grid.width)
            .filter(|&ix| {
                let (_, iy) = grid.cell_at([0.0, 0.0]).unwrap();
                grid.state(ix, iy) == CellState::Free
            })
            .map(|ix| grid.cell_center(ix, 0)[0])
            .fold(0.0, f64::max)
    };
    // Ground seen 12 m away: free to there. Not known (a planar scan): `no_return_free_m`.
    assert!((free_up_to(Some(12.0)) - 11.95).abs() < 1e-9);
    assert!((free_up_to(None) - 4.95).abs() < 1e-9);
    // A column that saw no ground clears nothing.
    let fan = BeamFan::new([beam(Some(0.0))]);
    let grid = OccupancyGrid::from_fans([(Pose2::IDENTITY, &fan)], &GridParams::default()).unwrap();
    assert_eq!(grid.counts().1, 0);
}
