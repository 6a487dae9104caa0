//! `levelmap optimize`: optimize a 2D pose graph file (g2o or TORO) and report χ² in g2o's
//! EdgeSE2 convention.

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use graphio::posegraph;
use serde::Serialize;
use slam::{GraphError, Init, InitError, Method, OptimizeParams, OptimizeReport, Optimizer};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Clone, Copy, Debug, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum InitArg {
    /// The file's vertices (VERTEX_SE2 / VERTEX2).
    File,
    /// Chain the edges i → i+1.
    Odometry,
    /// Compose measurements along a breadth-first spanning tree from the first node.
    Spanning,
    /// Linear rotation estimate over all edges, then linear translations (the default).
    Chordal,
}

#[derive(Clone, Copy, Debug, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum MethodArg {
    /// Levenberg-Marquardt.
    Lm,
    /// Gauss-Newton.
    Gn,
}

/// Optimize a 2D pose graph (g2o EDGE_SE2/VERTEX_SE2 or TORO EDGE2/VERTEX2).
#[derive(Args, Debug)]
pub struct OptimizeArgs {
    /// The pose-graph file.
    pub file: PathBuf,
    /// File format; guessed from the extension (.g2o, .graph) when omitted.
    #[arg(long, value_name = "g2o|toro")]
    pub format: Option<String>,
    /// Initial poses.
    #[arg(long, value_enum, default_value_t = InitArg::Chordal)]
    pub init: InitArg,
    #[arg(long, value_enum, default_value_t = MethodArg::Lm)]
    pub method: MethodArg,
    /// Most iterations.
    #[arg(long, default_value_t = 100)]
    pub max_iterations: u32,
    /// Write the optimized graph as g2o.
    #[arg(long, value_name = "OUT.g2o")]
    pub out: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Initialize and optimize this many times, each from the file with a new optimizer, and
    /// report the median times (the first run of a process pays for its fresh memory).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub repeat: u32,
}

#[derive(Serialize)]
struct Report {
    file: String,
    nodes: usize,
    edges: usize,
    init: InitArg,
    method: MethodArg,
    /// χ² (g2o's EdgeSE2 convention) at the initial poses and at the end.
    initial_chi2: f64,
    final_chi2: f64,
    iterations: u32,
    stop: slam::StopReason,
    /// Initialization, optimization, and both (ms), medians over `repeat` runs; parsing
    /// excluded. The initialization's fill-reducing order is computed once per run and serves
    /// the optimization too.
    init_ms: f64,
    solve_ms: f64,
    total_ms: f64,
    repeat: u32,
}

pub fn run(args: &OptimizeArgs) -> Result<()> {
    let mut file = posegraph::read_named(&args.file, args.format.as_deref())?;
    let init = match args.init {
        InitArg::File if !file.has_vertices => {
            bail!(
                "{}: --init file needs a vertex line for every node; this file has none",
                args.file.display()
            )
        }
        InitArg::File => Init::Given,
        InitArg::Odometry => Init::Odometry,
        InitArg::Spanning => Init::Spanning,
        InitArg::Chordal => Init::Chordal,
    };
    let params = OptimizeParams {
        method: match args.method {
            MethodArg::Lm => Method::LevenbergMarquardt,
            MethodArg::Gn => Method::GaussNewton,
        },
        max_iterations: args.max_iterations,
        ..Default::default()
    };
    let name = args.file.display().to_string();
    let mut times = Vec::with_capacity(args.repeat as usize);
    let mut solved = None;
    for _ in 0..args.repeat {
        let mut graph = file.graph.clone();
        let mut optimizer = Optimizer::new();
        let t0 = Instant::now();
        optimizer
            .initialize(&mut graph, init)
            .map_err(|e| match e {
                InitError::Graph(e) => graph_error(&file, &name, &e),
                other => anyhow::anyhow!("{name}: {other}"),
            })?;
        let init_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let report: OptimizeReport = optimizer
            .optimize(&mut graph, &params)
            .map_err(|e| graph_error(&file, &name, &e))?;
        let solve_ms = t1.elapsed().as_secs_f64() * 1e3;
        times.push((init_ms, solve_ms, init_ms + solve_ms));
        solved = Some((graph, report));
    }
    let (graph, report) = solved.expect("--repeat is at least 1");
    file.graph = graph;
    let median = |pick: fn(&(f64, f64, f64)) -> f64| {
        let mut v: Vec<f64> = times.iter().map(pick).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };

    if let Some(out) = &args.out {
        std::fs::write(out, posegraph::to_g2o(&file.graph, &file.ids))
            .with_context(|| format!("{}: cannot write", out.display()))?;
    }
    let r = Report {
        file: name,
        nodes: file.graph.poses.len(),
        edges: file.graph.edges.len(),
        init: args.init,
        method: args.method,
        initial_chi2: report.initial_chi2,
        final_chi2: report.final_chi2,
        iterations: report.iterations,
        stop: report.stop,
        init_ms: median(|t| t.0),
        solve_ms: median(|t| t.1),
        total_ms: median(|t| t.2),
        repeat: args.repeat,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!("{}: {} nodes, {} edges", r.file, r.nodes, r.edges);
        println!(
            "  chi2 {:.6} → {:.6} in {} iterations ({:?})",
            r.initial_chi2, r.final_chi2, r.iterations, r.stop
        );
        println!(
            "  {:.1} ms init ({:?}) + {:.1} ms solve ({:?})",
            r.init_ms, r.init, r.solve_ms, r.method
        );
    }
    Ok(())
}

/// A graph error in the file's terms: the line of the edge it names, the vertex ids.
fn graph_error(file: &posegraph::GraphFile, name: &str, error: &GraphError) -> anyhow::Error {
    let id = |node: usize| file.ids.get(node).copied().unwrap_or(node as i64);
    match *error {
        GraphError::MissingNode { edge, .. }
        | GraphError::NotFinite { edge }
        | GraphError::NotPositiveDefinite { edge }
        | GraphError::SelfLoop { edge } => match file.edge_lines.get(edge) {
            Some(line) => anyhow::anyhow!("{name}:{line}: {error}"),
            None => anyhow::anyhow!("{name}: {error}"),
        },
        GraphError::Disconnected {
            unreachable,
            example,
        } => anyhow::anyhow!(
            "{name}: graph is disconnected: {unreachable} vertices (e.g. vertex {}) have no path of edges to vertex {}",
            id(example),
            id(0)
        ),
        GraphError::BadPose { node } => {
            anyhow::anyhow!("{name}: vertex {} has a pose that is not finite", id(node))
        }
        GraphError::Singular => anyhow::anyhow!("{name}: {error}"),
    }
}
