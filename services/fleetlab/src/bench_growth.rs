//! `levelmap bench-growth`: one site grown to many nodes in compressed time, through the
//! mapper's own write path (nodes handed to its worker as the bus hands them, as fast as it
//! takes them; matching, the store's commits, the background solves as in service), and
//! measured at each size: the store's size and its restore time, the process's resident
//! memory per node, a whole-network solve, a node's time to be mapped, a map request.
//!
//! The robots drive laps of the park's three loops, each lap on new ground: a copy of the
//! park on a lattice 500 m apart (east, then north), as a new chain of the robot (an outbox
//! started again, placed by its GPS fixes). On the same paths again the mapper would pass
//! over its nodes and not add any (docs/services.md, "Bounded growth"): the nodes of a site
//! grow with the ground covered, and this bench covers new ground to grow them.
//!
//! With `--same-ground` every lap is on the park itself, each robot's one chain going on from
//! lap to lap, as a fleet that works in one place for a month: after the first laps the
//! nodes pass over covered ground, and what the site keeps of them (span rows, GPS edges up
//! to their bound, solve points) is what grows. A lap's scans are the same from lap to lap,
//! and so is its dead reckoning but for one step: from a lap's last node on to the next lap's
//! first, odometry moves by the true motion (the simulator's), and each lap's odometry frame
//! is the previous one's carried on by that step ([`Seam`]). Without it, odometry would jump
//! by the lap's drift there (1.1 m on the park's second loop), more than a pass is located
//! within.

use crate::FLEET;
use crate::bench_fleet::{Percentiles, agent, loop_source, node_pool, robot_node};
use anyhow::{Context, Result, bail};
use clap::Args;
use leveling::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use slam::Pose2;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use wire::Node;

/// Grow one site to each of `--sizes` nodes and measure the mapper there.
#[derive(Args, Debug)]
pub struct BenchGrowthArgs {
    /// Site sizes (nodes) at which it measures, ascending.
    #[arg(long, value_delimiter = ',', default_value = "10000,100000,1000000")]
    pub sizes: Vec<usize>,
    /// Robots driving, their nodes dealt in turn. On new ground each lap is a new chain of
    /// its robot, and a robot may start at most `fleetmap::MAX_CHAINS_PER_ROBOT` (256): the
    /// largest size needs enough robots that none laps more often (checked before the run).
    #[arg(long, default_value_t = 200)]
    pub robots: usize,
    /// Nodes at each size handed over one at a time and waited for (the time to be mapped,
    /// with no queue before it).
    #[arg(long, default_value_t = 200)]
    pub sample: usize,
    /// Folder for the mapper's store (new, empty or an earlier run's, emptied at start; any
    /// other is refused).
    #[arg(long, default_value = "levelmap-bench-growth")]
    pub dir: PathBuf,
    /// Every lap on the same ground (the park itself) instead of new ground.
    #[arg(long)]
    pub same_ground: bool,
    /// The mapper's Zenoh endpoint.
    #[arg(long, default_value = "tcp/127.0.0.1:7449")]
    pub zenoh: String,
    /// Print one JSON object of figures.
    #[arg(long)]
    pub json: bool,
}

/// The figures at one size.
#[derive(Serialize)]
struct AtSize {
    /// Nodes handed to the mapper so far.
    fed: usize,
    /// Of them, in the map (the rest passed over covered ground: not kept).
    nodes: usize,
    /// Of them, passed over covered ground (over every start of the mapper).
    passed: u64,
    /// Of them, refused (out of order, a quarantined fleet, …: none expected).
    rejected: u64,
    /// Nodes handed over and handled per second of the run up to here (compressed time).
    fed_per_s: f64,
    store_bytes: u64,
    store_bytes_per_node: f64,
    /// From a new mapper's start on the store to its serving the map.
    restore_ms: f64,
    /// The process's resident memory after the restore (Linux `VmRSS`).
    resident_bytes: u64,
    resident_bytes_per_node: f64,
    /// The most the process has held resident so far (Linux `VmHWM`): feeding, the solve,
    /// the map, the restore, and the mapper stopped before it, at once.
    peak_resident_bytes: u64,
    /// A whole-network solve asked for now (`POST …/optimize`'s work).
    solve_ms: f64,
    /// Each sampled node, handed over with no queue before it, until the worker is done
    /// with it (in the store and the view, and acked; or passed).
    node_to_view: Percentiles,
    /// `GET …/map.png?max_cells=2^22`: the whole site, its cells coarsened to fit.
    map_png_ms: f64,
    map_png_status: u16,
    map_png_bytes: usize,
}

#[derive(Serialize)]
struct Report {
    robots: usize,
    same_ground: bool,
    pool_nodes_per_loop: Vec<usize>,
    sizes: Vec<AtSize>,
}

/// Copies of the park along a lattice row before the next row starts.
const LATTICE_COLUMNS: u64 = 200;
/// The lattice's spacing (m): the park's loops fit in 500 m.
const LATTICE_M: f64 = 500.0;

/// A robot: its name, where along its loop's pool it starts, its lap and its node in it.
struct Robot {
    name: String,
    offset: usize,
    lap: u64,
    k: u64,
    sent: u64,
    /// On the same ground: its odometry frame in its first lap's (the seams it crossed).
    odometry_base: Pose2,
}

/// Where a loop's lap ends and the next begins, on the same ground.
#[derive(Clone, Copy, Debug)]
struct Seam {
    /// The robot's true planar motion from the lap's last node to its first.
    step: Pose2,
    /// The next lap's odometry frame in this lap's: the lap's last node's odometry, carried
    /// on by `step`, is where the first node's odometry puts it.
    next_frame: Pose2,
}

/// The robots, their nodes dealt in turn.
struct Fleet {
    pool: Vec<Vec<Node>>,
    seams: Vec<Seam>,
    robots: Vec<Robot>,
    next: usize,
    started_ns: u64,
    same_ground: bool,
}

impl Fleet {
    fn new(pool: Vec<Vec<Node>>, seams: Vec<Seam>, robots: usize, same_ground: bool) -> Fleet {
        let robots = (0..robots)
            .map(|r| Robot {
                name: format!("r{r}"),
                // Spread along the loop: robot r starts at the r-th share of its pool.
                offset: r * pool[r % pool.len()].len() / robots,
                lap: 0,
                k: 0,
                sent: 0,
                odometry_base: Pose2::default(),
            })
            .collect();
        Fleet {
            pool,
            seams,
            robots,
            next: 0,
            started_ns: runtime::session::now_ns(),
            same_ground,
        }
    }

    /// The next node of the next robot: its key and bytes as sent.
    fn next_node(&mut self) -> Result<(String, Vec<u8>)> {
        let r = self.next;
        let count = self.robots.len();
        self.next = (r + 1) % count;
        let loop_nodes = &self.pool[r % self.pool.len()];
        let robot = &mut self.robots[r];
        if robot.k as usize == loop_nodes.len() {
            (robot.lap, robot.k) = (robot.lap + 1, 0);
        }
        let index = (robot.offset + robot.k as usize) % loop_nodes.len();
        let mut template = loop_nodes[index].clone();
        // New ground: each lap a copy of the park of its own, driven as a new chain. The
        // same ground: the park itself, one chain lap after lap, its odometry carried across
        // each seam by the true step.
        let (copy, chain) = if self.same_ground {
            let seam = self.seams[r % self.seams.len()];
            let crossed = (index == 0 && robot.sent > 0).then_some(seam.step);
            if crossed.is_some() {
                robot.odometry_base = robot.odometry_base.compose(&seam.next_frame);
            }
            template = rebased(template, &robot.odometry_base, crossed)?;
            (0, (1, robot.sent))
        } else {
            (
                robot.lap * count as u64 + r as u64,
                (robot.lap + 1, robot.k),
            )
        };
        let offset_m = [
            (copy % LATTICE_COLUMNS) as f64 * LATTICE_M,
            (copy / LATTICE_COLUMNS) as f64 * LATTICE_M,
        ];
        // A node a second per robot, in compressed time.
        let stamp_ns = self.started_ns + robot.sent * 1_000_000_000;
        let payload = robot_node(&template, (FLEET, &robot.name), chain, offset_m, stamp_ns);
        robot.k += 1;
        robot.sent += 1;
        Ok((wire::node_key(FLEET, &robot.name)?, payload))
    }
}

/// `node` with its dead reckoning in the odometry frame `base` (planar), and `step` as its
/// motion since the node before when it follows a seam.
fn rebased(node: Node, base: &Pose2, step: Option<Pose2>) -> Result<Node> {
    let mut parts = node.into_parts();
    let frame = Isometry3::from_parts(
        Translation3::new(base.x, base.y, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), base.theta),
    );
    parts.odometry.pose = frame * parts.odometry.pose;
    if step.is_some() {
        parts.odometry_delta = step;
    }
    Ok(Node::new(parts)?)
}

/// The seam of each loop's lap ([`Seam`]), from the simulator's true poses at the lap's first
/// and last nodes.
fn seams(pool: &[Vec<Node>]) -> Vec<Seam> {
    pool.iter()
        .enumerate()
        .map(|(loop_index, lap)| {
            let (first, last) = (&lap[0], &lap[lap.len() - 1]);
            let source = loop_source(loop_index, LAP_NODES_MAX);
            let truth = |n: &Node| Pose2::from_isometry3(&source.truth_at(n.odometry.stamp_ns));
            let odometry = |n: &Node| Pose2::from_isometry3(&n.odometry.pose);
            let step = truth(last).between(&truth(first));
            let next_frame = odometry(last)
                .compose(&step)
                .compose(&odometry(first).inverse());
            Seam { step, next_frame }
        })
        .collect()
}

/// The nodes of each loop for one lap: from the start until the robot is back within 1 m of
/// it, heading the same way within 30°, having driven 100 m (a loop may cross itself), so
/// that a pool's end meets its start.
fn lap_pool() -> Result<Vec<Vec<Node>>> {
    node_pool(LAP_NODES_MAX, false)
        .into_iter()
        .enumerate()
        .map(|(loop_index, nodes)| {
            let start = nodes[0].odometry.pose;
            let mut driven = 0.0;
            for (i, pair) in nodes.windows(2).enumerate() {
                let (a, b) = (pair[0].odometry.pose, pair[1].odometry.pose);
                driven += (b.translation.vector - a.translation.vector).norm();
                let back = (b.translation.vector - start.translation.vector).norm() < 1.0
                    && b.rotation.angle_to(&start.rotation) < 30f64.to_radians();
                if driven > 100.0 && back {
                    if i + 1 < SHORTEST_LAP_NODES {
                        bail!("loop {loop_index}: a lap of {} nodes", i + 1);
                    }
                    return Ok(nodes[..=i].to_vec());
                }
            }
            bail!("loop {loop_index}: no lap within {LAP_NODES_MAX} nodes")
        })
        .collect()
}

/// A lap's nodes at most (the park's longest loop has fewer).
const LAP_NODES_MAX: usize = 1500;
/// A lap's nodes at least, for the check on chains per robot ([`lap_pool`] checks it).
const SHORTEST_LAP_NODES: usize = 25;

/// Runs the bench and prints its figures.
pub fn run(args: &BenchGrowthArgs) -> Result<()> {
    if args.sizes.is_empty() || args.sizes.windows(2).any(|w| w[0] >= w[1]) {
        bail!("--sizes must be ascending");
    }
    if args.robots == 0 {
        bail!("--robots must be at least 1");
    }
    let largest = args.sizes.last().copied().unwrap_or(0);
    // The shortest lap is the park's first loop's (29 nodes); a robot's laps, counted with it.
    let laps = largest.div_ceil(args.robots).div_ceil(SHORTEST_LAP_NODES) + 1;
    if !args.same_ground && laps > fleetmap::MAX_CHAINS_PER_ROBOT {
        bail!(
            "{largest} nodes over {} robots is up to {laps} laps (chains) per robot, more than \
             the {} the mapper takes: use more --robots",
            args.robots,
            fleetmap::MAX_CHAINS_PER_ROBOT
        );
    }
    crate::runtime()?.block_on(run_async(args))
}

async fn run_async(args: &BenchGrowthArgs) -> Result<()> {
    eprintln!("bench-growth: simulating a lap of each of the park's loops…");
    let same_ground = args.same_ground;
    let (pool, seams) = tokio::task::spawn_blocking(move || {
        let pool = lap_pool()?;
        let seams = if same_ground {
            seams(&pool)
        } else {
            Vec::new()
        };
        anyhow::Ok((pool, seams))
    })
    .await??;
    let pool_nodes_per_loop: Vec<usize> = pool.iter().map(Vec::len).collect();
    eprintln!("bench-growth: laps of {pool_nodes_per_loop:?} nodes");
    let config = crate::park_mapper_config(&args.dir, "127.0.0.1:0", &args.zenoh)?;
    let mut mapper = mapper::start(config.clone()).await?;
    let mut fleet = Fleet::new(pool, seams, args.robots, args.same_ground);
    let (mut fed, started) = (0usize, Instant::now());
    // Nodes fed, and passed, before this mapper started (its counters start at 0).
    let (mut fed_before_start, mut passed_before_start) = (0, 0);
    let mut sizes = Vec::new();
    for &size in &args.sizes {
        let bulk = size.saturating_sub(args.sample);
        while fed < bulk {
            let (key, payload) = fleet.next_node()?;
            tokio::task::block_in_place(|| mapper.feed_node(&key, payload))?;
            fed += 1;
            if fed % 10_000 == 0 {
                eprintln!(
                    "bench-growth: {fed} nodes fed, {} mapped, {:.0} s, {} MB resident",
                    mapped_nodes(&mapper),
                    started.elapsed().as_secs_f64(),
                    proc_status_kb("VmRSS:")? / 1024
                );
            }
        }
        drain(&mapper, (fed - fed_before_start) as u64).await?;
        let fed_per_s = fed as f64 / started.elapsed().as_secs_f64();
        let node_to_view =
            tokio::task::block_in_place(|| sample_nodes(&mapper, &mut fleet, size - fed))?;
        fed = size;
        let nodes = mapped_nodes(&mapper);
        let passed = passed_before_start + passed_nodes(&mapper);
        let rejected = rejected_nodes(&mapper);
        if rejected > 0 {
            // Every node is new or passes: a refusal means the bench is not growing a site.
            bail!("the mapper refused {rejected} nodes by {size} (its /metrics say why)");
        }
        let solve_started = Instant::now();
        mapper.optimize(FLEET).await?;
        let solve_ms = ms(solve_started);
        let (map_png_ms, map_png_status, map_png_bytes) = map_png(&mapper.http_addr).await?;
        let store_bytes = std::fs::metadata(&config.store_path)
            .with_context(|| format!("{}", config.store_path.display()))?
            .len();
        mapper.stop().await?;
        let restore_started = Instant::now();
        mapper = mapper::start(config.clone()).await?;
        let restore_ms = ms(restore_started);
        (fed_before_start, passed_before_start) = (fed, passed);
        let resident_bytes = proc_status_kb("VmRSS:")? * 1024;
        let at = AtSize {
            fed,
            nodes,
            passed,
            rejected,
            fed_per_s,
            store_bytes,
            store_bytes_per_node: store_bytes as f64 / nodes.max(1) as f64,
            restore_ms,
            resident_bytes,
            resident_bytes_per_node: resident_bytes as f64 / nodes.max(1) as f64,
            peak_resident_bytes: proc_status_kb("VmHWM:")? * 1024,
            solve_ms,
            node_to_view,
            map_png_ms,
            map_png_status,
            map_png_bytes,
        };
        eprintln!(
            "bench-growth: {fed} fed, {nodes} nodes, {passed} passed: store {} MB ({:.0} B/node), \
             restore {restore_ms:.0} ms, {:.0} B resident/node (peak {} MB), solve {solve_ms:.0} ms, \
             node p99 {:.1} ms, map.png {map_png_ms:.0} ms",
            at.store_bytes >> 20,
            at.store_bytes_per_node,
            at.resident_bytes_per_node,
            at.peak_resident_bytes >> 20,
            at.node_to_view.p99_ms
        );
        sizes.push(at);
    }
    mapper.stop().await?;
    let report = Report {
        robots: args.robots,
        same_ground: args.same_ground,
        pool_nodes_per_loop,
        sizes,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        for s in &report.sizes {
            println!(
                "{:>9} nodes  store {:>7.0} B/node  restore {:>8.0} ms  resident {:>6.0} B/node  \
                 solve {:>8.0} ms  node p50/p99 {:.1}/{:.1} ms  map.png {:.0} ms ({})",
                s.nodes,
                s.store_bytes_per_node,
                s.restore_ms,
                s.resident_bytes_per_node,
                s.solve_ms,
                s.node_to_view.p50_ms,
                s.node_to_view.p99_ms,
                s.map_png_ms,
                s.map_png_status
            );
        }
    }
    Ok(())
}

/// The fleet's nodes in the mapper's view.
fn mapped_nodes(mapper: &mapper::Running) -> usize {
    mapper.shared.fleet(FLEET).map_or(0, |v| v.nodes.len())
}

/// The nodes the mapper passed over covered ground (taken, not kept).
fn passed_nodes(mapper: &mapper::Running) -> u64 {
    let passed = &mapper.shared.metrics.nodes_passed;
    passed.load(std::sync::atomic::Ordering::Relaxed)
}

/// The nodes of mapping robots refused.
fn rejected_nodes(mapper: &mapper::Running) -> u64 {
    let rejected = mapper.shared.metrics.rejected.lock();
    let rejected = rejected.unwrap_or_else(std::sync::PoisonError::into_inner);
    (rejected.iter())
        .filter(|((topic, _), _)| *topic == "node")
        .map(|(_, count)| count)
        .sum()
}

/// The nodes the worker is done with: mapped and acked, passed, or refused.
fn handled_nodes(mapper: &mapper::Running) -> u64 {
    let accepted = &mapper.shared.metrics.nodes_accepted;
    accepted.load(std::sync::atomic::Ordering::Relaxed)
        + passed_nodes(mapper)
        + rejected_nodes(mapper)
}

/// Waits until the worker has handled `fed` nodes (those handed over wait in its queue):
/// a sampled node then has none before it.
async fn drain(mapper: &mapper::Running, fed: u64) -> Result<()> {
    let (mut last, mut changed) = (handled_nodes(mapper), Instant::now());
    while last < fed {
        tokio::time::sleep(Duration::from_millis(10)).await;
        let handled = handled_nodes(mapper);
        if handled != last {
            (last, changed) = (handled, Instant::now());
        } else if changed.elapsed() > Duration::from_secs(60) {
            bail!("the mapper handled {last} of {fed} nodes and none in 60 s");
        }
    }
    Ok(())
}

/// Hands over `count` nodes one at a time, each waited for until the worker is done with it
/// (acked once in the store and the view, or passed over covered ground).
fn sample_nodes(mapper: &mapper::Running, fleet: &mut Fleet, count: usize) -> Result<Percentiles> {
    let mut times = Vec::with_capacity(count);
    for _ in 0..count {
        // Read before the node is handed over: the worker may take it at once.
        let before = handled_nodes(mapper);
        let (key, payload) = fleet.next_node()?;
        let t0 = Instant::now();
        mapper.feed_node(&key, payload)?;
        while handled_nodes(mapper) == before {
            if t0.elapsed() > Duration::from_secs(60) {
                bail!("a node was not mapped within 60 s");
            }
            // A thread's sleep, not Tokio's: Tokio's timer counts whole milliseconds, which
            // would round every node's time up to one.
            std::thread::sleep(SAMPLE_POLL);
        }
        times.push(ms(t0));
    }
    Ok(Percentiles::of(times))
}

/// How often a sampled node's end is looked for: well under its time, and no busy core.
const SAMPLE_POLL: Duration = Duration::from_micros(20);

/// Cells of the map asked for: as the Foxglove feed's grid.
const MAP_CELLS: usize = 1 << 22;

/// `GET …/map.png` of the whole site in [`MAP_CELLS`] cells: time, status, bytes.
async fn map_png(http: &std::net::SocketAddr) -> Result<(f64, u16, usize)> {
    let url = format!("http://{http}/api/v1/fleets/{FLEET}/map.png?max_cells={MAP_CELLS}");
    tokio::task::spawn_blocking(move || {
        let t0 = Instant::now();
        let response = agent().get(&url).call()?;
        let status = response.status().as_u16();
        let bytes = response.into_body().read_to_vec()?.len();
        Ok((ms(t0), status, bytes))
    })
    .await?
}

/// One of the process's memory figures (kB) in Linux `/proc/self/status`: `VmRSS:` (resident
/// now), `VmHWM:` (the most resident so far).
fn proc_status_kb(field: &str) -> Result<u64> {
    let status = std::fs::read_to_string("/proc/self/status").context("/proc/self/status")?;
    status
        .lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .with_context(|| format!("no {field} in /proc/self/status"))
}

fn ms(t0: Instant) -> f64 {
    t0.elapsed().as_secs_f64() * 1e3
}
