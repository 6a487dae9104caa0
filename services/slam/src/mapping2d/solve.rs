//! When the network is optimized: at once; or, deferred, a window of the node's chain at
//! once and the whole network when the caller runs it, now or in the background
//! ([`crate::incremental`]); never while a part of it is not anchored yet.

use super::Mapper2d;
use crate::incremental::{
    Adjacency, GlobalSolver, JobSource, SolveJob, SolveResult, apply_solve, solve_window,
};
use crate::network::GraphError;
use crate::optimize::OptimizeReport;
use serde::{Deserialize, Serialize};

/// A deferred mapper's solving state.
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct Background {
    /// Each node's edges and fixes, synced with the network where it is read.
    pub(super) adjacency: Adjacency,
    pub(super) jobs: JobSource,
    /// The global solver; `None` while it is out with a job. Not saved: made again from the
    /// network and `jobs` ([`GlobalSolver::resumed`]).
    #[serde(skip)]
    pub(super) solver: Option<GlobalSolver>,
    /// Bumped by every solve in the foreground: a background solve taken before it is stale.
    generation: u64,
}

impl Default for Background {
    fn default() -> Self {
        Background {
            adjacency: Adjacency::default(),
            jobs: JobSource::default(),
            solver: Some(GlobalSolver::default()),
            generation: 0,
        }
    }
}

/// A solve of the whole network taken out of the mapper ([`Mapper2d::take_solve`]), to
/// [`run`](Self::run) on any thread and give back with [`Mapper2d::finish_solve`].
#[derive(Debug)]
pub struct BackgroundSolve {
    solver: GlobalSolver,
    job: SolveJob,
    generation: u64,
}

/// A background solve that ran: give it back with [`Mapper2d::finish_solve`].
#[derive(Debug)]
pub struct SolvedInBackground {
    solver: GlobalSolver,
    result: SolveResult,
    generation: u64,
}

impl BackgroundSolve {
    /// Nodes in the network when it was taken.
    pub fn nodes(&self) -> usize {
        self.job.nodes()
    }

    /// Solves the whole network as it was when taken.
    pub fn run(mut self) -> SolvedInBackground {
        let result = self.solver.solve(self.job);
        SolvedInBackground {
            solver: self.solver,
            result,
            generation: self.generation,
        }
    }
}

impl SolvedInBackground {
    /// Nodes in the network when it was taken.
    pub fn nodes(&self) -> usize {
        self.result.nodes()
    }
}

impl Mapper2d {
    /// Optimizes now; or, with `defer_optimization`, re-solves the window of `node`'s chain
    /// and marks the whole network's solve pending.
    pub(super) fn optimize_when_anchored(&mut self, node: usize) -> Result<(), GraphError> {
        if self.params.defer_optimization {
            self.optimization_pending = true;
            self.solve_window(node);
            return Ok(());
        }
        self.optimize_anchored().map(drop)
    }

    /// The GPS edges of `node` in the network.
    pub(super) fn fixes_on(&mut self, node: usize) -> usize {
        self.background.adjacency.sync(&self.graph);
        self.background.adjacency.fixes_of(node).count()
    }

    /// Re-solves the newest `local_window_nodes` nodes of `node`'s chain, every other node
    /// held. The chain's first node is held too, so the window is always tied to something.
    fn solve_window(&mut self, node: usize) {
        let size = self.params.local_window_nodes as isize;
        let variables: Vec<usize> = (0..size)
            .map_while(|k| self.chain_neighbour(node, -k))
            .filter(|&n| self.node_robot[n].1 > 0)
            .collect();
        if variables.is_empty() {
            return;
        }
        let background = &mut self.background;
        background.adjacency.sync(&self.graph);
        let params = &self.params.optimize;
        if solve_window(&mut self.graph, &background.adjacency, &variables, params).is_ok() {
            self.stats.window_solves += 1;
            self.near.refile(&self.graph.poses, &variables);
        }
    }

    /// The solve of the whole network that nodes since the last one called for (with
    /// `defer_optimization`), taken out to run in the background; `None` when none is
    /// pending, or the last one is still out.
    pub fn take_solve(&mut self) -> Option<BackgroundSolve> {
        if !self.optimization_pending {
            return None;
        }
        let taken = self.take_solve_now()?;
        self.optimization_pending = false;
        Some(taken)
    }

    /// The background solve of the network as it is, pending or not (a replay takes it
    /// where the original did); `None` while the last one is out.
    pub fn take_solve_now(&mut self) -> Option<BackgroundSolve> {
        let solver = self.background.solver.take()?;
        let job = self.background.jobs.job(&self.graph, &self.params.optimize);
        Some(BackgroundSolve {
            solver,
            job,
            generation: self.background.generation,
        })
    }

    /// Gives back a background solve and applies it: each node it solved moves by its
    /// correction, each node added since with the last solved node of its chain. Returns
    /// whether it was applied: not when a part of the network was not anchored yet (counted
    /// as deferred), nor when the network was solved in the foreground since it was taken
    /// (it is stale; the next background solve is pending then).
    pub fn finish_solve(&mut self, done: SolvedInBackground) -> Result<bool, GraphError> {
        self.background.solver = Some(done.solver);
        if done.generation != self.background.generation {
            self.optimization_pending = true;
            return Ok(false);
        }
        let robots = &self.node_robot;
        match apply_solve(&mut self.graph, &done.result, |node| robots[node].0) {
            Ok(report) => {
                self.stats.optimizations += 1;
                self.last_optimization = Some(report);
                self.near.rebuild(&self.graph.poses);
                Ok(true)
            }
            Err(GraphError::Disconnected { .. } | GraphError::Singular) => {
                self.stats.deferred_optimizations += 1;
                Ok(false)
            }
            Err(e) => Err(e),
        }
    }

    /// Runs the optimization that scans added since the last one called for (with
    /// `defer_optimization`), here and now; returns whether one ran.
    pub fn optimize_pending(&mut self) -> Result<bool, GraphError> {
        if !std::mem::take(&mut self.optimization_pending) {
            return Ok(false);
        }
        self.optimize_anchored()
    }

    /// Optimizes now, pending or not, unless a part of the network is not anchored yet;
    /// returns whether it ran.
    pub fn optimize_now(&mut self) -> Result<bool, GraphError> {
        self.optimization_pending = false;
        self.optimize_anchored()
    }

    /// Optimizes unless a part of the network is not anchored yet; returns whether it ran.
    fn optimize_anchored(&mut self) -> Result<bool, GraphError> {
        match self.optimize() {
            Ok(_) => Ok(true),
            Err(GraphError::Disconnected { .. } | GraphError::Singular) => {
                self.stats.deferred_optimizations += 1;
                Ok(false)
            }
            Err(e) => Err(e),
        }
    }

    /// Optimizes the whole network now and records the report. A background solve out
    /// meanwhile becomes stale.
    pub(super) fn optimize(&mut self) -> Result<OptimizeReport, GraphError> {
        self.background.generation += 1;
        let report = self
            .optimizer
            .optimize(&mut self.graph, &self.params.optimize);
        // A failed solve may have moved the poses too.
        self.near.rebuild(&self.graph.poses);
        let report = report?;
        self.stats.optimizations += 1;
        self.last_optimization = Some(report);
        Ok(report)
    }
}
