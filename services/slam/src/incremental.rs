//! Solving a growing network without paying for the whole of it at every node: a local
//! window re-solved in the foreground, and the global solve in the background.
//!
//! - **Window** ([`solve_window`]): the newest nodes of a chain are the variables; every
//!   node an edge links them to is held where it is. Its cost depends on the window, not on
//!   the network, so the pose a robot gets back at once already feels a new closure or fix.
//! - **Background** ([`JobSource`], [`GlobalSolver`], [`apply_solve`]): a job carries what
//!   the global solver does not have yet (the current estimates, the edges and fixes added
//!   since its last job); the solver keeps the network between jobs and solves all of it,
//!   from the estimates, on whatever thread its owner runs it. Its result is applied as a
//!   correction: each node it solved moves by its own correction, and each node added since
//!   the job moves with the last solved node of its chain, so what changed meanwhile (new
//!   nodes, window solves) rides along instead of being overwritten.
//!
//! Pure: the caller decides the threads; a job applied at the same point gives the same
//! network, which is what lets the mapper's store replay it.

use crate::network::{GpsEdge, GraphError, PoseGraph, RelativeEdge};
use crate::optimize::{OptimizeParams, OptimizeReport, Optimizer};
use crate::se2::Pose2;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The edges and fixes of each node, kept as the network grows (appended only).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Adjacency {
    edges: Vec<Vec<u32>>,
    fixes: Vec<Vec<u32>>,
    edges_seen: usize,
    fixes_seen: usize,
}

impl Adjacency {
    /// Takes in what was appended to `graph` since the last call.
    pub fn sync(&mut self, graph: &PoseGraph) {
        self.edges.resize(graph.poses.len(), Vec::new());
        self.fixes.resize(graph.poses.len(), Vec::new());
        for (k, e) in graph.edges.iter().enumerate().skip(self.edges_seen) {
            self.edges[e.from].push(k as u32);
            self.edges[e.to].push(k as u32);
        }
        self.edges_seen = graph.edges.len();
        for (k, g) in graph.gps.iter().enumerate().skip(self.fixes_seen) {
            self.fixes[g.node].push(k as u32);
        }
        self.fixes_seen = graph.gps.len();
    }

    /// The relative edges at `node` (indices into the network's edges).
    pub fn edges_of(&self, node: usize) -> impl Iterator<Item = usize> + '_ {
        self.edges[node].iter().map(|&k| k as usize)
    }

    /// The GPS edges at `node`.
    pub fn fixes_of(&self, node: usize) -> impl Iterator<Item = usize> + '_ {
        self.fixes[node].iter().map(|&k| k as usize)
    }
}

/// Solves the poses of `variables` with every other node held: the window's edges are those
/// at a variable, their other ends held where they are. `adjacency` must be in step with
/// `graph`. Every variable must be linked, through the window, to a held node or to a fix.
pub fn solve_window(
    graph: &mut PoseGraph,
    adjacency: &Adjacency,
    variables: &[usize],
    params: &OptimizeParams,
) -> Result<OptimizeReport, GraphError> {
    let mut local: HashMap<usize, usize> = HashMap::with_capacity(variables.len() * 2);
    let mut window = PoseGraph::default();
    for &v in variables {
        local.entry(v).or_insert_with(|| {
            window.poses.push(graph.poses[v]);
            window.poses.len() - 1
        });
    }
    let mut edges: Vec<usize> = variables
        .iter()
        .flat_map(|&v| adjacency.edges_of(v))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let mut held = Vec::new();
    let mut index = |node: usize, window: &mut PoseGraph| {
        *local.entry(node).or_insert_with(|| {
            window.poses.push(graph.poses[node]);
            held.push(window.poses.len() - 1);
            window.poses.len() - 1
        })
    };
    for k in edges {
        let e = &graph.edges[k];
        let (from, to) = (index(e.from, &mut window), index(e.to, &mut window));
        window.edges.push(RelativeEdge {
            from,
            to,
            ..e.clone()
        });
    }
    for &v in variables {
        for k in adjacency.fixes_of(v) {
            let node = index(v, &mut window);
            window.gps.push(GpsEdge {
                node,
                ..graph.gps[k].clone()
            });
        }
    }
    if held.is_empty() && window.gps.is_empty() {
        // Nothing holds the window: it would float.
        return Err(GraphError::Singular);
    }
    let report = Optimizer::holding(held).optimize(&mut window, params)?;
    for &v in variables {
        graph.poses[v] = window.poses[local[&v]];
    }
    Ok(report)
}

/// The foreground's side of the background solve: how much of the network the solver has.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct JobSource {
    edges_sent: usize,
    fixes_sent: usize,
}

/// One global solve to run: the current estimates and what the solver has not seen yet.
#[derive(Clone, Debug)]
pub struct SolveJob {
    /// Estimates of every node when the job was made.
    poses: Vec<Pose2>,
    edges: Vec<RelativeEdge>,
    fixes: Vec<GpsEdge>,
    params: OptimizeParams,
}

impl SolveJob {
    /// Nodes in the network when the job was made.
    pub fn nodes(&self) -> usize {
        self.poses.len()
    }
}

impl JobSource {
    /// A job for the network as it is now.
    pub fn job(&mut self, graph: &PoseGraph, params: &OptimizeParams) -> SolveJob {
        let job = SolveJob {
            poses: graph.poses.clone(),
            edges: graph.edges[self.edges_sent..].to_vec(),
            fixes: graph.gps[self.fixes_sent..].to_vec(),
            params: *params,
        };
        self.edges_sent = graph.edges.len();
        self.fixes_sent = graph.gps.len();
        job
    }
}

/// The background side: the network as its jobs brought it, and the optimizer with its
/// buffers. Parts of the network that nothing anchors yet float, each in its own frame.
#[derive(Debug)]
pub struct GlobalSolver {
    graph: PoseGraph,
    optimizer: Optimizer,
}

impl Default for GlobalSolver {
    fn default() -> Self {
        GlobalSolver {
            graph: PoseGraph::default(),
            optimizer: Optimizer::for_parts(),
        }
    }
}

/// A finished global solve.
#[derive(Clone, Debug)]
pub struct SolveResult {
    /// The estimates the job started from.
    started: Vec<Pose2>,
    /// The solved poses and the report, or why the network could not be solved (a part not
    /// anchored yet: `Disconnected` or `Singular`).
    pub outcome: Result<(Vec<Pose2>, OptimizeReport), GraphError>,
}

impl SolveResult {
    /// Nodes the job held.
    pub fn nodes(&self) -> usize {
        self.started.len()
    }
}

impl GlobalSolver {
    /// The solver as it stood after the jobs `jobs` made of `graph` (a restored mapper's):
    /// the edges and fixes they carried. Its poses come with the next job, and its optimizer
    /// makes its symbolic factorization again.
    pub fn resumed(graph: &PoseGraph, jobs: &JobSource) -> GlobalSolver {
        let mut solver = GlobalSolver::default();
        solver.graph.edges = graph.edges[..jobs.edges_sent.min(graph.edges.len())].to_vec();
        solver.graph.gps = graph.gps[..jobs.fixes_sent.min(graph.gps.len())].to_vec();
        solver
    }

    /// Solves the whole network of `job` (and every job before it) from its estimates.
    pub fn solve(&mut self, job: SolveJob) -> SolveResult {
        self.graph.poses.clone_from(&job.poses);
        self.graph.edges.extend(job.edges);
        self.graph.gps.extend(job.fixes);
        let outcome = self
            .optimizer
            .optimize(&mut self.graph, &job.params)
            .map(|report| (self.graph.poses.clone(), report));
        SolveResult {
            started: job.poses,
            outcome,
        }
    }
}

/// Applies a global solve to `graph` (which may have grown since its job): node `i` of the
/// job moves by its correction `solvedᵢ · startedᵢ⁻¹`, each later node by the correction of
/// the last solved node of its chain (`chain_of`), none if its chain is new. Returns the
/// report, or the solve's error with nothing moved.
pub fn apply_solve(
    graph: &mut PoseGraph,
    result: &SolveResult,
    chain_of: impl Fn(usize) -> usize,
) -> Result<OptimizeReport, GraphError> {
    let (solved, report) = result.outcome.as_ref().map_err(Clone::clone)?;
    let mut chain_correction: HashMap<usize, Pose2> = HashMap::new();
    for (i, (after, before)) in solved.iter().zip(&result.started).enumerate() {
        let correction = after.compose(&before.inverse());
        graph.poses[i] = correction.compose(&graph.poses[i]);
        chain_correction.insert(chain_of(i), correction);
    }
    for i in result.nodes()..graph.poses.len() {
        if let Some(correction) = chain_correction.get(&chain_of(i)) {
            graph.poses[i] = correction.compose(&graph.poses[i]);
        }
    }
    Ok(*report)
}

#[cfg(test)]
#[path = "incremental_tests.rs"]
mod tests;
