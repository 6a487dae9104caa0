//! `levelmap bench-fleet`: many robots against one mapper on this machine, over real Zenoh TCP
//! on loopback, measured from outside through HTTP: how long a published node takes to become
//! visible on the API's event stream, and how fast robot pose queries are answered meanwhile.

mod foxglove;
mod http;
mod live;

pub(crate) use http::{agent, follow_events, query_poses};

use crate::FLEET;
use anyhow::{Context, Result};
use clap::Args;
use edge::{NodeBuilder, SimSource, SimSourceConfig, Source, SourceEvent};
use runtime::session::{Role, SessionConfig};
use serde::Serialize;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use wire::Node;
use zenoh::pubsub::Publisher;

/// Load-test the mapper: N simulated robots publishing nodes and odometry over Zenoh, with
/// pose queries over HTTP at the same time.
#[derive(Args, Debug)]
pub struct BenchFleetArgs {
    /// Robots publishing.
    #[arg(long, default_value_t = 100)]
    pub robots: usize,
    /// How long they publish (s).
    #[arg(long, default_value_t = 30.0)]
    pub duration: f64,
    /// Nodes per robot per second.
    #[arg(long, default_value_t = 1.0)]
    pub node_rate: f64,
    /// Odometry messages per robot per second.
    #[arg(long, default_value_t = 10.0)]
    pub odometry_rate: f64,
    /// HTTP pose queries per second, spread over `--connections` keep-alive connections.
    #[arg(long, default_value_t = 2000.0)]
    pub query_rate: f64,
    /// Keep-alive HTTP connections the pose queries use.
    #[arg(long, default_value_t = 4)]
    pub connections: usize,
    /// Zenoh client sessions the robots share (robots are grouped onto them).
    #[arg(long, default_value_t = 10)]
    pub sessions: usize,
    /// The mapper's Zenoh endpoint.
    #[arg(long, default_value = "tcp/127.0.0.1:7448")]
    pub zenoh: String,
    /// The mapper's HTTP address (port 0: any free one).
    #[arg(long, default_value = "127.0.0.1:0")]
    pub http: String,
    /// Folder for the mapper's store (new, empty or an earlier run's, emptied at start; any other
    /// is refused).
    #[arg(long, default_value = "levelmap-bench-fleet")]
    pub dir: std::path::PathBuf,
    /// Print one JSON object of figures.
    #[arg(long)]
    pub json: bool,
    /// Keep the mapper serving (HTTP API and dashboard) after the run, until Ctrl-C.
    #[arg(long)]
    pub serve: bool,
    /// Nodes carry their segmented 3D cloud as the edge's defaults reduce it (`[cloud]` of
    /// deploy/edge.toml: about 40 KB a node); without it, none do.
    #[arg(long)]
    pub clouds: bool,
    /// HTTP clients of robots' live feeds (`…/robots/{robot}/live`, one robot each, in turn),
    /// reading during the whole run; with any, the report has their delays and rates, and
    /// the map windows around the robots after the run.
    #[arg(long, default_value_t = 0)]
    pub live_clients: usize,
    /// Serve the mapper's Foxglove feed (`[foxglove]`, on a free loopback port) during the run.
    #[arg(long)]
    pub foxglove: bool,
    /// Foxglove clients subscribing to every channel of the feed during the whole run (with
    /// any, `--foxglove` is implied); the report has what they received.
    #[arg(long, default_value_t = 0)]
    pub foxglove_clients: usize,
    /// The Foxglove clients leave the grids out (every other channel still).
    #[arg(long)]
    pub foxglove_no_grid: bool,
}

/// Percentiles of a sample (named in ms, the unit of most uses).
#[derive(Serialize, Default)]
pub(crate) struct Percentiles {
    pub count: usize,
    pub p50_ms: f64,
    pub p90_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

impl Percentiles {
    pub(crate) fn of(mut ms: Vec<f64>) -> Percentiles {
        if ms.is_empty() {
            return Percentiles::default();
        }
        ms.sort_by(f64::total_cmp);
        let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
        Percentiles {
            count: ms.len(),
            p50_ms: at(0.5),
            p90_ms: at(0.9),
            p99_ms: at(0.99),
            max_ms: *ms.last().expect("non-empty"),
        }
    }
}

#[derive(Serialize)]
struct BenchReport {
    robots: usize,
    duration_s: f64,
    cores: usize,
    nodes_published: usize,
    nodes_visible: usize,
    odometry_published: u64,
    /// From a node's publication to its event on `/api/v1/events` (HTTP).
    publish_to_http: Percentiles,
    /// `GET /api/v1/fleets/park/robots/{robot}/pose`, keep-alive connections, during the load.
    pose_queries: Percentiles,
    pose_query_rate_achieved: f64,
    pose_query_errors: u64,
    map_nodes: usize,
    /// Nodes passed over covered ground (located, not added: docs/services.md, "Bounded
    /// growth").
    nodes_passed: u64,
    map_edges: usize,
    optimizations: u64,
    /// The live feeds' clients (`--live-clients`).
    live: Option<live::LiveReport>,
    /// 40 m windows around the robots, after the run (`--live-clients`).
    windows: Option<live::WindowReport>,
    /// The Foxglove feed's clients (`--foxglove-clients`), each what it received.
    foxglove_clients: Option<Vec<foxglove::FoxgloveClient>>,
}

/// The simulated robot of the park's loop `loop_index` whose scans the pools replay, for
/// `nodes` nodes (a scan every 4 s), its clock from 0.
pub(crate) fn loop_source(loop_index: usize, nodes: usize) -> SimSource {
    let config = SimSourceConfig {
        loop_index,
        seed: 7,
        duration_s: nodes as f64 * 4.0,
        ..SimSourceConfig::default()
    };
    SimSource::new(&config, 0, 10.0).expect("park loop")
}

/// The nodes of the park's three loops, each a node per scan, to be replayed.
pub(crate) fn node_pool(per_loop: usize, clouds: bool) -> Vec<Vec<Node>> {
    (0..3)
        .map(|loop_index| {
            let mut source = loop_source(loop_index, per_loop);
            let mut builder =
                NodeBuilder::new(FLEET, "r", Default::default(), Default::default(), 0);
            if clouds {
                builder = builder.with_cloud(&edge::CloudParams::default());
            }
            let mut nodes = Vec::new();
            while nodes.len() < per_loop {
                let Some(event) = source.next_event() else {
                    break;
                };
                if let SourceEvent::Scan(scan) = event {
                    nodes.extend(builder.offer(&scan).expect("the simulator's scans level"));
                }
            }
            nodes
        })
        .collect()
}

/// Node `k` of chain `chain_id` of a robot of `fleet` as sent: a pool node moved by
/// `offset_m` (east, north: odometry and GPS), renamed, restamped, encoded as an outbox keeps
/// it with its send fields appended.
pub(crate) fn robot_node(
    template: &Node,
    (fleet, robot): (&str, &str),
    (chain_id, k): (u64, u64),
    offset_m: [f64; 2],
    stamp_ns: u64,
) -> Vec<u8> {
    let mut node = template.clone().into_parts();
    node.fleet = fleet.to_owned();
    node.robot = robot.to_owned();
    node.node_seq = k;
    node.chain_id = chain_id;
    // Every stamp moves by the same time: the fixes keep their own (earlier, increasing)
    // times relative to the scan's start.
    let shift = stamp_ns.saturating_sub(template.stamp_ns);
    node.stamp_ns += shift;
    node.scan.stamp_ns += shift;
    node.odometry.stamp_ns += shift;
    node.odometry.pose.translation.x += offset_m[0];
    node.odometry.pose.translation.y += offset_m[1];
    let datum = sim::PARK_DATUM;
    for g in &mut node.gps {
        g.stamp_ns += shift;
        let mut enu = datum.geodetic_to_enu(&g.position);
        enu.x += offset_m[0];
        enu.y += offset_m[1];
        g.position = datum.enu_to_geodetic(&enu);
    }
    if k == 0 {
        node.odometry_delta = None;
    }
    wire::node_as_sent(&node.encode(), 0, k + 1, stamp_ns)
}

/// Runs the bench: a mapper, simulated robots over Zenoh, HTTP queries; prints the figures.
pub fn run(args: &BenchFleetArgs) -> Result<()> {
    crate::runtime()?.block_on(run_async(args))
}

async fn run_async(args: &BenchFleetArgs) -> Result<()> {
    anyhow::ensure!(
        args.robots > 0 && args.sessions > 0,
        "need robots and sessions"
    );
    let nodes_per_robot = (args.duration * args.node_rate).ceil().max(1.0) as usize;
    if !args.json {
        eprintln!("simulating the park's loops for {nodes_per_robot} nodes each…");
    }
    let clouds = args.clouds;
    let pool = tokio::task::spawn_blocking(move || node_pool(nodes_per_robot, clouds)).await?;

    let mapper = mapper::start(crate::park_mapper_config(
        &args.dir,
        &args.http,
        &args.zenoh,
    )?)
    .await?;
    let http = mapper.http_addr.to_string();
    let feed = match args.foxglove || args.foxglove_clients > 0 {
        true => {
            let config = mapper::config::FoxgloveConfig {
                enabled: true,
                listen: "127.0.0.1:0".into(),
                ..Default::default()
            };
            let tokens = mapper::tokens::Tokens::new("", "");
            let (shared, clouds) = (mapper.shared.clone(), mapper.clouds.clone());
            Some(foxglove_feed::start(&config, tokens, shared, clouds).await?)
        }
        false => None,
    };
    let foxglove_stop = Arc::new(AtomicBool::new(false));
    let foxglove_clients: Vec<_> = match &feed {
        Some(feed) => (0..args.foxglove_clients)
            .map(|_| {
                let url = format!("ws://{}", feed.addr);
                let no_grid = args.foxglove_no_grid;
                foxglove::start(url, no_grid, foxglove_stop.clone())
            })
            .collect(),
        None => Vec::new(),
    };

    // The event stream, timestamped on receipt.
    let seen: Arc<Mutex<HashMap<(String, u64), Instant>>> = Arc::default();
    let stop = Arc::new(AtomicBool::new(false));
    let sse = {
        let (http, seen, stop) = (http.clone(), seen.clone(), stop.clone());
        std::thread::spawn(move || follow_events(&http, &seen, &stop))
    };

    // Robots on shared client sessions, publishers matched before the clock starts.
    let mut sessions = Vec::new();
    for _ in 0..args.sessions.min(args.robots) {
        sessions.push(
            SessionConfig::client(&args.zenoh)
                .open(Role::Client)
                .await?,
        );
    }
    let mut publishers = Vec::new();
    for r in 0..args.robots {
        let session = &sessions[r % sessions.len()];
        let robot = format!("robot{r}");
        let (node, odom) = robot_publishers(session, FLEET, &robot).await?;
        publishers.push((robot, node, odom));
    }
    for (robot, node, _) in &publishers {
        wait_matched(node, robot, Instant::now() + Duration::from_secs(10)).await?;
    }

    // Live feed clients, during the whole run; they stop half a second before the robots
    // do (a feed without odometry sends nothing that would wake a reader).
    let live_stop = Arc::new(AtomicBool::new(false));
    let live_clients: Vec<_> = (0..args.live_clients)
        .map(|c| {
            let (http, stop) = (http.clone(), live_stop.clone());
            let robot = c % args.robots;
            std::thread::spawn(move || live::follow_live(&http, robot, &stop))
        })
        .collect();

    // Pose queries, during the whole run.
    let queries = {
        let per_connection = args.query_rate / args.connections.max(1) as f64;
        let paths: Arc<Vec<String>> = Arc::new(
            (0..args.robots)
                .map(|r| format!("/api/v1/fleets/{FLEET}/robots/robot{r}/pose"))
                .collect(),
        );
        (0..args.connections)
            .map(|c| {
                let (http, stop, paths) = (http.clone(), stop.clone(), paths.clone());
                std::thread::spawn(move || query_poses(&http, &paths, per_connection, c, &stop))
            })
            .collect::<Vec<_>>()
    };

    if !args.json {
        eprintln!(
            "{} robots publishing for {} s: {} nodes/s, {} odometry/s…",
            args.robots,
            args.duration,
            args.robots as f64 * args.node_rate,
            args.robots as f64 * args.odometry_rate
        );
    }
    let sent: Arc<Mutex<HashMap<(String, u64), Instant>>> = Arc::default();
    let started = Instant::now();
    let epoch = runtime::session::now_ns();
    let tick = Duration::from_secs_f64(1.0 / args.odometry_rate.max(args.node_rate));
    let node_every = (args.odometry_rate.max(args.node_rate) / args.node_rate).round() as u64;
    let mut odometry_published = 0u64;
    let mut interval = tokio::time::interval(tick);
    let mut step = 0u64;
    let mut published = 0usize;
    let mut live_stopped = None;
    while started.elapsed().as_secs_f64() < args.duration {
        interval.tick().await;
        if live_stopped.is_none() && started.elapsed().as_secs_f64() >= args.duration - 0.5 {
            live_stop.store(true, Ordering::SeqCst);
            live_stopped = Some(Instant::now());
        }
        let k = step / node_every.max(1);
        let node_turn = step % node_every.max(1);
        for (r, (robot, node_pub, odom_pub)) in publishers.iter().enumerate() {
            let template_list = &pool[r % 3];
            let Some(template) = template_list.get(k as usize) else {
                continue;
            };
            let east = (r / 3) as f64 * 500.0;
            let stamp = epoch + started.elapsed().as_nanos() as u64;
            // Robots take turns within the node period, as real ones would not be in step.
            if node_turn == (r as u64 % node_every.max(1)) && (k as usize) < nodes_per_robot {
                // One chain per robot, from node 0: chain ids are per robot.
                let node = robot_node(template, (FLEET, robot), (1, k), [east, 0.0], stamp);
                sent.lock()
                    .expect("sent")
                    .insert((robot.clone(), k), Instant::now());
                node_pub
                    .put(node)
                    .await
                    .map_err(anyhow::Error::from_boxed)?;
                published += 1;
            }
            let mut odometry = template.odometry;
            odometry.stamp_ns = stamp;
            odometry.pose.translation.x += east;
            let odometry = wire::encode_odometry(FLEET, robot, &odometry, step, stamp);
            if odom_pub.put(odometry).await.is_ok() {
                odometry_published += 1;
            }
        }
        step += 1;
    }
    // Let the last nodes through.
    let deadline = Instant::now() + Duration::from_secs(30);
    while seen.lock().expect("seen").len() < published && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    stop.store(true, Ordering::SeqCst);
    live_stop.store(true, Ordering::SeqCst);
    let stopped = live_stopped.unwrap_or_else(Instant::now);
    let mut clients = Vec::new();
    for c in live_clients {
        clients.push(
            c.join()
                .map_err(|_| anyhow::anyhow!("live client thread"))?,
        );
    }
    let live = (args.live_clients > 0).then(|| live::LiveReport::of(clients, stopped));
    foxglove_stop.store(true, Ordering::SeqCst);
    let mut foxglove_got = Vec::new();
    for c in foxglove_clients {
        foxglove_got.push(
            c.join()
                .map_err(|_| anyhow::anyhow!("Foxglove client thread"))??,
        );
    }
    let windows = (args.live_clients > 0).then(|| live::query_windows(&http, args.robots));
    let mut query_ms = Vec::new();
    let mut query_errors = 0;
    let query_time = started.elapsed().as_secs_f64();
    for q in queries {
        let queried = q.join().map_err(|_| anyhow::anyhow!("query thread"))?;
        query_ms.extend(queried.ms);
        query_errors += queried.errors + queried.unavailable;
    }
    let latencies: Vec<f64> = {
        let sent = sent.lock().expect("sent");
        let seen = seen.lock().expect("seen");
        sent.iter()
            .filter_map(|(key, t0)| {
                Some(seen.get(key)?.saturating_duration_since(*t0).as_secs_f64() * 1e3)
            })
            .collect()
    };
    let view = mapper
        .shared
        .fleet(FLEET)
        .context("no node reached the mapper")?;
    let report = BenchReport {
        robots: args.robots,
        duration_s: args.duration,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        nodes_published: published,
        nodes_visible: latencies.len(),
        nodes_passed: mapper
            .shared
            .metrics
            .nodes_passed
            .load(std::sync::atomic::Ordering::Relaxed),
        odometry_published,
        publish_to_http: Percentiles::of(latencies),
        pose_query_rate_achieved: query_ms.len() as f64 / query_time,
        pose_queries: Percentiles::of(query_ms),
        pose_query_errors: query_errors,
        map_nodes: view.poses.len(),
        map_edges: view.edges.len(),
        optimizations: mapper.shared.metrics.optimizations.load(Ordering::Relaxed),
        live,
        windows,
        foxglove_clients: (args.foxglove_clients > 0).then_some(foxglove_got),
    };
    for s in sessions {
        s.close().await.map_err(anyhow::Error::from_boxed)?;
    }
    drop(sse);
    let report_text = if args.json {
        serde_json::to_string_pretty(&report)?
    } else {
        let (p, q) = (&report.publish_to_http, &report.pose_queries);
        format!(
            "{} robots, {} nodes published, {} visible: publish → HTTP p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
            report.robots,
            report.nodes_published,
            report.nodes_visible,
            p.p50_ms,
            p.p99_ms,
            p.max_ms
        ) + &format!(
            "\npose queries: {} at {:.0}/s, p50 {:.2} ms, p99 {:.2} ms ({} errors)",
            q.count, report.pose_query_rate_achieved, q.p50_ms, q.p99_ms, report.pose_query_errors
        )
    };
    println!("{report_text}");
    if args.serve {
        // The report is out; the map stays up for the dashboard (web/bench/pan.mjs).
        eprintln!(
            "serving http://{http}/ (fleet {FLEET}, {} nodes) until Ctrl-C",
            report.map_nodes
        );
        tokio::signal::ctrl_c().await?;
    }
    if let Some(feed) = feed {
        feed.stop().await;
    }
    mapper.stop().await
}

/// A robot's node publisher (blocking when congested: a bench drops no node) and its
/// odometry publisher, on `session`.
pub(crate) async fn robot_publishers(
    session: &zenoh::Session,
    fleet: &str,
    robot: &str,
) -> Result<(Publisher<'static>, Publisher<'static>)> {
    let node = session
        .declare_publisher(wire::node_key(fleet, robot)?)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
        .map_err(anyhow::Error::from_boxed)?;
    let odometry = session
        .declare_publisher(wire::odom_key(fleet, robot)?)
        .await
        .map_err(anyhow::Error::from_boxed)?;
    Ok((node, odometry))
}

/// Waits until `robot`'s node publisher matches a mapper's subscriber, until `deadline`.
pub(crate) async fn wait_matched(
    node: &Publisher<'_>,
    robot: &str,
    deadline: Instant,
) -> Result<()> {
    while !node
        .matching_status()
        .await
        .map_err(anyhow::Error::from_boxed)?
        .matching()
    {
        anyhow::ensure!(
            Instant::now() < deadline,
            "no mapper's subscriber matched {robot}'s nodes"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    Ok(())
}
