//! Incremental smoothing with the batch answer at every node: iSAM2's method (Kaess et al.,
//! IJRR 2012) on the pose network, its Bayes tree kept at the level of single poses.
//!
//! Each pose has a conditional `R δᵥ + S δ_sep = d` on the poses eliminated after it (its
//! separator); the first of those is its parent, which makes a tree whose roots are eliminated
//! last. An update
//!
//! 1. marks the poses its new edges touch (and the poses to relinearize, with their
//!    neighbours), and removes them and every ancestor (the *top*);
//! 2. linearizes the edges among the top anew, takes each subtree hanging off the top (an
//!    *orphan*) as the factor it left on its separator when it was eliminated, orders the top
//!    by minimum degree with the update's poses last, and eliminates it again;
//! 3. solves the top from the roots down, and goes into an orphan only where its separator's
//!    step changed by more than `wildfire` (the rest of the tree keeps its steps);
//! 4. relinearizes every pose whose step exceeds `relinearize_translation` or
//!    `relinearize_rotation` (its linearization
//!    point moves to the estimate) and repeats 1–3 for them, up to `max_relinearizations`
//!    times, so the estimate handed back is a converged Gauss-Newton answer, not one step.
//!
//! The cost of an update is the top's size, not the network's. Node 0 is held where it is
//! (the gauge of a network without GPS, as the batch optimizer's), so every other node must
//! be linked to it through edges. Pure: no I/O, no threads.

mod eliminate;
mod reeliminate;
#[cfg(test)]
mod tests;

use crate::network::RelativeEdge;
use crate::se2::{Pose2, wrap_angle};
use eliminate::{Conditional, Quadratic};
use reeliminate::Scratch;
use serde::{Deserialize, Serialize};

const NONE: u32 = u32::MAX;

/// When to relinearize and how far a changed step spreads down the tree.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SmootherParams {
    /// A pose whose step in x or y exceeds this (m) is relinearized.
    pub relinearize_translation: f64,
    /// A pose whose step in θ exceeds this (rad) is relinearized.
    pub relinearize_rotation: f64,
    /// Rounds of relinearization within one update; what is left waits for the next.
    pub max_relinearizations: u32,
    /// A subtree's steps are recomputed when its separator's moved by more than this.
    pub wildfire: f64,
}

impl Default for SmootherParams {
    fn default() -> Self {
        SmootherParams {
            relinearize_translation: 1e-2,
            relinearize_rotation: 1e-2,
            max_relinearizations: 4,
            wildfire: 1e-4,
        }
    }
}

/// Why an update was refused or failed.
#[derive(Clone, Debug, PartialEq)]
pub enum SmootherError {
    /// An edge names a node that does not exist (after the update's new nodes), or links
    /// a node to itself.
    BadEdge {
        /// The edge's first node.
        from: usize,
        /// The edge's second node.
        to: usize,
        /// Nodes there would be after the update.
        nodes: usize,
    },
    /// A new node is not linked by any of the update's edges.
    Unlinked(usize),
    /// A pose's information is not positive definite: the edges do not fix it. The
    /// smoother is then inconsistent and must be rebuilt.
    Unconstrained(usize),
}

impl std::fmt::Display for SmootherError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SmootherError::BadEdge { from, to, nodes } => {
                write!(
                    f,
                    "edge {from} → {to}: no such node pair among {nodes} nodes"
                )
            }
            SmootherError::Unlinked(v) => write!(f, "node {v} has no edge: nothing places it"),
            SmootherError::Unconstrained(v) => write!(
                f,
                "node {v} is not fixed by its edges (information not positive definite)"
            ),
        }
    }
}

impl std::error::Error for SmootherError {}

/// What an update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct UpdateStats {
    /// Poses eliminated again, over all rounds.
    pub eliminated: usize,
    /// Poses whose step was recomputed, over all rounds.
    pub solved: usize,
    /// Poses relinearized.
    pub relinearized: usize,
    /// Rounds of elimination (1 + relinearization rounds).
    pub rounds: u32,
}

/// The tree's shape: what an update costs grows with the separators and the depth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TreeShape {
    /// Poses in a separator: mean and largest.
    pub separator_mean: f64,
    /// Largest separator.
    pub separator_max: usize,
    /// Poses from the deepest pose up to its root, and the mean over poses.
    pub depth_max: usize,
    /// Mean depth.
    pub depth_mean: f64,
}

/// The smoother: linearization points, steps, the tree of conditionals, and the edges.
#[derive(Clone, Debug, Default)]
pub struct IncrementalSmoother {
    params: SmootherParams,
    theta: Vec<Pose2>,
    delta: Vec<[f64; 3]>,
    edges: Vec<RelativeEdge>,
    edges_of: Vec<Vec<u32>>,
    parent: Vec<u32>,
    children: Vec<Vec<u32>>,
    position: Vec<u64>,
    next_position: u64,
    conditionals: Vec<Conditional>,
    /// What eliminating each pose left on its separator: the subtree's factor when the
    /// pose is an orphan.
    left: Vec<Quadratic>,
    /// Poses over the threshold that the last update had no round left for.
    pending: Vec<u32>,
    work: Work,
}

/// Scratch reused across updates.
#[derive(Clone, Debug, Default)]
struct Work {
    stamp: u32,
    mark: Vec<u32>,
    slot: Vec<u32>,
    edge_mark: Vec<u32>,
    changed: Vec<u32>,
    elimination: Scratch,
}

impl IncrementalSmoother {
    /// An empty smoother.
    pub fn new(params: SmootherParams) -> IncrementalSmoother {
        IncrementalSmoother {
            params,
            ..IncrementalSmoother::default()
        }
    }

    /// Nodes held.
    pub fn len(&self) -> usize {
        self.theta.len()
    }

    /// True before the first node.
    pub fn is_empty(&self) -> bool {
        self.theta.is_empty()
    }

    /// The edges taken in, in order.
    pub fn edges(&self) -> &[RelativeEdge] {
        &self.edges
    }

    /// The estimate of `node`: its linearization point moved by its step.
    pub fn estimate(&self, node: usize) -> Pose2 {
        moved(&self.theta[node], &self.delta[node])
    }

    /// Every node's estimate.
    pub fn estimates(&self) -> Vec<Pose2> {
        (0..self.len()).map(|v| self.estimate(v)).collect()
    }

    /// Every pose but node 0, each after its parent: a parent is eliminated after its
    /// children, so by elimination position, last first.
    fn roots_first(&self) -> Vec<usize> {
        let mut poses: Vec<usize> = (1..self.len()).collect();
        poses.sort_unstable_by_key(|&v| std::cmp::Reverse(self.position[v]));
        poses
    }

    /// The tree's separators and depths now.
    pub fn shape(&self) -> TreeShape {
        let n = self.len();
        let mut depth = vec![0usize; n];
        for v in self.roots_first() {
            let p = self.parent[v];
            depth[v] = if p == NONE { 1 } else { depth[p as usize] + 1 };
        }
        let seps = (1..n).map(|v| self.conditionals[v].sep.len());
        let count = n.saturating_sub(1).max(1) as f64;
        TreeShape {
            separator_mean: seps.clone().sum::<usize>() as f64 / count,
            separator_max: seps.max().unwrap_or(0),
            depth_max: depth.iter().copied().max().unwrap_or(0),
            depth_mean: depth.iter().sum::<usize>() as f64 / count,
        }
    }

    /// Recomputes every step from the roots down, whatever the wildfire threshold (O(n)): the
    /// estimates are then the exact solution at the current linearization points.
    pub fn solve_all(&mut self) {
        for v in self.roots_first() {
            self.delta[v] = self.conditionals[v].solve(&self.delta);
        }
    }

    /// Adds `poses` as the next nodes (their first guesses) and `edges` (between any nodes,
    /// old or new), and brings every estimate the update reaches to the new optimum.
    pub fn update(
        &mut self,
        poses: &[Pose2],
        edges: &[RelativeEdge],
    ) -> Result<UpdateStats, SmootherError> {
        let first_new = self.len();
        let nodes = first_new + poses.len();
        for e in edges {
            if e.from >= nodes || e.to >= nodes || e.from == e.to {
                return Err(SmootherError::BadEdge {
                    from: e.from,
                    to: e.to,
                    nodes,
                });
            }
        }
        for v in first_new.max(1)..nodes {
            if !edges.iter().any(|e| e.from == v || e.to == v) {
                return Err(SmootherError::Unlinked(v));
            }
        }
        self.grow(poses);
        let mut affected: Vec<u32> = (first_new.max(1)..nodes).map(|v| v as u32).collect();
        for e in edges {
            let k = self.edges.len() as u32;
            self.edges_of[e.from].push(k);
            self.edges_of[e.to].push(k);
            self.edges.push(e.clone());
            affected.extend([e.from as u32, e.to as u32]);
        }
        affected.retain(|&v| v != 0);
        let last: Vec<u32> = (first_new.max(1)..nodes).map(|v| v as u32).collect();
        let pending = std::mem::take(&mut self.pending);
        affected.extend(self.relinearize(&pending));
        let mut stats = UpdateStats::default();
        loop {
            let solved = self.reeliminate(&affected, &last, &mut stats)?;
            let over: Vec<u32> = solved
                .into_iter()
                .filter(|&v| {
                    let d = &self.delta[v as usize];
                    d[0].abs().max(d[1].abs()) > self.params.relinearize_translation
                        || d[2].abs() > self.params.relinearize_rotation
                })
                .collect();
            if over.is_empty() {
                break;
            }
            if stats.rounds > self.params.max_relinearizations {
                self.pending = over;
                break;
            }
            stats.relinearized += over.len();
            affected = self.relinearize(&over);
        }
        Ok(stats)
    }

    fn grow(&mut self, poses: &[Pose2]) {
        let n = self.len() + poses.len();
        self.theta.extend_from_slice(poses);
        self.delta.resize(n, [0.0; 3]);
        self.edges_of.resize(n, Vec::new());
        self.parent.resize(n, NONE);
        self.children.resize(n, Vec::new());
        self.position.resize(n, 0);
        self.conditionals.resize(n, Conditional::default());
        self.left.resize(n, Quadratic::default());
        self.work.mark.resize(n, 0);
        self.work.slot.resize(n, 0);
        self.work.changed.resize(n, 0);
    }

    /// Moves the linearization points of `nodes` to their estimates; returns them with the
    /// nodes they share an edge with (whose factors change too).
    fn relinearize(&mut self, nodes: &[u32]) -> Vec<u32> {
        let mut affected = Vec::with_capacity(nodes.len() * 3);
        for &v in nodes {
            let v = v as usize;
            self.theta[v] = self.estimate(v);
            self.delta[v] = [0.0; 3];
            for &k in &self.edges_of[v] {
                let e = &self.edges[k as usize];
                affected.extend([e.from as u32, e.to as u32]);
            }
        }
        affected.retain(|&v| v != 0);
        affected.sort_unstable();
        affected.dedup();
        affected
    }

    fn next_stamp(&mut self) -> u32 {
        self.work.stamp = self.work.stamp.wrapping_add(1);
        if self.work.stamp == 0 {
            self.work.mark.fill(0);
            self.work.edge_mark.fill(0);
            self.work.changed.fill(0);
            self.work.stamp = 1;
        }
        self.work.stamp
    }

    /// Solves the re-eliminated poses from the roots down, then each subtree below them
    /// whose separator moved by more than the wildfire threshold.
    fn solve_down(&mut self, order: &[u32], stamp: u32) -> Vec<u32> {
        let mut solved = Vec::with_capacity(order.len());
        let mut stack = Vec::new();
        for &v in order.iter().rev() {
            self.step(v, stamp);
            solved.push(v);
            stack.extend(
                self.children[v as usize]
                    .iter()
                    .copied()
                    .filter(|&c| self.work.mark[c as usize] != stamp),
            );
        }
        while let Some(v) = stack.pop() {
            let conditional = &self.conditionals[v as usize];
            if !conditional
                .sep
                .iter()
                .any(|&u| self.work.changed[u as usize] == stamp)
            {
                continue;
            }
            self.step(v, stamp);
            solved.push(v);
            if self.work.changed[v as usize] == stamp {
                stack.extend(self.children[v as usize].iter().copied());
            }
        }
        solved
    }

    /// Recomputes the step of `v`, marking it changed when it moved past the wildfire.
    fn step(&mut self, v: u32, stamp: u32) {
        let new = self.conditionals[v as usize].solve(&self.delta);
        let old = &mut self.delta[v as usize];
        if new
            .iter()
            .zip(old.iter())
            .any(|(a, b)| (a - b).abs() > self.params.wildfire)
        {
            self.work.changed[v as usize] = stamp;
        }
        *old = new;
    }
}

fn moved(p: &Pose2, d: &[f64; 3]) -> Pose2 {
    Pose2 {
        x: p.x + d[0],
        y: p.y + d[1],
        theta: wrap_angle(p.theta + d[2]),
    }
}
