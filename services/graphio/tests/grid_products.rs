//! The map products on real data: the occupancy grid of the corrected Intel Research Lab log
//! (910 scans at their SLAM-corrected poses, MANIFEST.md §2b), encoded as PNG and PGM + YAML.
//! Consistent poses make a consistent grid: the returns land on occupied cells and the
//! robot's path is free.

use graphio::{carmen, gridmap};
use slam::Pose2;
use slam::grid::{CellState, GridParams, OccupancyGrid};
use slam::matching::Scan2;
use testdata::shared_data;

/// Share of the returns (within max range) that land on occupied cells of the grid built
/// from the same scans at `poses`, and how many poses stand on free cells.
fn consistency(
    scans: &[Scan2],
    poses: &[Pose2],
    params: &GridParams,
) -> (OccupancyGrid, f64, usize) {
    let grid = OccupancyGrid::from_scans(poses.iter().copied().zip(scans), params).expect("grid");
    let at = |q: [f64; 2]| {
        let (ix, iy) = grid.cell_at(q).expect("inside the grid");
        grid.state(ix, iy)
    };
    let (mut returns, mut on_occupied, mut path_free) = (0usize, 0usize, 0usize);
    for (pose, scan) in poses.iter().zip(scans) {
        for (p, r) in scan.points().iter().zip(scan.ranges_m()) {
            if *r <= params.max_range_m {
                returns += 1;
                on_occupied += usize::from(at(pose.transform_point(*p)) == CellState::Occupied);
            }
        }
        path_free += usize::from(at([pose.x, pose.y]) == CellState::Free);
    }
    let share = on_occupied as f64 / returns as f64;
    (grid, share, path_free)
}

#[test]
fn intel_corrected_grid_is_consistent_and_encodes() {
    let log = carmen::read(&shared_data(
        "radish_2d_corrected_logs/intel-corrected.log.gz",
    ))
    .expect("log");
    assert_eq!(log.scans.len(), 910);
    let scans: Vec<Scan2> = log.scans.iter().map(|s| s.to_scan2()).collect();
    let params = GridParams::default();
    let poses: Vec<Pose2> = log.scans.iter().map(|s| s.laser_pose).collect();
    let (grid, share, path_free) = consistency(&scans, &poses, &params);
    let (unknown, free, occupied) = grid.counts();
    println!(
        "Intel: {} × {} cells at {} m, origin {:?}; {free} free, {occupied} occupied, {unknown} unknown",
        grid.width, grid.height, grid.resolution_m, grid.origin_m
    );
    println!(
        "  {share:.3} of the returns on occupied cells; {path_free} of 910 poses on free cells"
    );
    // The lab is about 30 m × 30 m; beams through doors and windows reach further.
    assert!(grid.width < 1200 && grid.height < 1200);
    assert!(free > 5 * occupied, "{free} free, {occupied} occupied");
    assert!(share > 0.75, "{share}");
    assert!(path_free >= 900, "{path_free}");
    // The share measures registration: headings off by 2° blur the walls.
    let skewed: Vec<Pose2> = poses
        .iter()
        .enumerate()
        .map(|(k, p)| Pose2::new(p.x, p.y, p.theta + if k % 2 == 0 { 0.035 } else { -0.035 }))
        .collect();
    let (_, skewed_share, _) = consistency(&scans, &skewed, &params);
    println!("  with headings off by ±2°: {skewed_share:.3}");
    assert!(skewed_share < share - 0.1, "{skewed_share} vs {share}");

    // Both encodings carry the whole grid.
    let png = gridmap::to_png(&grid).expect("png");
    let reader = png::Decoder::new(std::io::Cursor::new(png))
        .read_info()
        .expect("decodes");
    assert_eq!(
        (reader.info().width as usize, reader.info().height as usize),
        (grid.width, grid.height)
    );
    let pgm = gridmap::to_pgm(&grid).expect("pgm");
    let header = format!(
        "P5\n# CREATOR: map_saver.cpp 0.100 m/pix\n{} {}\n255\n",
        grid.width, grid.height
    );
    assert!(pgm.starts_with(header.as_bytes()));
    assert_eq!(pgm.len(), header.len() + grid.width * grid.height);
    let free_pixels = pgm[header.len()..]
        .iter()
        .filter(|&&v| v == gridmap::FREE)
        .count();
    assert_eq!(free_pixels, free);
}
