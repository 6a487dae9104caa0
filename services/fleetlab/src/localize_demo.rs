//! `levelmap demo-localize`: localization on a published map, measured against the
//! simulator's ground truth. Three robots survey the park (as `levelmap demo`); the map is
//! frozen as version 1 through the HTTP API; a fourth robot, set to `localize` on it, drives
//! from a place the mapper does not know, without GPS. Its nodes are found on the version at
//! the node rate (the first by the global search) and the network must not grow. Then its
//! captured scans are sent to `POST …/localize` with a prior near the truth, with none, and
//! with one 20 m off (a lost robot), each answer scored against the truth.

use crate::FLEET;
use anyhow::{Context, Result, ensure};
use clap::Args;
use edge::{EdgeConfig, SimSourceConfig, SourceConfig};
use http::{HttpFigures, MapErrors, get_json, localize_over_http, percentile, post_json, put_json};
use mapper::MapperConfig;
use runtime::session::SessionConfig;
use serde::Serialize;
use serde_json::{Value, json};
use sim::FleetRobot;
use slam::Pose2;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The write token of the lab's mapper (freeze a version, set modes).
mod http;

const TOKEN: &str = "levelmap-lab";
/// The robot that localizes first (by its id): it drives the dell loop from the dock,
/// without GPS, where the survey's robot1 drove.
const LOCALIZING: &str = "robot3";

/// A robot that localizes: it drives a park loop from its dock, without GPS, with its own
/// sensor noise.
struct Localizer {
    name: String,
    loop_index: usize,
    seed: u64,
}

/// The robots drive `args.duration` at once in localize mode; each one's figures and ground
/// truth (with its clock's epoch).
async fn localize_drive<'w>(
    args: &LocalizeDemoArgs,
    http: &str,
    map_errors: &MapErrors,
    robots: &[&Localizer],
) -> Result<(Vec<Drive>, Vec<(String, (FleetRobot<'w>, u64))>)> {
    let epoch_ns = runtime::session::now_ns();
    let configs = robots
        .iter()
        .map(|r| {
            let source = SimSourceConfig {
                loop_index: r.loop_index,
                seed: r.seed,
                duration_s: args.duration,
                scattered_start: false,
                gps: false,
            };
            robot_config(args, &r.name, source)
        })
        .collect();
    let reports = drive(configs, epoch_ns).await?;
    let mut drives = Vec::new();
    let mut truths = Vec::new();
    for (r, report) in robots.iter().zip(&reports) {
        let truth = FleetRobot::new(
            edge::park(),
            r.loop_index,
            (args.duration * 1e9) as u64,
            r.seed,
        )
        .expect("a loop");
        let url = format!("{http}/robots/{}/localization", r.name);
        let log = tokio::task::spawn_blocking(move || get_json(&url)).await??;
        drives.push(score_drive(
            &r.name,
            map_errors,
            &log,
            &truth,
            epoch_ns,
            report.localizations,
        )?);
        truths.push((r.name.clone(), (truth, epoch_ns)));
    }
    Ok((drives, truths))
}

/// Run the localization demo: survey, freeze, localize a fourth robot, then localize scans
/// over HTTP.
#[derive(Args, Debug)]
pub struct LocalizeDemoArgs {
    /// How long the three surveying robots drive (s of simulated time).
    #[arg(long, default_value_t = 120.0)]
    pub survey: f64,
    /// How long the localizing robot drives (s of simulated time).
    #[arg(long, default_value_t = 120.0)]
    pub duration: f64,
    /// Scans sent to `POST …/localize` (the localizing robot's first ones), each three times.
    #[arg(long, default_value_t = 100)]
    pub scans: usize,
    /// Simulated time per wall-clock time: 1 is real time, 0 as fast as the machine goes.
    #[arg(long, default_value_t = 0.0)]
    pub speed: f64,
    /// The mapper's HTTP address.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: String,
    /// The mapper's Zenoh router endpoint; robots connect to it.
    #[arg(long, default_value = "tcp/127.0.0.1:7447")]
    pub zenoh: String,
    /// Folder for the mapper's store and the robots' outboxes (new, empty or an earlier run's,
    /// emptied at start; any other is refused).
    #[arg(long, value_name = "DIR", default_value = "levelmap-demo-localize")]
    pub dir: PathBuf,
    /// Seed of the sensors' noise (the localizing robot's is this + 1).
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    survey_nodes: usize,
    survey_ate_m: f64,
    version: u64,
    /// Network nodes after the localizing drive: equal to `survey_nodes` when it did not grow.
    nodes_after: usize,
    /// The fourth robot.
    localizing: Drive,
    /// Three more, set by the fleet's mode, whose scans (after the fourth's) go to step 3.
    more: Vec<Drive>,
    http: BTreeMap<&'static str, HttpFigures>,
    wall_s: f64,
}

/// The localizing robot's nodes as the mapper answered them.
#[derive(Serialize)]
struct Drive {
    robot: String,
    nodes: usize,
    localized: usize,
    dead_reckoned: usize,
    lost: usize,
    /// The first node found: its search ("global": the robot's start was unknown) and error.
    first_search: Option<String>,
    first_error_m: Option<f64>,
    /// Over the nodes found (status localized).
    rmse_m: f64,
    max_error_m: f64,
    within_10cm: f64,
    /// Over every node with a pose (found or carried forward by odometry).
    rmse_all_m: f64,
    /// Over the nodes found, against where the map puts the place (`MapErrors::relative`).
    rmse_of_map_m: f64,
    median_ms: f64,
    /// The robot's own count of localizations received.
    received_by_robot: u64,
}

/// Runs the demo and prints its figures.
pub fn run(args: &LocalizeDemoArgs) -> Result<()> {
    crate::runtime()?.block_on(run_async(args))
}

fn robot_config(args: &LocalizeDemoArgs, robot: &str, source: SimSourceConfig) -> EdgeConfig {
    EdgeConfig {
        fleet: FLEET.into(),
        robot: robot.into(),
        zenoh: SessionConfig::client(&args.zenoh),
        outbox_path: args.dir.join(format!("{robot}-outbox.redb")),
        speed: args.speed,
        source: SourceConfig::Sim(source),
        ..EdgeConfig::default()
    }
}

async fn drive(configs: Vec<EdgeConfig>, epoch_ns: u64) -> Result<Vec<edge::EdgeReport>> {
    let mut robots = Vec::new();
    for config in configs {
        let source = edge::open_source(&config, epoch_ns)?;
        robots.push(tokio::spawn(edge::run(
            config,
            source,
            std::future::pending(),
        )));
    }
    let mut reports = Vec::new();
    for robot in robots {
        let report = robot.await??;
        ensure!(
            report.outbox_pending == 0,
            "{}: nodes left unacked",
            report.robot
        );
        reports.push(report);
    }
    Ok(reports)
}

/// The leveled frame of a simulated robot at `stamp_ns` (sim time): what a node's pose is.
fn leveled_truth(robot: &FleetRobot<'_>, t_ns: u64) -> Pose2 {
    let pose = robot.truth_at(t_ns);
    Pose2::from_isometry3(&leveling::leveled_frame(&pose, &robot.scanner().mount).inverse())
}

fn distance(a: &Pose2, b: &Pose2) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

async fn run_async(args: &LocalizeDemoArgs) -> Result<()> {
    let started = Instant::now();
    let mapper = mapper::start(MapperConfig {
        token: TOKEN.into(),
        ..crate::park_mapper_config(&args.dir, &args.http, &args.zenoh)?
    })
    .await?;
    let http = format!("http://{}/api/v1/fleets/{FLEET}", mapper.http_addr);
    let say = |line: String| {
        if !args.json {
            println!("{line}");
        }
    };
    let epoch_ns = runtime::session::now_ns();

    // 1. The survey, frozen as a version.
    let survey: Vec<EdgeConfig> = (0..3)
        .map(|i| {
            let source = SimSourceConfig {
                loop_index: i,
                seed: args.seed,
                duration_s: args.survey,
                scattered_start: false,
                gps: true,
            };
            robot_config(args, &format!("robot{i}"), source)
        })
        .collect();
    drive(survey, epoch_ns).await?;
    mapper.optimize(FLEET).await?;
    let view = mapper
        .shared
        .fleet(FLEET)
        .context("no node reached the mapper")?;
    let survey_nodes = view.poses.len();
    let survey_ate_m = {
        let duration_ns = (args.survey * 1e9) as u64;
        let truth: Vec<FleetRobot> = (0..3)
            .map(|i| FleetRobot::new(edge::park(), i, duration_ns, args.seed).expect("a loop"))
            .collect();
        let pairs: Vec<(Pose2, Pose2)> = view
            .nodes
            .iter()
            .zip(&view.poses)
            .map(|(n, p)| {
                let i: usize = view.robots[n.robot].id["robot".len()..]
                    .parse()
                    .expect("robotN");
                (*p, leveled_truth(&truth[i], n.stamp_ns - epoch_ns))
            })
            .collect();
        (slam::position_rmse(pairs.iter().copied()), MapErrors(pairs))
    };
    let (survey_ate_m, map_errors) = survey_ate_m;
    say(format!(
        "survey: {survey_nodes} nodes, ATE {survey_ate_m:.3} m"
    ));
    let http_c = http.clone();
    let version = tokio::task::spawn_blocking(move || -> Result<u64> {
        let frozen = post_json(&format!("{http_c}/versions"), &json!({}))?;
        let version = frozen["version"].as_u64().context("a version number")?;
        let modes = json!({"mode": "localize", "version": version, "robots": [LOCALIZING]});
        put_json(&format!("{http_c}/modes"), &modes)?;
        Ok(version)
    })
    .await??;
    say(format!(
        "version {version} frozen; {LOCALIZING} set to localize on it"
    ));

    // 2. The fourth robot drives in localize mode, set by its id; then three more, set by
    // the fleet's mode. Every node they send is captured for step 3.
    let captured: Arc<Mutex<BTreeMap<(String, u64), wire::Node>>> = Arc::default();
    let session = SessionConfig::client(&args.zenoh)
        .open(runtime::session::Role::Client)
        .await?;
    let _capture = {
        let captured = captured.clone();
        session
            .declare_subscriber(wire::all_robots_key_expr(FLEET, wire::Topic::Node)?)
            .callback(move |sample| {
                if let Ok(node) = wire::decode_node(&sample.payload().to_bytes()) {
                    let key = (node.robot.clone(), node.node_seq);
                    captured.lock().expect("capture").insert(key, node);
                }
            })
            .await
            .map_err(anyhow::Error::from_boxed)?
    };
    let localizer = |robot: usize| Localizer {
        name: format!("robot{robot}"),
        loop_index: (robot + 1) % 3,
        seed: args.seed + robot as u64 - 2,
    };
    let fourth = localizer(3);
    let (drive_fourth, truth_fourth) = localize_drive(args, &http, &map_errors, &[&fourth]).await?;
    let localizing = drive_fourth.into_iter().next().context("robot3's drive")?;
    say(format!(
        "{LOCALIZING}: {} nodes, {} localized: RMSE {:.3} m against the truth (max {:.3} m), {:.3} m against the map; first by the {} search",
        localizing.nodes,
        localizing.localized,
        localizing.rmse_m,
        localizing.max_error_m,
        localizing.rmse_of_map_m,
        localizing.first_search.as_deref().unwrap_or("no"),
    ));
    let http_c = http.clone();
    tokio::task::spawn_blocking(move || {
        put_json(
            &format!("{http_c}/modes"),
            &json!({"mode": "localize", "version": version}),
        )
    })
    .await??;
    let more: Vec<Localizer> = (4..7).map(localizer).collect();
    let (drive_more, truth_more) =
        localize_drive(args, &http, &map_errors, &more.iter().collect::<Vec<_>>()).await?;
    for d in &drive_more {
        say(format!(
            "{}: {} nodes, {} localized: RMSE {:.3} m against the truth, {:.3} m against the map",
            d.robot, d.nodes, d.localized, d.rmse_m, d.rmse_of_map_m
        ));
    }
    let nodes_after = mapper.shared.fleet(FLEET).map_or(0, |v| v.poses.len());
    say(format!(
        "network: {survey_nodes} nodes after the survey, {nodes_after} after the localizing drives"
    ));

    // 3. The captured scans over HTTP: a prior near the truth, none, one 20 m off.
    let captured = std::mem::take(&mut *captured.lock().expect("capture"));
    let truths: BTreeMap<String, (FleetRobot, u64)> =
        truth_fourth.into_iter().chain(truth_more).collect();
    let scans: Vec<(Pose2, Value)> = captured
        .values()
        .filter_map(|n| {
            let (truth, epoch) = truths.get(&n.robot)?;
            let (bearings, ranges): (Vec<f32>, Vec<f32>) = n
                .scan
                .beams
                .iter()
                .map(|b| (b.bearing_rad, b.range_m.unwrap_or(0.0)))
                .unzip();
            let truth_pose = leveled_truth(truth, n.stamp_ns - epoch);
            Some((
                truth_pose,
                json!({"bearings_rad": bearings, "ranges_m": ranges}),
            ))
        })
        .take(args.scans)
        .collect();
    ensure!(
        scans.len() == args.scans,
        "captured {} scans of the {} asked for",
        scans.len(),
        args.scans
    );
    let http_c = http.clone();
    let errors = map_errors.clone();
    let figures =
        tokio::task::spawn_blocking(move || localize_over_http(&http_c, &scans, &errors)).await??;
    for (kind, f) in &figures {
        say(format!(
            "POST localize, {kind}: {}/{} found, within 0.10 m of the truth {:.0} %, of the map {:.0} %, median {:.1} ms, p90 {:.1} ms ({} global)",
            f.found,
            f.requests,
            100.0 * f.share_within_10cm,
            100.0 * f.share_within_10cm_of_map,
            f.median_ms,
            f.p90_ms,
            f.global_searches
        ));
    }
    let report = Report {
        survey_nodes,
        survey_ate_m,
        version,
        nodes_after,
        localizing,
        more: drive_more,
        http: figures,
        wall_s: started.elapsed().as_secs_f64(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    drop(session);
    mapper.stop().await
}

fn score_drive(
    robot: &str,
    map_errors: &MapErrors,
    log: &Value,
    truth: &FleetRobot<'_>,
    epoch_ns: u64,
    received: u64,
) -> Result<Drive> {
    let entries = log.as_array().context("a list of localizations")?;
    let mut errors_found = Vec::new();
    let mut errors_all = Vec::new();
    let mut errors_of_map = Vec::new();
    let mut took = Vec::new();
    let (mut first_search, mut first_error_m) = (None, None);
    let mut counts = BTreeMap::<String, usize>::new();
    for e in entries {
        let status = e["status"].as_str().context("a status")?.to_owned();
        *counts.entry(status.clone()).or_default() += 1;
        took.push(e["took_ms"].as_f64().unwrap_or(f64::NAN));
        let Ok(pose) = serde_json::from_value::<Pose2>(e["pose"].clone()) else {
            continue;
        };
        let stamp = e["stamp_ns"].as_u64().context("a stamp")?;
        let truth_pose = leveled_truth(truth, stamp - epoch_ns);
        let error = distance(&pose, &truth_pose);
        errors_all.push(error);
        if status == "localized" {
            if first_search.is_none() {
                first_search = e["search"].as_str().map(str::to_owned);
                first_error_m = Some(error);
            }
            errors_found.push(error);
            errors_of_map.push(map_errors.relative(&pose, &truth_pose));
        }
    }
    let rmse = |v: &[f64]| (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
    Ok(Drive {
        robot: robot.to_owned(),
        nodes: entries.len(),
        localized: counts.get("localized").copied().unwrap_or(0),
        dead_reckoned: counts.get("dead_reckoned").copied().unwrap_or(0),
        lost: counts.get("lost").copied().unwrap_or(0),
        first_search,
        first_error_m,
        rmse_m: rmse(&errors_found),
        max_error_m: errors_found.iter().copied().fold(0.0, f64::max),
        within_10cm: errors_found.iter().filter(|e| **e <= 0.10).count() as f64
            / errors_found.len().max(1) as f64,
        rmse_all_m: rmse(&errors_all),
        rmse_of_map_m: rmse(&errors_of_map),
        median_ms: percentile(&mut took, 0.5),
        received_by_robot: received,
    })
}
