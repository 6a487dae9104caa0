//! The paper's baseline: a fleet run mapped from each robot's fixed horizontal 2D scanner
//! instead of its leveled 3D scans, with the mapper's own code ([`FleetMap`]) and parameters,
//! scored against the simulator's ground truth.

use crate::map_score::MapScore;
use crate::{FLEET, sim_mapping_params};
use anyhow::Result;
use edge::{EdgeConfig, NodeBuilder, PlanarScan};
use leveling::nalgebra::Isometry3;
use mapper::{FleetMap, MapperConfig};
use sim::FleetRobot;
use slam::Pose2;

/// What the fixed 2D scanners' map came to.
#[derive(Clone, Copy, Debug)]
pub struct Fixed2dRun {
    /// RMSE of node positions against ground truth (m).
    pub ate_rmse_m: f64,
    /// Loop closures in its network.
    pub loop_closures: usize,
    /// Its grid against the truth.
    pub map: MapScore,
}

/// The run of `robots` of the park's loops, `duration_s` long with noise seed `seed` (the
/// simulator is deterministic per seed, so this is the demo's run), from the fixed 2D
/// scanners, mapped with the mapper's own code and parameters, scored against the truth.
pub fn map_fixed2d(robots: usize, duration_s: f64, seed: u64) -> Result<Fixed2dRun> {
    let duration_ns = (duration_s * 1e9) as u64;
    let defaults = MapperConfig::default();
    let mut map = FleetMap::new(
        FLEET,
        sim_mapping_params(),
        Some(slam::geodesy::GeoDatum {
            origin: sim::PARK_DATUM.origin,
        }),
        defaults.max_range_m,
    );
    let mut robots: Vec<FleetRobot> = (0..robots)
        .map(|i| FleetRobot::new(edge::park(), i, duration_ns, seed).expect("park loop"))
        .collect();
    let base = EdgeConfig::default();
    let mut builders: Vec<NodeBuilder> = (0..robots.len())
        .map(|i| {
            NodeBuilder::new(
                FLEET,
                &format!("robot{i}"),
                base.node.clone(),
                base.leveling,
                0,
            )
        })
        .collect();
    let mut truth = Vec::new();
    loop {
        let mut any = false;
        for (robot, builder) in robots.iter_mut().zip(&mut builders) {
            let Some(scan) = robot.next_scan() else {
                continue;
            };
            any = true;
            let mount: Isometry3<f64> = robot.fixed_scanner().mount;
            let stamp_ns = scan.scan.raw.columns[0].stamp_ns;
            let planar = PlanarScan {
                stamp_ns,
                bearings_rad: scan.fixed2d.iter().map(|b| b.bearing_rad as f32).collect(),
                ranges_m: scan
                    .fixed2d
                    .iter()
                    .map(|b| b.range_m.unwrap_or(0.0) as f32)
                    .collect(),
                robot_at_start: scan.odometry_at_start,
                sensor_in_robot: mount,
                gps: scan
                    .gps_since_previous
                    .iter()
                    .map(|f| edge::sim_gps_reading(robot, f, 0))
                    .collect(),
            };
            let Some(node) = builder.offer_planar(&planar)? else {
                continue;
            };
            map.ingest(&node)?;
            map.optimize_pending()?;
            truth.push(Pose2::from_isometry3(&(scan.scan.truth_start_pose * mount)));
        }
        if !any {
            break;
        }
    }
    map.optimize_now()?;
    let ate = slam::position_rmse(map.poses().iter().copied().zip(truth));
    let grid = fleetmap::grid_of(
        || map.nodes().iter().map(|n| &**n),
        map.poses(),
        &slam::GridParams::default(),
    )?;
    let paths: Vec<Vec<[f64; 2]>> = robots.iter().map(crate::map_score::path_of).collect();
    Ok(Fixed2dRun {
        ate_rmse_m: ate,
        loop_closures: map.stats().loop_closures,
        map: crate::map_score::score(&grid, edge::park(), &paths),
    })
}
