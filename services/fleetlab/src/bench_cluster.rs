//! `levelmap bench-cluster`: the cluster mode (docs/cluster.md) loaded and measured from
//! outside on this machine: three nats-servers, mapper hosts as separate processes with
//! their Zenoh routers meshed, one gateway, and simulated robots spread over the sites, each
//! on a session that lists every router. Measured through the gateway, as users see it: how
//! long a published node takes to show on `/api/v1/events`, how fast robot poses are
//! answered; with `--kill-host`, a host owning sites is SIGKILLed halfway and each site it
//! owned is timed to its first new ack and its first HTTP 200. Afterwards every robot's
//! nodes are counted in its site's map: acked and lost, taken twice, never taken.
//! `--single-machine` runs the same robots and sites against one mapper without
//! `[cluster]`, for the cost of the cluster.

mod count;
mod deployment;
mod robots;

use crate::bench_fleet::{Percentiles, follow_events, node_pool, query_poses, robot_node};
use anyhow::{Context, Result, bail};
use clap::Args;
use count::count_nodes;
use deployment::{Deployment, status};
use robots::Robots;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Load-test the cluster mode: robots over sites on mapper hosts, NATS JetStream and a
/// gateway, all on this machine; measured through the gateway.
#[derive(Args, Debug)]
pub struct BenchClusterArgs {
    /// Robots publishing; robot r maps site r mod --sites.
    #[arg(long, default_value_t = 200)]
    pub robots: usize,
    /// Sites (fleets) `site0`, `site1`, … spread over the hosts.
    #[arg(long, default_value_t = 10)]
    pub sites: usize,
    /// Mapper hosts, each a `levelmap mapper` process with its own store and router.
    #[arg(long, default_value_t = 5)]
    pub hosts: usize,
    /// How long the robots publish (s).
    #[arg(long, default_value_t = 600.0)]
    pub duration: f64,
    /// Nodes per robot per second.
    #[arg(long, default_value_t = 1.0)]
    pub node_rate: f64,
    /// Odometry messages per robot per second.
    #[arg(long, default_value_t = 10.0)]
    pub odometry_rate: f64,
    /// Pose queries per second through the gateway, over `--connections` connections.
    #[arg(long, default_value_t = 1000.0)]
    pub query_rate: f64,
    /// Keep-alive HTTP connections the pose queries use.
    #[arg(long, default_value_t = 4)]
    pub connections: usize,
    /// Zenoh client sessions the robots share, spread over the hosts' routers.
    #[arg(long, default_value_t = 20)]
    pub sessions: usize,
    /// SIGKILL the host owning the most sites (mapper and router) halfway through.
    #[arg(long, conflicts_with = "single_machine")]
    pub kill_host: bool,
    /// The same robots and sites against one mapper without `[cluster]`: no NATS, no
    /// gateway.
    #[arg(long)]
    pub single_machine: bool,
    /// The nats-server binary (2.15); default: `NATS_SERVER_BIN`.
    #[arg(long, value_name = "FILE")]
    pub nats_server: Option<PathBuf>,
    /// Folder of the run's processes: configs, stores, logs (new, empty or an earlier run's,
    /// emptied at start; any other is refused; kept after).
    #[arg(long, default_value = "levelmap-bench-cluster")]
    pub dir: PathBuf,
    /// Print one JSON object of figures.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct BenchClusterReport {
    /// `cluster` or `single-machine`.
    mode: &'static str,
    robots: usize,
    sites: usize,
    hosts: usize,
    nats_servers: usize,
    duration_s: f64,
    cores: usize,
    nodes_published: u64,
    /// Nodes the robots saw acked.
    nodes_acked: u64,
    /// Nodes in their robot's chain in the site's map afterwards (mapped, or passed over
    /// covered ground and located).
    nodes_taken: u64,
    /// Acked, and not in the site's map afterwards.
    acked_nodes_lost: u64,
    /// Nodes in a site's graph more than once (each extra copy counted).
    nodes_duplicated: u64,
    /// Published, and not in the site's map afterwards (acked or not).
    nodes_not_taken: u64,
    /// Nodes the robots sent again (no ack in time, or asked for).
    nodes_resent: u64,
    /// From a node's first publication to its event on `/api/v1/events` through the
    /// gateway (events missed while the stream reconnects are not counted).
    publish_to_http: Percentiles,
    /// `GET /api/v1/fleets/{site}/robots/{robot}/pose` through the gateway.
    pose_queries: Percentiles,
    pose_query_rate_achieved: f64,
    /// 503: the robot's site had no owner then.
    pose_queries_unavailable: u64,
    pose_query_errors: u64,
    /// The sites each host served, at the start and at the end.
    owners_at_start: BTreeMap<String, Vec<String>>,
    owners_at_end: BTreeMap<String, Vec<String>>,
    /// `--kill-host`: the host killed and each site it owned.
    kill: Option<KillReport>,
}

#[derive(Serialize)]
struct KillReport {
    host: String,
    /// When, from the robots' start (s).
    at_s: f64,
    sites: Vec<MovedSite>,
}

#[derive(Serialize)]
struct MovedSite {
    site: String,
    /// From the kill to the first ack that moved on, of any of the site's robots.
    first_ack_ms: Option<f64>,
    /// From the kill to the first 200 of the site's summary through the gateway.
    first_http_200_ms: Option<f64>,
}

/// Runs the bench; prints the figures.
pub fn run(args: &BenchClusterArgs) -> Result<()> {
    if args.robots < args.sites || args.sites == 0 {
        bail!("--robots must be at least --sites, and --sites at least 1");
    }
    if args.kill_host && args.hosts < 2 {
        bail!("--kill-host needs at least two --hosts: the killed host's sites move");
    }
    let sites: Vec<String> = (0..args.sites).map(|s| format!("site{s}")).collect();
    let nodes_per_robot = (args.duration * args.node_rate).ceil().max(1.0) as usize;
    say(
        args,
        &format!("simulating the park's loops for {nodes_per_robot} nodes each…"),
    );
    let pool = node_pool(nodes_per_robot, false);
    let mut deployment = if args.single_machine {
        say(args, "starting one single-machine mapper…");
        Deployment::single_machine(&args.dir, &sites)?
    } else {
        let nats = args
            .nats_server
            .clone()
            .or_else(sitelog::local::nats_server_from_env)
            .context("name the nats-server binary: --nats-server FILE or NATS_SERVER_BIN")?;
        say(
            args,
            &format!(
                "starting 3 nats-servers, {} mapper hosts, a gateway…",
                args.hosts
            ),
        );
        Deployment::cluster(&args.dir, args.hosts, &sites, &nats)?
    };
    deployment
        .wait_served(&sites, Duration::from_secs(120))
        .with_context(|| format!("logs are in {}", args.dir.display()))?;
    if !args.single_machine {
        say(args, "waiting for every site to be on its first host…");
        deployment
            .wait_home(&sites, Duration::from_secs(120))
            .with_context(|| format!("logs are in {}", args.dir.display()))?;
    }
    crate::runtime()?.block_on(drive(args, &sites, &pool, nodes_per_robot, deployment))
}

fn say(args: &BenchClusterArgs, line: &str) {
    if !args.json {
        eprintln!("{line}");
    }
}

async fn drive(
    args: &BenchClusterArgs,
    sites: &[String],
    pool: &[Vec<wire::Node>],
    nodes_per_robot: usize,
    mut deployment: Deployment,
) -> Result<()> {
    let http = deployment.http().to_owned();
    let owners_at_start = deployment.owners();
    say(args, &format!("owners: {owners_at_start:?}"));
    let robots = Robots::connect(
        args.robots,
        args.sessions,
        &deployment.zenoh_endpoints(),
        sites,
    )
    .await?;

    let stop = Arc::new(AtomicBool::new(false));
    let seen: Arc<Mutex<HashMap<(String, u64), Instant>>> = Arc::default();
    let events = {
        let (http, seen, stop) = (http.clone(), seen.clone(), stop.clone());
        // The gateway's stream ends with any host's: read it again.
        std::thread::spawn(move || {
            while !stop.load(Ordering::SeqCst) {
                follow_events(&http, &seen, &stop);
                std::thread::sleep(Duration::from_millis(100));
            }
        })
    };
    let paths: Arc<Vec<String>> = Arc::new(
        robots
            .robots
            .iter()
            .map(|r| format!("/api/v1/fleets/{}/robots/{}/pose", sites[r.site], r.name))
            .collect(),
    );
    let per_connection = args.query_rate / args.connections.max(1) as f64;
    let queries: Vec<_> = (0..args.connections)
        .map(|c| {
            let (http, stop, paths) = (http.clone(), stop.clone(), paths.clone());
            std::thread::spawn(move || query_poses(&http, &paths, per_connection, c, &stop))
        })
        .collect();

    say(
        args,
        &format!(
            "{} robots on {} sites publishing for {} s…",
            args.robots, args.sites, args.duration
        ),
    );
    let sent: Arc<Mutex<HashMap<(String, u64), Instant>>> = Arc::default();
    let started = Instant::now();
    let epoch = runtime::session::now_ns();
    let rate = args.odometry_rate.max(args.node_rate);
    let node_every = ((rate / args.node_rate).round() as u64).max(1);
    let mut interval = tokio::time::interval(Duration::from_secs_f64(1.0 / rate));
    let (mut step, mut published) = (0u64, 0u64);
    let kill_at = args.duration / 2.0;
    let mut kill: Option<(String, Instant, Vec<String>)> = None;
    let mut http_200 = None;
    let mut progress_said = 0;
    while started.elapsed().as_secs_f64() < args.duration {
        interval.tick().await;
        let elapsed = started.elapsed().as_secs_f64();
        if args.kill_host && kill.is_none() && elapsed >= kill_at {
            let owners = deployment.owners();
            let (host, owned) = owners
                .into_iter()
                .max_by_key(|(_, sites)| sites.len())
                .context("no host serves a site")?;
            deployment.kill(&host)?;
            let at = Instant::now();
            say(
                args,
                &format!("killed {host} (owned {owned:?}) at {elapsed:.1} s"),
            );
            http_200 = Some(watch_served(&http, &owned, at));
            kill = Some((host, at, owned));
        }
        if !args.json && elapsed as u64 / 30 > progress_said {
            progress_said = elapsed as u64 / 30;
            let acked: u64 = robots
                .acks
                .iter()
                .map(|a| a.lock().expect("acks").acked.map_or(0, |s| s + 1))
                .sum();
            eprintln!("{elapsed:.0} s: {published} nodes published, {acked} acked");
        }
        let k = step / node_every;
        let node_turn = step % node_every;
        for (r, robot) in robots.robots.iter().enumerate() {
            // A site's robots drive its three loops in turn, each three 500 m east of the
            // three before (as bench-fleet's robots do in one site).
            let in_site = r / args.sites;
            let Some(template) = pool[in_site % 3].get(k as usize) else {
                continue;
            };
            let east = (in_site / 3) as f64 * 500.0;
            let stamp = epoch + started.elapsed().as_nanos() as u64;
            if node_turn == r as u64 % node_every && (k as usize) < nodes_per_robot {
                let fleet = &sites[robot.site];
                let node = robot_node(template, (fleet, &robot.name), (1, k), [east, 0.0], stamp);
                sent.lock()
                    .expect("sent")
                    .insert((robot.name.clone(), k), Instant::now());
                robots.send_node(r, k, node).await;
                published += 1;
            }
            let mut odometry = template.odometry;
            odometry.stamp_ns = stamp;
            odometry.pose.translation.x += east;
            let odometry =
                wire::encode_odometry(&sites[robot.site], &robot.name, &odometry, step, stamp);
            robots.send_odometry(r, odometry).await;
            robots.resend_due(r).await;
        }
        step += 1;
    }

    say(args, "waiting for the last acks…");
    let last_seq =
        |r: usize| (pool[(r / args.sites) % 3].len().min(nodes_per_robot) as u64).checked_sub(1);
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let all_acked =
            (0..args.robots).all(|r| robots.acks[r].lock().expect("acks").acked == last_seq(r));
        if all_acked || Instant::now() > deadline {
            break;
        }
        for r in 0..args.robots {
            robots.resend_due(r).await;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // Events of the last acked nodes.
    tokio::time::sleep(Duration::from_secs(2)).await;
    stop.store(true, Ordering::SeqCst);
    let mut query_ms = Vec::new();
    let (mut unavailable, mut errors) = (0, 0);
    let query_time = started.elapsed().as_secs_f64();
    for q in queries {
        let queried = q.join().map_err(|_| anyhow::anyhow!("query thread"))?;
        query_ms.extend(queried.ms);
        unavailable += queried.unavailable;
        errors += queried.errors;
    }
    drop(events);

    let acked: Vec<Option<u64>> = robots
        .acks
        .iter()
        .map(|a| a.lock().expect("acks").acked)
        .collect();
    let resent: u64 = robots
        .acks
        .iter()
        .map(|a| a.lock().expect("acks").resent)
        .sum();
    let names: Vec<(String, usize)> = robots
        .robots
        .iter()
        .map(|r| (r.name.clone(), r.site))
        .collect();
    let progress = robots.progress.lock().expect("progress").clone();
    robots.close().await?;
    let counted = count_nodes(&http, sites, &names, &acked, &last_seq)?;

    let latencies: Vec<f64> = {
        let (sent, seen) = (sent.lock().expect("sent"), seen.lock().expect("seen"));
        sent.iter()
            .filter_map(|(key, t0)| {
                Some(seen.get(key)?.saturating_duration_since(*t0).as_secs_f64() * 1e3)
            })
            .collect()
    };
    let kill = match kill {
        None => None,
        Some((host, at, owned)) => {
            let served: HashMap<String, Instant> = http_200
                .context("watched")?
                .join()
                .map_err(|_| anyhow::anyhow!("watch thread"))?;
            let ms = |t: Instant| t.saturating_duration_since(at).as_secs_f64() * 1e3;
            Some(KillReport {
                at_s: at.duration_since(started).as_secs_f64(),
                sites: owned
                    .iter()
                    .map(|site| {
                        let index = sites.iter().position(|s| s == site);
                        MovedSite {
                            site: site.clone(),
                            first_ack_ms: progress
                                .iter()
                                .find(|(s, t)| Some(*s) == index && *t > at)
                                .map(|(_, t)| ms(*t)),
                            first_http_200_ms: served.get(site).map(|t| ms(*t)),
                        }
                    })
                    .collect(),
                host,
            })
        }
    };
    let report = BenchClusterReport {
        mode: if args.single_machine {
            "single-machine"
        } else {
            "cluster"
        },
        robots: args.robots,
        sites: args.sites,
        hosts: if args.single_machine { 1 } else { args.hosts },
        nats_servers: if args.single_machine { 0 } else { 3 },
        duration_s: args.duration,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        nodes_published: published,
        nodes_acked: acked.iter().map(|a| a.map_or(0, |s| s + 1)).sum(),
        nodes_taken: counted.taken,
        acked_nodes_lost: counted.acked_lost,
        nodes_duplicated: counted.duplicated,
        nodes_not_taken: counted.not_taken,
        nodes_resent: resent,
        publish_to_http: Percentiles::of(latencies),
        pose_query_rate_achieved: query_ms.len() as f64 / query_time,
        pose_queries: Percentiles::of(query_ms),
        pose_queries_unavailable: unavailable,
        pose_query_errors: errors,
        owners_at_start,
        owners_at_end: deployment.owners(),
        kill,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let (p, q) = (&report.publish_to_http, &report.pose_queries);
        println!(
            "{} mode, {} robots on {} sites: {} nodes published, {} acked, {} in the maps; \
             {} acked lost, {} duplicated\npublish → HTTP p50 {:.1} ms, p99 {:.1} ms; pose \
             queries p50 {:.2} ms, p99 {:.2} ms ({} unavailable, {} errors)",
            report.mode,
            report.robots,
            report.sites,
            report.nodes_published,
            report.nodes_acked,
            report.nodes_taken,
            report.acked_nodes_lost,
            report.nodes_duplicated,
            p.p50_ms,
            p.p99_ms,
            q.p50_ms,
            q.p99_ms,
            report.pose_queries_unavailable,
            report.pose_query_errors
        );
        if let Some(kill) = &report.kill {
            for s in &kill.sites {
                println!(
                    "{} moved off {}: first ack after {:?} ms, first HTTP 200 after {:?} ms",
                    s.site, kill.host, s.first_ack_ms, s.first_http_200_ms
                );
            }
        }
    }
    drop(deployment);
    Ok(())
}

/// Polls each of `sites`' summary through `http` from `since` until it answers 200 (at
/// most 120 s); when each first did.
fn watch_served(
    http: &str,
    sites: &[String],
    since: Instant,
) -> std::thread::JoinHandle<HashMap<String, Instant>> {
    let (http, sites) = (http.to_owned(), sites.to_vec());
    std::thread::spawn(move || {
        let mut served = HashMap::new();
        while served.len() < sites.len() && since.elapsed() < Duration::from_secs(120) {
            for site in &sites {
                if !served.contains_key(site)
                    && status(&http, &format!("/api/v1/fleets/{site}/summary")) == 200
                {
                    served.insert(site.clone(), Instant::now());
                }
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        served
    })
}
