//! `levelmap demo`: a mapper and three simulated robots in the hilly park, each robot its own
//! edge service talking to the mapper over Zenoh TCP on loopback. At the end it scores the
//! map against the simulator's ground truth, and scores the same run mapped from each robot's
//! fixed horizontal 2D scanner (the paper's baseline, [`crate::fixed2d`]) for comparison.

use crate::FLEET;
use crate::map_score::MapScore;
use anyhow::{Context, Result};
use clap::Args;
use edge::{EdgeConfig, SimSourceConfig, SourceConfig};
use mapper::MapperConfig;
use runtime::session::SessionConfig;
use serde::Serialize;
use sim::{FleetRobot, FleetStart};
use slam::Pose2;
use std::path::PathBuf;
use std::time::Instant;

/// Run the fleet demo: a mapper and simulated robots over real Zenoh, the map over HTTP.
#[derive(Args, Clone, Debug)]
pub struct DemoArgs {
    /// How long the robots drive (s of simulated time).
    #[arg(long, default_value_t = 120.0)]
    pub duration: f64,
    /// Drive this many laps of the first robot's loop instead of `--duration`.
    #[arg(long)]
    pub laps: Option<u32>,
    /// Skip the fixed-2D baseline (minutes for a long drive).
    #[arg(long)]
    pub no_baseline: bool,
    /// Add every node, even where the map has nodes already (no bounded growth:
    /// `[mapping.coverage] enabled = false`), for comparison.
    #[arg(long)]
    pub keep_every_node: bool,
    /// Robots (1 to 3: the park's loops).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u8).range(1..=3))]
    pub robots: u8,
    /// Simulated time per wall-clock time: 1 is real time, 0 as fast as the machine goes.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// The mapper's HTTP address.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: String,
    /// The mapper's Zenoh router endpoint; robots connect to it.
    #[arg(long, default_value = "tcp/127.0.0.1:7447")]
    pub zenoh: String,
    /// Folder for the mapper's store and the robots' outboxes (new, empty or an earlier run's,
    /// emptied at start; any other is refused).
    #[arg(long, value_name = "DIR", default_value = "levelmap-demo")]
    pub dir: PathBuf,
    /// Seed of the sensors' noise (and of the scattered starts).
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// The robots send no GPS fixes.
    #[arg(long)]
    pub no_gps: bool,
    /// Each robot starts at a random place along its loop with odometry from the identity:
    /// the mapper knows neither where nor how the robots start, and must find them in one
    /// another's maps. With `--no-gps`, the map has a frame of its own: the ATE is taken
    /// after the rigid motion that fits it best to the ground truth.
    #[arg(long)]
    pub scatter_starts: bool,
    /// Keep serving the map after the robots finish, until Ctrl-C.
    #[arg(long)]
    pub serve: bool,
    /// Bearer token of the mapper's write routes (re-optimize); none: they are off.
    #[arg(
        long,
        env = "LEVELMAP_TOKEN",
        default_value = "",
        hide_env_values = true
    )]
    pub token: String,
    /// Bearer token of the mapper's read routes; none: reading needs no token.
    #[arg(
        long,
        env = "LEVELMAP_READ_TOKEN",
        default_value = "",
        hide_env_values = true
    )]
    pub read_token: String,
    /// XYZ tiles the dashboard draws under the grid (`[http.base_map]`), e.g.
    /// `https://tile.openstreetmap.org/{z}/{x}/{y}.png`; none by default.
    #[arg(long, value_name = "URL")]
    pub base_map: Option<String>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct DemoReport {
    api: String,
    robots: usize,
    nodes: usize,
    edges: usize,
    gps_edges: usize,
    /// Of `gps_edges`, the fixes of passes over covered ground, carried to the nodes passed.
    pass_fixes: usize,
    loop_closures: usize,
    inter_robot_closures: usize,
    /// RMSE of node positions against ground truth (m).
    ate_rmse_m: f64,
    /// Whether `ate_rmse_m` was taken after fitting the map to the ground truth (SE(2)).
    ate_aligned: bool,
    /// Connected parts of the pose network (1: every robot in one map).
    components: usize,
    /// The grid against the simulator's truth (docs/slam.md); none when the map has a frame
    /// of its own (`--no-gps --scatter-starts`).
    map: Option<MapScore>,
    /// The same run mapped from the fixed 2D scanners instead (m); only for the docked
    /// start with GPS, the baseline's setting.
    ate_rmse_fixed2d_m: Option<f64>,
    fixed2d_loop_closures: Option<usize>,
    /// The fixed 2D scanners' grid against the truth.
    map_fixed2d: Option<MapScore>,
    node_sends: u64,
    node_resends: u64,
    /// Nodes left unacked in the outboxes (0 when every node reached the map).
    outbox_pending: u64,
    /// Nodes passed over covered ground (located, not added: docs/services.md, "Bounded
    /// growth").
    nodes_passed: u64,
    /// The mapper's store file at the end (bytes).
    store_bytes: u64,
    /// Simulated time driven (s).
    duration_s: f64,
    /// With `--laps`: the map when the first robot finished its first lap.
    first_lap: Option<FirstLap>,
    wall_s: f64,
}

/// Runs the demo: a mapper and simulated robots, the map scored against ground truth.
pub fn run(args: &DemoArgs) -> Result<()> {
    let mut args = args.clone();
    if let Some(laps) = args.laps {
        let lap_ns = sim::Route::park_loop(0)
            .and_then(|r| r.lap_ns())
            .context("the first loop's lap time")?;
        args.duration = f64::from(laps) * lap_ns as f64 * 1e-9;
    }
    crate::runtime()?.block_on(run_async(&args))
}

async fn run_async(args: &DemoArgs) -> Result<()> {
    let started = Instant::now();
    let mut park = crate::park_mapper_config(&args.dir, &args.http, &args.zenoh)?;
    if let Some(url) = &args.base_map {
        park.http.base_map = Some(mapper::config::BaseMap {
            url: url.clone().try_into().map_err(anyhow::Error::msg)?,
            attribution: String::new(),
            max_zoom: 19,
        });
    }
    let mapper = mapper::start(MapperConfig {
        mapping: slam::Mapper2dParams {
            coverage: slam::CoverageParams {
                enabled: !args.keep_every_node,
                ..Default::default()
            },
            ..park.mapping.clone()
        },
        token: args.token.clone(),
        read_token: args.read_token.clone(),
        ..park
    })
    .await?;
    let api = format!("http://{}/api/v1/fleets/{FLEET}", mapper.http_addr);
    let dashboard = format!("http://{}/", mapper.http_addr);
    if !args.json {
        println!("mapper: Zenoh {} · dashboard {dashboard}", args.zenoh);
    }
    let epoch_ns = runtime::session::now_ns();
    let duration_ns = (args.duration * 1e9) as u64;
    let start = if args.scatter_starts {
        FleetStart::Scattered
    } else {
        FleetStart::Dock
    };
    let truth: Vec<FleetRobot> = (0..usize::from(args.robots))
        .map(|i| {
            FleetRobot::starting(edge::park(), i, duration_ns, args.seed, start).expect("park loop")
        })
        .collect();
    // Without GPS and a known start the map's frame is its own.
    let ate_aligned = args.no_gps && args.scatter_starts;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let mut robots = Vec::new();
    for i in 0..usize::from(args.robots) {
        let config = robot_config(args, i);
        let source = edge::open_source(&config, epoch_ns)?;
        let mut stop = stop_rx.clone();
        robots.push(tokio::spawn(edge::run(config, source, async move {
            let _ = stop.wait_for(|s| *s).await;
        })));
    }
    let stop = runtime::session::shutdown_signal();
    let ctrl_c = tokio::spawn(async move {
        stop.await;
        let _ = stop_tx.send(true);
    });
    // With --laps: the map as it was when the first robot finished its first lap.
    let first_lap = match args.laps {
        Some(_) => Some(after_first_lap(&mapper, &truth, epoch_ns, ate_aligned, &args.dir).await?),
        None => None,
    };
    let progress = (!args.json).then(|| {
        tokio::spawn(show_progress(
            mapper.shared.clone(),
            epoch_ns,
            args.duration,
        ))
    });
    let mut sends = (0, 0, 0);
    let mut reports = Vec::new();
    for robot in robots {
        reports.push(robot.await??);
    }
    if let Some(progress) = progress {
        progress.abort();
    }
    for report in reports {
        if !args.json {
            let acked = report
                .acked_node_seq
                .map_or("none acked".to_owned(), |seq| format!("acked up to {seq}"));
            println!(
                "{}: {} nodes, {} sends ({} re-sends), {acked}",
                report.robot, report.nodes, report.node_sends, report.node_resends,
            );
        }
        sends.0 += report.node_sends;
        sends.1 += report.node_resends;
        sends.2 += report.outbox_pending;
    }
    mapper.optimize(FLEET).await?;
    let view = mapper
        .shared
        .fleet(FLEET)
        .context("no node reached the mapper")?;
    let ate = ate_of(&view, &truth, epoch_ns, ate_aligned);
    let map = if ate_aligned {
        None
    } else {
        let grid = view.grid(&slam::GridParams::default())?;
        let paths: Vec<Vec<[f64; 2]>> = truth.iter().map(crate::map_score::path_of).collect();
        Some(crate::map_score::score(&grid, edge::park(), &paths))
    };
    // Seconds of simulation and mapping (minutes in a debug build): on the blocking pool, so
    // that the mapper's HTTP API, on this runtime, goes on answering meanwhile.
    let baseline = if args.no_gps || args.scatter_starts || args.no_baseline {
        None
    } else {
        let (robots, duration, seed) = (usize::from(args.robots), args.duration, args.seed);
        Some(
            tokio::task::spawn_blocking(move || {
                crate::fixed2d::map_fixed2d(robots, duration, seed)
            })
            .await??,
        )
    };
    let report = DemoReport {
        api: api.clone(),
        robots: view.robots.len(),
        nodes: view.poses.len(),
        edges: view.edges.len(),
        gps_edges: view.gps.len(),
        pass_fixes: view.stats.pass_fixes,
        loop_closures: view.stats.loop_closures,
        inter_robot_closures: view.stats.inter_robot_closures,
        ate_rmse_m: ate,
        ate_aligned,
        components: slam::PoseGraph {
            poses: view.poses.to_vec(),
            edges: view.edges.to_vec(),
            gps: Vec::new(),
        }
        .component_count(),
        map,
        ate_rmse_fixed2d_m: baseline.map(|b| b.ate_rmse_m),
        fixed2d_loop_closures: baseline.map(|b| b.loop_closures),
        map_fixed2d: baseline.map(|b| b.map),
        node_sends: sends.0,
        node_resends: sends.1,
        outbox_pending: sends.2,
        nodes_passed: mapper
            .shared
            .metrics
            .nodes_passed
            .load(std::sync::atomic::Ordering::Relaxed),
        store_bytes: std::fs::metadata(args.dir.join("mapper.redb")).map_or(0, |m| m.len()),
        duration_s: args.duration,
        first_lap,
        wall_s: started.elapsed().as_secs_f64(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "map: {} robots, {} nodes, {} edges ({} GPS), {} loop closures ({} between robots), {} connected part(s)",
            report.robots,
            report.nodes,
            report.edges,
            report.gps_edges,
            report.loop_closures,
            report.inter_robot_closures,
            report.components
        );
        let aligned = if ate_aligned {
            " (map fitted to the truth)"
        } else {
            ""
        };
        match baseline {
            Some(fixed) => println!(
                "ATE: leveled scans {ate:.3} m, fixed 2D scanner {:.3} m ({:.1}x worse)",
                fixed.ate_rmse_m,
                fixed.ate_rmse_m / ate
            ),
            None => println!("ATE: leveled scans {ate:.3} m{aligned}"),
        }
        let line = |who: &str, s: &MapScore| {
            println!(
                "grid ({who}): {:.1} % of {} obstacles shown, {:.2} % of obstacle cells free, {:.1} % of the free space near the paths free",
                100.0 * s.obstacle_recall,
                s.obstacles,
                100.0 * s.false_free,
                100.0 * s.free_coverage
            )
        };
        if let Some(s) = &report.map {
            line("leveled scans", s);
        }
        if let Some(s) = &report.map_fixed2d {
            line("fixed 2D scanner", s);
        }
    }
    if args.serve {
        if !args.json {
            println!("serving the dashboard at {dashboard} until Ctrl-C (or SIGTERM)");
        }
        let _ = ctrl_c.await;
    } else {
        ctrl_c.abort();
    }
    mapper.stop().await
}

/// The map's node positions against the ground truth (RMSE, m); fitted to it first when the
/// map has a frame of its own.
fn ate_of(view: &fleetmap::FleetView, truth: &[FleetRobot], epoch_ns: u64, aligned: bool) -> f64 {
    let leveled_truth = |robot: usize, stamp_ns: u64| {
        let t = &truth[robot];
        let pose = t.truth_at(stamp_ns - epoch_ns);
        Pose2::from_isometry3(&leveling::leveled_frame(&pose, &t.scanner().mount).inverse())
    };
    let pairs = view.nodes.iter().zip(&view.poses).map(|(n, p)| {
        let robot: usize = view.robots[n.robot].id["robot".len()..]
            .parse()
            .expect("robotN");
        (*p, leveled_truth(robot, n.stamp_ns))
    });
    if aligned {
        slam::aligned_position_rmse(pairs)
    } else {
        slam::position_rmse(pairs)
    }
}

/// Prints one line every few seconds while the robots drive: nodes mapped, closures, the
/// time driven and left.
async fn show_progress(
    shared: std::sync::Arc<mapper::views::Shared>,
    epoch_ns: u64,
    duration_s: f64,
) {
    let started = Instant::now();
    loop {
        tokio::time::sleep(std::time::Duration::from_secs(5)).await;
        let Some(view) = shared.fleet(FLEET) else {
            continue;
        };
        let newest_ns = view
            .nodes
            .iter()
            .map(|n| n.stamp_ns)
            .max()
            .unwrap_or(epoch_ns);
        let driven = newest_ns.saturating_sub(epoch_ns) as f64 * 1e-9;
        println!(
            "… {} nodes mapped, {} loop closures; {:.0} of {:.0} s driven ({:.0} s left), {:.0} s wall",
            view.poses.len(),
            view.stats.loop_closures,
            driven.min(duration_s),
            duration_s,
            (duration_s - driven).max(0.0),
            started.elapsed().as_secs_f64()
        );
    }
}

/// The map after the first lap of the first robot's loop.
#[derive(Serialize)]
struct FirstLap {
    nodes: usize,
    ate_rmse_m: f64,
    store_bytes: u64,
}

/// Waits until robot0's odometry is past its first lap, solves the map and takes its
/// figures (the robots drive on meanwhile).
async fn after_first_lap(
    mapper: &mapper::Running,
    truth: &[FleetRobot<'_>],
    epoch_ns: u64,
    aligned: bool,
    dir: &std::path::Path,
) -> Result<FirstLap> {
    let lap_ns = sim::Route::park_loop(0)
        .and_then(|r| r.lap_ns())
        .context("the first loop's lap time")?;
    loop {
        let at = mapper
            .shared
            .live
            .lock()
            .expect("live lock")
            .get(&(FLEET.to_owned(), "robot0".to_owned()))
            .map(|l| l.stamp_ns);
        if at.is_some_and(|t| t >= epoch_ns + lap_ns) {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    mapper.optimize(FLEET).await?;
    let view = mapper.shared.fleet(FLEET).context("no node after a lap")?;
    Ok(FirstLap {
        nodes: view.poses.len(),
        ate_rmse_m: ate_of(&view, truth, epoch_ns, aligned),
        store_bytes: std::fs::metadata(dir.join("mapper.redb")).map_or(0, |m| m.len()),
    })
}

fn robot_config(args: &DemoArgs, i: usize) -> EdgeConfig {
    EdgeConfig {
        fleet: FLEET.into(),
        robot: format!("robot{i}"),
        zenoh: SessionConfig::client(&args.zenoh),
        outbox_path: args.dir.join(format!("robot{i}-outbox.redb")),
        speed: args.speed,
        source: SourceConfig::Sim(SimSourceConfig {
            loop_index: i,
            seed: args.seed,
            duration_s: args.duration,
            scattered_start: args.scatter_starts,
            gps: !args.no_gps,
        }),
        ..EdgeConfig::default()
    }
}
