//! Three simulated robots map the hilly park together, once from leveled scans and once from
//! fixed horizontal 2D scanners, with the same dead reckoning and GPS: the paper's claim
//! (leveled scans map uneven ground where a fixed 2D scanner fails), measured as the absolute
//! trajectory error of the map's nodes against ground truth, and robots that meet share one
//! map (inter-robot closures).

use leveling::nalgebra::Isometry3;
use leveling::{Leveler, SegmentParams};
use sim::{FleetRobot, FleetScan, FleetStart, Route, World};
use slam::matching::Scan2;
use slam::nalgebra::{Matrix2, Vector2};
use slam::{GpsObservation, Mapper2d, Mapper2dParams, MapperStats, Pose2, gnss};

const ROBOTS: usize = 3;
const DURATION_NS: u64 = 120_000_000_000;

/// What the mapper gets from one scan, with the node frame's true pose.
struct NodeInput {
    robot: usize,
    odometry: Pose2,
    scan: Scan2,
    gps: Vec<GpsObservation>,
    truth: Pose2,
}

/// Runs the fleet and maps it with one scan kind; returns the mapper's stats and the ATE
/// (RMSE of node positions against the truth, m; after fitting the map to the truth when
/// `aligned`), and the network's connected parts with, for each, its nodes' ATE after
/// fitting that part alone to the truth.
fn map_fleet(inputs: Vec<NodeInput>, aligned: bool) -> (MapperStats, f64, Vec<(usize, f64)>) {
    // The simulator's dead reckoning is precise (see the constructor's doc).
    let mut mapper = Mapper2d::new(Mapper2dParams {
        node_distance_m: 1.0,
        ..Mapper2dParams::precise_dead_reckoning()
    });
    let mut truth = Vec::new();
    for input in inputs {
        let placed = mapper
            .add_robot_scan(input.robot, input.odometry, input.scan, &input.gps)
            .expect("valid network");
        if let slam::Placed::Node(node) = placed {
            assert_eq!(node, truth.len());
            truth.push(input.truth);
        }
    }
    mapper.finish().expect("optimize");
    let graph = mapper.graph();
    let pairs = graph.poses.iter().copied().zip(truth.iter().copied());
    let ate = if aligned {
        slam::aligned_position_rmse(pairs)
    } else {
        slam::position_rmse(pairs)
    };
    let labels = graph.components();
    let parts = (0..labels.len())
        .filter(|&i| labels[i] == i)
        .map(|root| {
            let members = (0..labels.len()).filter(|&i| labels[i] == root);
            let pairs: Vec<(Pose2, Pose2)> = members.map(|i| (graph.poses[i], truth[i])).collect();
            (pairs.len(), slam::aligned_position_rmse(pairs))
        })
        .collect();
    (mapper.stats(), ate, parts)
}

/// The GPS fixes as the mapper takes them, for a node frame `frame_in_robot` (m, robot
/// frame): every fix since the previous scan's start, oldest first. A fix is up to a scan
/// (4 s) older than the scan: dead reckoning carries it to the scan's start (at 1.2 m/s, a
/// second is 1.2 m), as the edge does (the antenna where it was at the fix's time, in the
/// robot frame at the scan's start).
fn gps_for(scan: &FleetScan, robot: &FleetRobot, frame_in_robot: [f64; 2]) -> Vec<GpsObservation> {
    let antenna = robot.gps().antenna_in_robot_m;
    scan.gps_since_previous
        .iter()
        .map(|fix| {
            let at_fix = robot
                .odometry_track(fix.stamp_ns, fix.stamp_ns)
                .at(fix.stamp_ns)
                .expect("the track covers the fix");
            // Where the antenna was at the fix, in the robot frame at the scan's start, turned
            // level with the robot's roll and pitch: the one GPS model of edge and mapper.
            let start = &scan.odometry_at_start;
            let offset = gnss::carry_antenna_to_node(&antenna, &at_fix, start);
            let heading = Pose2::from_isometry3(start).theta;
            let origin = Pose2::new(frame_in_robot[0], frame_in_robot[1], 0.0);
            let lever = gnss::leveled_lever_arm(&offset, &start.rotation, heading, &origin);
            let var = fix.sigma_horizontal_m.powi(2);
            GpsObservation {
                position_m: Vector2::new(fix.enu_m.x, fix.enu_m.y),
                covariance_m2: Matrix2::new(var, 0.0, 0.0, var),
                lever_arm_m: lever,
            }
        })
        .collect()
}

/// Measured (120 s, seed 7), every 1 Hz fix since the previous scan on each node (3.8 per
/// node), lever arms levelled with the robot's attitude: leveled ATE 0.072 m with 4
/// inter-robot closures, fixed 2D 0.244 m (3.4×). Without the levelling they were 0.077 and
/// 0.248 m; with one fix per node (the latest at the scan's start) 0.138 and 0.413 m (3.0×). The
/// bounds below guard that. GPS sets the floor: with these fixes and exact relative edges
/// (every sequential and closure edge of the leveled network set to the truth, at its
/// information) the ATE is 0.068 m (one fix per node: 0.126 m).
#[test]
fn leveled_scans_map_the_hilly_park_better_than_a_fixed_2d_scanner() {
    let world = World::park();
    let (leveled, fixed) = fleet_inputs(&world, FleetStart::Dock, true, 7, DURATION_NS);
    let (stats, ate, _) = map_fleet(leveled, false);
    let (stats_fixed, ate_fixed, _) = map_fleet(fixed, false);
    eprintln!("leveled: ATE {ate:.3} m, {stats:?}");
    eprintln!("fixed 2D: ATE {ate_fixed:.3} m, {stats_fixed:?}");
    assert!(stats.inter_robot_closures >= 1, "{stats:?}");
    assert!(ate <= 0.085, "leveled ATE {ate:.3} m");
    assert!(
        ate_fixed >= 3.0 * ate,
        "fixed {ate_fixed:.3} m, leveled {ate:.3} m"
    );
}

/// A seed's run: the network's parts (nodes, fitted ATE) and the mapper's stats.
type SeedRun = (u64, Vec<(usize, f64)>, MapperStats);

/// The robots start at random places along their loops with odometry from the identity,
/// and without GPS: nothing tells the mapper where they are relative to one another. They
/// must find one another in their maps (first contact: pairs of submaps searched whole, a
/// match checked against both robots' longer stretches of path and confirmed by a second
/// from other submaps). A wrong contact moves a part by metres: every part, fitted alone to
/// the truth, must stay within 0.2 m.
///
/// Each robot drives its whole loop once (the longest loop's lap, 146 s, not the demo's
/// 120 s), so every place where two loops come close has been driven by both robots: their
/// paths overlap as far as the park lets them, whatever the seed. Measured
/// (docs/measurements/slam.md): all ten seeds end in one part (fitted ATE 0.075–0.179 m). In
/// 120 s seeds 1 and 4 leave one robot alone: its path and another's come within 10 m for
/// 10–23 m, which gives one or two matches from one submap, and a wrong match 81–96 m off in
/// the same park is as well supported (docs/measurements/slam.md, "First contact").
#[test]
fn robots_without_gps_or_a_known_start_meet_without_a_wrong_contact() {
    let world = World::park();
    let seeds: Vec<u64> = (1..=10).collect();
    let whole_loops_ns = (0..ROBOTS)
        .filter_map(|i| Route::park_loop(i)?.lap_ns())
        .max()
        .expect("the park's loops");
    // Two workers, the machine's two cores, each taking the next seed when it is done (the
    // seeds' runs differ in length: pairs would wait for their slower half).
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut results: Vec<SeedRun> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..2)
            .map(|_| {
                scope.spawn(|| {
                    let mut runs = Vec::new();
                    while let Some(&seed) =
                        seeds.get(next.fetch_add(1, std::sync::atomic::Ordering::Relaxed))
                    {
                        let start = FleetStart::Scattered;
                        let (leveled, _) = fleet_inputs(&world, start, false, seed, whole_loops_ns);
                        let (stats, _, parts) = map_fleet(leveled, true);
                        runs.push((seed, parts, stats));
                    }
                    runs
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().expect("seed runs"))
            .collect()
    });
    results.sort_by_key(|run| run.0);
    let mut apart = Vec::new();
    for (seed, parts, stats) in &results {
        eprintln!(
            "seed {seed}: parts (nodes, fitted ATE) {parts:?}, first contacts {}, contact searches {}",
            stats.first_contacts, stats.contact_searches
        );
        for &(nodes, ate) in parts {
            assert!(
                ate <= 0.2,
                "seed {seed}: a part of {nodes} nodes is {ate:.3} m from the truth: a wrong contact"
            );
        }
        if parts.len() > 1 {
            apart.push(*seed);
        }
    }
    assert!(
        apart.is_empty(),
        "seeds left in more than one part: {apart:?}"
    );
}

/// The fleet's nodes, leveled and from the fixed 2D scanner, in time order.
fn fleet_inputs(
    world: &World,
    start: FleetStart,
    with_gps: bool,
    seed: u64,
    duration_ns: u64,
) -> (Vec<NodeInput>, Vec<NodeInput>) {
    let mut robots: Vec<FleetRobot> = (0..ROBOTS)
        .map(|i| FleetRobot::starting(world, i, duration_ns, seed, start).expect("park loop"))
        .collect();
    let gps_for = |scan: &FleetScan, robot: &FleetRobot, frame: [f64; 2]| {
        if with_gps {
            gps_for(scan, robot, frame)
        } else {
            Vec::new()
        }
    };
    let mut leveler = Leveler::new(SegmentParams::default());
    let (mut leveled, mut fixed) = (Vec::new(), Vec::new());
    // Round robin: the robots scan at the same pace, so this is time order.
    loop {
        let mut any = false;
        for robot in &mut robots {
            let Some(scan) = robot.next_scan() else {
                continue;
            };
            any = true;
            let start = scan.scan.truth_start_pose;
            let start_ns = scan.scan.raw.columns[0].stamp_ns;
            assert_eq!(robot.truth_at(start_ns), start);

            // Leveled: the node frame is the leveled frame (sensor at scan start, robot heading).
            let mount = robot.scanner().mount;
            let level = leveler
                .level(&scan.scan.raw, &scan.track, &mount)
                .expect("track covers the scan");
            let (bearings, ranges): (Vec<f32>, Vec<f32>) = level.scan.returns().unzip();
            let leveled_frame = |robot_pose: &Isometry3<f64>| {
                Pose2::from_isometry3(&leveling::leveled_frame(robot_pose, &mount).inverse())
            };
            let m = mount.translation.vector;
            leveled.push(NodeInput {
                robot: scan.robot,
                odometry: leveled_frame(&scan.odometry_at_start),
                scan: Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths"),
                gps: gps_for(&scan, robot, [m.x, m.y]),
                truth: leveled_frame(&start),
            });

            // Fixed 2D: the node frame is the scanner's, tilting with the robot.
            let fixed_mount = robot.fixed_scanner().mount;
            let (bearings, ranges): (Vec<f32>, Vec<f32>) = scan
                .fixed2d
                .iter()
                .filter_map(|b| b.range_m.map(|r| (b.bearing_rad as f32, r as f32)))
                .unzip();
            let f = fixed_mount.translation.vector;
            fixed.push(NodeInput {
                robot: scan.robot,
                odometry: Pose2::from_isometry3(&(scan.odometry_at_start * fixed_mount)),
                scan: Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths"),
                gps: gps_for(&scan, robot, [f.x, f.y]),
                truth: Pose2::from_isometry3(&(start * fixed_mount)),
            });
        }
        if !any {
            break;
        }
    }
    (leveled, fixed)
}
