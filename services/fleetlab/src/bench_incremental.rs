//! `levelmap bench-incremental`: a pose-graph file replayed node by node, as a robot would
//! add it, through one of two ways of solving a growing network:
//!
//! - `window` (the mapper's, `slam::incremental`): each node is placed by its odometry edge,
//!   a node that brings a closure re-solves the window of the newest nodes at once, and the
//!   whole graph is solved on a second thread and applied as a correction;
//! - `bayes-tree` (`slam::smoother`): iSAM2's incremental smoothing, every node an update of
//!   the tree, nothing in the background.
//!
//! Measured: the foreground time per added node, by graph size; how far the newest node's
//! estimate (what a robot gets back) lies from a batch solve of the graph so far; the final
//! χ² against the batch optimum.

use crate::bench_fleet::Percentiles;
use anyhow::{Context, Result, bail};
use clap::Args;
use graphio::posegraph;
use serde::Serialize;
use slam::incremental::{
    Adjacency, GlobalSolver, JobSource, SolveResult, apply_solve, solve_window,
};
use slam::{
    IncrementalSmoother, Init, OptimizeParams, Optimizer, Pose2, PoseGraph, SmootherParams,
    initialize,
};
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Replay a 2D pose graph node by node through the incremental solver (window now, the
/// whole graph in the background) and measure it against batch solves.
#[derive(Args, Debug)]
pub struct BenchIncrementalArgs {
    /// The pose-graph file.
    pub file: PathBuf,
    /// File format; guessed from the extension (.g2o, .graph) when omitted.
    #[arg(long, value_name = "g2o|toro")]
    pub format: Option<String>,
    /// How the growing network is solved.
    #[arg(long, value_enum, default_value_t = Solver::Window)]
    pub solver: Solver,
    /// A pose whose step in x or y exceeds this (m) is relinearized (`bayes-tree`).
    #[arg(long, default_value_t = SmootherParams::default().relinearize_translation)]
    pub relinearize_translation: f64,
    /// A pose whose step in θ exceeds this (rad) is relinearized (`bayes-tree`).
    #[arg(long, default_value_t = SmootherParams::default().relinearize_rotation)]
    pub relinearize_rotation: f64,
    /// Rounds of relinearization within one update (`bayes-tree`).
    #[arg(long, default_value_t = SmootherParams::default().max_relinearizations)]
    pub max_relinearizations: u32,
    /// A subtree's steps are recomputed when its separator moved by more than this
    /// (`bayes-tree`).
    #[arg(long, default_value_t = SmootherParams::default().wildfire)]
    pub wildfire: f64,
    /// Nodes re-solved at a node that brings a closure (`window`).
    #[arg(long, default_value_t = 30)]
    pub window: usize,
    /// Nodes added per second (0: as fast as the foreground goes, the hardest case for
    /// the background solves).
    #[arg(long, default_value_t = 0.0)]
    pub rate: f64,
    /// Graph sizes at which the newest node is compared with a batch solve of the graph so
    /// far (besides every `--check-every` nodes).
    #[arg(long, value_delimiter = ',', default_value = "1000,5000,10000")]
    pub sizes: Vec<usize>,
    /// Also compare every this many nodes.
    #[arg(long, default_value_t = 500)]
    pub check_every: usize,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// How the replay solves the growing network.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    /// A window of the newest nodes now, the whole network in the background (the mapper's).
    Window,
    /// Incremental smoothing on a Bayes tree (iSAM2's method), in the foreground.
    BayesTree,
}

/// Foreground time per added node over the 500 nodes up to a size.
#[derive(Serialize)]
struct AtSize {
    nodes: usize,
    per_node: Percentiles,
}

#[derive(Serialize)]
struct Report {
    file: String,
    nodes: usize,
    edges: usize,
    solver: Solver,
    window: usize,
    rate: f64,
    /// Every added node (ms): placing it, its edges, its window, and taking or applying a
    /// background solve when one was due.
    per_node: Percentiles,
    per_node_mean_ms: f64,
    at_sizes: Vec<AtSize>,
    /// Background solves applied (`window`).
    background_solves: usize,
    /// Per update, the mean of poses eliminated again, and of rounds (`bayes-tree`).
    eliminated_per_update: f64,
    rounds_per_update: f64,
    /// The tree at the end (`bayes-tree`).
    tree: Option<slam::TreeShape>,
    /// The newest node's estimate when it was added against a batch solve of the graph up to
    /// it (m): over the checks, the median and the largest; and the largest difference of any
    /// node of the graph then.
    newest_vs_batch_p50_m: f64,
    newest_vs_batch_max_m: f64,
    /// Share of the checks where the newest node was within 1 cm of the batch solve.
    newest_within_1cm: f64,
    any_node_vs_batch_max_m: f64,
    checks: usize,
    /// After the last node and the background's last solve.
    final_chi2: f64,
    batch_chi2: f64,
    relative_chi2: f64,
}

/// Runs the replay and prints the report.
pub fn run(args: &BenchIncrementalArgs) -> Result<()> {
    let file = posegraph::read_named(&args.file, args.format.as_deref())?;
    let full = file.graph;
    let n = full.poses.len();
    if n < 2 {
        bail!("{}: fewer than two nodes", args.file.display());
    }
    // Edges by the newer of their ends: what each node brings.
    let mut brought: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (k, e) in full.edges.iter().enumerate() {
        brought[e.from.max(e.to)].push(k);
    }
    let replay = match args.solver {
        Solver::Window => replay_window(args, &full, &brought)?,
        Solver::BayesTree => replay_bayes_tree(args, &full, &brought)?,
    };
    let report = report(args, &full, &replay)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_text(&report);
    }
    Ok(())
}

/// What a replay leaves: the final network, the time of each node, the checks.
struct Replay {
    graph: PoseGraph,
    times_ms: Vec<f64>,
    /// Graph size, every node's estimate then.
    checks: Vec<(usize, Vec<Pose2>)>,
    background_solves: usize,
    /// Poses eliminated again and rounds, over all updates.
    eliminated: usize,
    rounds: usize,
    tree: Option<slam::TreeShape>,
}

fn is_check(args: &BenchIncrementalArgs, size: usize, n: usize) -> bool {
    size.is_multiple_of(args.check_every) || args.sizes.contains(&size) || size == n
}

fn wait_for_node(args: &BenchIncrementalArgs, started: Instant, i: usize) {
    if args.rate > 0.0 {
        let due = started + Duration::from_secs_f64(i as f64 / args.rate);
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
    }
}

/// Every node an update of the smoother, placed from the estimate of its predecessor.
fn replay_bayes_tree(
    args: &BenchIncrementalArgs,
    full: &PoseGraph,
    brought: &[Vec<usize>],
) -> Result<Replay> {
    let n = full.poses.len();
    let mut smoother = IncrementalSmoother::new(SmootherParams {
        relinearize_translation: args.relinearize_translation,
        relinearize_rotation: args.relinearize_rotation,
        max_relinearizations: args.max_relinearizations,
        wildfire: args.wildfire,
    });
    let (mut eliminated, mut rounds) = (0, 0);
    smoother.update(&[full.poses[0]], &[]).context("node 0")?;
    let (mut times_ms, mut checks) = (vec![0.0; n], Vec::new());
    let mut edges = Vec::new();
    let started = Instant::now();
    for i in 1..n {
        wait_for_node(args, started, i);
        let t = Instant::now();
        let guess = place(|k| smoother.estimate(k), full, &brought[i], i);
        edges.clear();
        edges.extend(brought[i].iter().map(|&k| full.edges[k].clone()));
        let stats = smoother
            .update(&[guess], &edges)
            .with_context(|| format!("node {i}"))?;
        (eliminated, rounds) = (
            eliminated + stats.eliminated,
            rounds + stats.rounds as usize,
        );
        times_ms[i] = t.elapsed().as_secs_f64() * 1e3;
        if is_check(args, i + 1, n) {
            checks.push((i + 1, smoother.estimates()));
        }
    }
    // Every step exact (untimed): the wildfire leaves far steps slightly stale.
    smoother.solve_all();
    let graph = PoseGraph {
        poses: smoother.estimates(),
        edges: smoother.edges().to_vec(),
        gps: Vec::new(),
    };
    Ok(Replay {
        graph,
        times_ms,
        checks,
        background_solves: 0,
        eliminated,
        rounds,
        tree: Some(smoother.shape()),
    })
}

/// Odometry placing, windows at closures, and the whole network on a second thread.
fn replay_window(
    args: &BenchIncrementalArgs,
    full: &PoseGraph,
    brought: &[Vec<usize>],
) -> Result<Replay> {
    let n = full.poses.len();
    let params = OptimizeParams::default();
    let (jobs, job_rx) = mpsc::channel();
    let (results, result_rx) = mpsc::channel::<SolveResult>();
    let solver = std::thread::spawn(move || {
        let mut solver = GlobalSolver::default();
        for job in job_rx {
            if results.send(solver.solve(job)).is_err() {
                break;
            }
        }
    });
    let mut graph = PoseGraph {
        poses: vec![full.poses[0]],
        ..PoseGraph::default()
    };
    let (mut source, mut adjacency) = (JobSource::default(), Adjacency::default());
    let (mut out, mut pending, mut applied) = (false, false, 0usize);
    let mut times_ms = vec![0.0; n];
    let mut checks = Vec::new();
    let started = Instant::now();
    for i in 1..n {
        wait_for_node(args, started, i);
        let t = Instant::now();
        if let Ok(result) = result_rx.try_recv() {
            apply_solve(&mut graph, &result, |_| 0).context("background solve")?;
            (out, applied) = (false, applied + 1);
        }
        graph
            .poses
            .push(place(|k| graph.poses[k], full, &brought[i], i));
        graph
            .edges
            .extend(brought[i].iter().map(|&k| full.edges[k].clone()));
        let closes = brought[i]
            .iter()
            .any(|&k| full.edges[k].from.abs_diff(full.edges[k].to) > 1);
        if closes {
            adjacency.sync(&graph);
            let window: Vec<usize> = (i.saturating_sub(args.window - 1).max(1)..=i).collect();
            solve_window(&mut graph, &adjacency, &window, &params).context("window")?;
            pending = true;
        }
        if pending && !out {
            jobs.send(source.job(&graph, &params))?;
            (out, pending) = (true, false);
        }
        times_ms[i] = t.elapsed().as_secs_f64() * 1e3;
        if is_check(args, i + 1, n) {
            checks.push((i + 1, graph.poses.clone()));
        }
    }
    // The background's last solve, of the whole graph from where the replay left it.
    if out {
        let result = result_rx.recv()?;
        apply_solve(&mut graph, &result, |_| 0).context("background solve")?;
        applied += 1;
    }
    jobs.send(source.job(&graph, &params))?;
    let result = result_rx.recv()?;
    apply_solve(&mut graph, &result, |_| 0).context("the last background solve")?;
    applied += 1;
    drop(jobs);
    solver.join().expect("the solver thread");
    Ok(Replay {
        graph,
        times_ms,
        checks,
        background_solves: applied,
        eliminated: 0,
        rounds: 0,
        tree: None,
    })
}

/// Where node `i` starts: its predecessor (`pose_of` an earlier node) moved by the odometry
/// edge it brings (else by the first edge it brings from an earlier node).
fn place(pose_of: impl Fn(usize) -> Pose2, full: &PoseGraph, brought: &[usize], i: usize) -> Pose2 {
    let edges = || brought.iter().map(|&k| &full.edges[k]);
    let chain = edges().find(|e| e.from + 1 == i && e.to == i);
    match chain.or_else(|| edges().find(|e| e.to == i && e.from < i)) {
        Some(e) => pose_of(e.from).compose(&e.measurement),
        None => edges().find(|e| e.from == i).map_or(pose_of(i - 1), |e| {
            pose_of(e.to).compose(&e.measurement.inverse())
        }),
    }
}

/// The graph's first `size` nodes solved in one batch (chordal start), each node's pose in
/// node 0's frame.
fn batch(full: &PoseGraph, size: usize) -> Result<Vec<Pose2>> {
    let mut prefix = PoseGraph {
        poses: full.poses[..size].to_vec(),
        edges: full
            .edges
            .iter()
            .filter(|e| e.from.max(e.to) < size)
            .cloned()
            .collect(),
        gps: Vec::new(),
    };
    initialize(&mut prefix, Init::Chordal)?;
    Optimizer::new().optimize(&mut prefix, &OptimizeParams::default())?;
    Ok(in_first_frame(&prefix.poses))
}

fn in_first_frame(poses: &[Pose2]) -> Vec<Pose2> {
    poses.iter().map(|p| poses[0].between(p)).collect()
}

fn distance(a: &Pose2, b: &Pose2) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

fn report(args: &BenchIncrementalArgs, full: &PoseGraph, replay: &Replay) -> Result<Report> {
    let n = full.poses.len();
    let times_ms = &replay.times_ms;
    let at_sizes = args
        .sizes
        .iter()
        .filter(|&&size| size <= n)
        .map(|&size| AtSize {
            nodes: size,
            per_node: Percentiles::of(times_ms[size.saturating_sub(500).max(1)..size].to_vec()),
        })
        .collect();
    let (mut newest, mut any_node) = (Vec::new(), 0.0f64);
    for (size, poses) in &replay.checks {
        let reference = batch(full, *size)?;
        let ours = in_first_frame(poses);
        newest.push(distance(&ours[size - 1], &reference[size - 1]));
        let worst = ours.iter().zip(&reference).map(|(a, b)| distance(a, b));
        any_node = worst.fold(any_node, f64::max);
    }
    let within = newest.iter().filter(|&&d| d <= 0.01).count() as f64 / newest.len() as f64;
    let newest_p = Percentiles::of(newest);
    let mut optimum = full.clone();
    initialize(&mut optimum, Init::Chordal)?;
    let batch_chi2 = Optimizer::new()
        .optimize(&mut optimum, &OptimizeParams::default())?
        .final_chi2;
    let final_chi2 = replay.graph.chi2();
    Ok(Report {
        file: args.file.display().to_string(),
        nodes: n,
        edges: full.edges.len(),
        solver: args.solver,
        window: args.window,
        rate: args.rate,
        per_node: Percentiles::of(times_ms[1..].to_vec()),
        per_node_mean_ms: times_ms[1..].iter().sum::<f64>() / (n - 1) as f64,
        at_sizes,
        background_solves: replay.background_solves,
        eliminated_per_update: replay.eliminated as f64 / (n - 1) as f64,
        rounds_per_update: replay.rounds as f64 / (n - 1) as f64,
        tree: replay.tree,
        newest_vs_batch_p50_m: newest_p.p50_ms,
        newest_vs_batch_max_m: newest_p.max_ms,
        newest_within_1cm: within,
        any_node_vs_batch_max_m: any_node,
        checks: replay.checks.len(),
        final_chi2,
        batch_chi2,
        relative_chi2: (final_chi2 - batch_chi2) / batch_chi2,
    })
}

fn print_text(r: &Report) {
    println!(
        "{}: {} nodes, {} edges, window {}",
        r.file, r.nodes, r.edges, r.window
    );
    println!(
        "  per node ({:?}): mean {:.3} ms, p50 {:.3} ms, p99 {:.3} ms, max {:.1} ms",
        r.solver, r.per_node_mean_ms, r.per_node.p50_ms, r.per_node.p99_ms, r.per_node.max_ms
    );
    for s in &r.at_sizes {
        println!(
            "  at {} nodes: p50 {:.3} ms, p99 {:.3} ms",
            s.nodes, s.per_node.p50_ms, s.per_node.p99_ms
        );
    }
    println!(
        "  newest node vs batch: p50 {:.4} m, max {:.4} m, {:.0} % within 1 cm ({} checks); any node {:.4} m",
        r.newest_vs_batch_p50_m,
        r.newest_vs_batch_max_m,
        100.0 * r.newest_within_1cm,
        r.checks,
        r.any_node_vs_batch_max_m
    );
    println!(
        "  chi2 {:.6} vs batch {:.6} ({:+.2e}), {} background solves",
        r.final_chi2, r.batch_chi2, r.relative_chi2, r.background_solves
    );
    if r.solver == Solver::BayesTree {
        println!(
            "  per update: {:.1} poses eliminated again, {:.2} rounds",
            r.eliminated_per_update, r.rounds_per_update
        );
    }
    if let Some(t) = &r.tree {
        println!(
            "  tree: separators mean {:.1}, max {}; depth mean {:.0}, max {}",
            t.separator_mean, t.separator_max, t.depth_mean, t.depth_max
        );
    }
}
