//! Nonlinear least squares on the pose network: Gauss-Newton or Levenberg-Marquardt, with
//! sparse Cholesky (faer) whose symbolic factorization is kept while the network's structure
//! stays the same (warm restarts as the mapper adds measurements reuse it too).
//!
//! Beyond the paper, which solves a linear system: the full nonlinear problem on SE(2), with
//! robust kernels by iteratively reweighted least squares.

use crate::linear::SparsePattern;
use crate::network::{GraphError, PoseGraph};
use crate::se2::wrap_angle;
use nalgebra::{Matrix3, SMatrix, SVector};
use serde::{Deserialize, Serialize};

/// Which Newton-type method.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Steps accepted only when the cost drops; undamped (Gauss-Newton) until a step fails,
    /// then damped (Nielsen's update) until the damping has decayed away again.
    #[default]
    LevenbergMarquardt,
    /// Undamped steps; fastest from a good start.
    GaussNewton,
}

/// Stopping rules and method.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimizeParams {
    /// Gauss-Newton or Levenberg-Marquardt.
    pub method: Method,
    /// Most iterations (linear solves that changed the poses).
    pub max_iterations: u32,
    /// Stop when an undamped step lowers the cost by less than this fraction of it, and by
    /// at most a tenth of what the step before gained. Default 1e-6, Ceres' function
    /// tolerance (GTSAM's is 1e-5). The second condition tells the quadratic convergence
    /// near an optimum, where the rest of the decrease is smaller still, from a slow crawl
    /// along a flat valley, where much may remain.
    pub relative_decrease: f64,
    /// Stop when an accepted step lowers the cost by less than this fraction of it, however
    /// the steps before went. Default 1e-9.
    pub min_relative_decrease: f64,
    /// Stop when no pose variable moves by more than this (m or rad).
    pub min_step: f64,
    /// Levenberg-Marquardt's damping after the first failed step, relative to the diagonal
    /// of the normal matrix.
    pub initial_damping: f64,
}

impl Default for OptimizeParams {
    fn default() -> Self {
        OptimizeParams {
            method: Method::LevenbergMarquardt,
            max_iterations: 100,
            relative_decrease: 1e-6,
            min_relative_decrease: 1e-9,
            min_step: 1e-10,
            initial_damping: 1e-4,
        }
    }
}

/// Why the iteration stopped.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The cost stopped decreasing (relative decrease below the tolerance).
    Converged,
    /// The step became negligible.
    SmallStep,
    /// Levenberg-Marquardt could not find a step that lowers the cost.
    NoDescent,
    /// `max_iterations` reached.
    MaxIterations,
}

/// What an optimization did.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OptimizeReport {
    /// Σ eᵀΩe before and after, without robust kernels (g2o's convention).
    pub initial_chi2: f64,
    /// See `initial_chi2`.
    pub final_chi2: f64,
    /// The robust cost Σ ρ(eᵀΩe) that was minimized.
    pub final_cost: f64,
    /// Iterations run (linear solves that changed the poses).
    pub iterations: u32,
    /// Why it stopped.
    pub stop: StopReason,
    /// Whether the symbolic factorization of an earlier call was reused.
    pub reused_symbolic: bool,
}

/// The optimizer, with the symbolic factorization of the last network structure it saw.
#[derive(Debug, Default)]
pub struct Optimizer {
    structure: Option<Structure>,
    gauge: Gauge,
}

/// Which nodes stay where they are.
#[derive(Clone, Debug, Default, PartialEq)]
enum Gauge {
    /// Node 0 without GPS; none with it (the fixes anchor the network).
    #[default]
    FirstNode,
    /// The first node of each part that GPS does not anchor.
    FloatingParts,
    /// These nodes (sorted): a window of a network, the rest of it held.
    Nodes(Vec<usize>),
}

#[derive(Debug)]
struct Structure {
    /// Node pairs of the relative edges, GPS nodes, node count: the pattern's identity.
    key: (Vec<(usize, usize)>, Vec<usize>, usize),
    /// Variable offset of each node; `None` for the node that fixes the gauge.
    var_of: Vec<Option<usize>>,
    pattern: SparsePattern,
}

type Block = SMatrix<f64, 3, 3>;

impl Structure {
    fn build(graph: &PoseGraph, gauge: &Gauge) -> Structure {
        let n = graph.poses.len();
        let fixed = match gauge {
            Gauge::FloatingParts => graph.unanchored_part_roots(),
            Gauge::Nodes(nodes) => nodes.clone(),
            // Without GPS the network floats: node 0 fixes it.
            Gauge::FirstNode if graph.gps.is_empty() => vec![0],
            Gauge::FirstNode => Vec::new(),
        };
        let mut var_of = vec![None; n];
        let mut next = 0;
        for (i, v) in var_of.iter_mut().enumerate() {
            if fixed.binary_search(&i).is_err() {
                *v = Some(next);
                next += 3;
            }
        }
        let mut entries = Vec::new();
        for e in &graph.edges {
            push_edge_entries(&mut entries, var_of[e.from], var_of[e.to]);
        }
        for g in &graph.gps {
            push_edge_entries(&mut entries, var_of[g.node], None);
        }
        // The diagonal once more, for the damping.
        entries.extend((0..next).map(|d| (d, d)));
        Structure {
            key: structure_key(graph),
            var_of,
            pattern: SparsePattern::new_blocked(next, &entries, 3),
        }
    }
}

fn structure_key(graph: &PoseGraph) -> (Vec<(usize, usize)>, Vec<usize>, usize) {
    (
        graph.edges.iter().map(|e| (e.from, e.to)).collect(),
        graph.gps.iter().map(|g| g.node).collect(),
        graph.poses.len(),
    )
}

/// Lower-triangle entries of the blocks an edge between variables `a` and `b` touches, in
/// the order [`push_edge_values`] gives their values.
fn push_edge_entries(entries: &mut Vec<(usize, usize)>, a: Option<usize>, b: Option<usize>) {
    for v in [a, b].into_iter().flatten() {
        for r in 0..3 {
            for c in 0..=r {
                entries.push((v + r, v + c));
            }
        }
    }
    if let (Some(a), Some(b)) = (a, b) {
        let (hi, lo) = if a > b { (a, b) } else { (b, a) };
        for r in 0..3 {
            for c in 0..3 {
                entries.push((hi + r, lo + c));
            }
        }
    }
}

/// Values for [`push_edge_entries`]: diagonal blocks `haa`, `hbb`, and `hab` = Jaᵀ Ω Jb.
fn push_edge_values(
    values: &mut Vec<f64>,
    a: Option<usize>,
    b: Option<usize>,
    haa: &Block,
    hbb: &Block,
    hab: &Block,
) {
    for (v, h) in [(a, haa), (b, hbb)] {
        if v.is_some() {
            for r in 0..3 {
                for c in 0..=r {
                    values.push(h[(r, c)]);
                }
            }
        }
    }
    if let (Some(a), Some(b)) = (a, b) {
        for r in 0..3 {
            for c in 0..3 {
                // Block (hi, lo): Hab when a is the higher variable, else Hba = Habᵀ.
                values.push(if a > b { hab[(r, c)] } else { hab[(c, r)] });
            }
        }
    }
}

/// The linearized system at the current poses.
#[derive(Default)]
struct Linearization {
    values: Vec<f64>,
    gradient: Vec<f64>,
    diagonal: Vec<f64>,
    /// Σ ρ(eᵀΩe), what is minimized.
    cost: f64,
    /// Σ eᵀΩe, what is reported.
    chi2: f64,
}

impl Optimizer {
    /// An optimizer with empty buffers (they grow on the first solve and are kept).
    pub fn new() -> Optimizer {
        Optimizer::default()
    }

    /// An optimizer for a network whose parts may not be linked yet (a robot that has met
    /// no other and has no GPS): each part that GPS does not anchor keeps its first node
    /// where it is (its own gauge), instead of the network being refused as disconnected.
    pub fn for_parts() -> Optimizer {
        Optimizer {
            gauge: Gauge::FloatingParts,
            ..Optimizer::default()
        }
    }

    /// An optimizer that keeps `fixed` nodes where they are (a window of a larger network,
    /// its boundary held); every other node must be linked to one of them or to GPS.
    pub fn holding(mut fixed: Vec<usize>) -> Optimizer {
        fixed.sort_unstable();
        fixed.dedup();
        Optimizer {
            gauge: Gauge::Nodes(fixed),
            ..Optimizer::default()
        }
    }

    fn validate(&self, graph: &PoseGraph) -> Result<(), GraphError> {
        match self.gauge {
            Gauge::FirstNode => graph.validate(),
            // A part linked to no held node makes the system singular, which the
            // factorization reports.
            Gauge::FloatingParts | Gauge::Nodes(_) => graph.validate_parts(),
        }
    }

    /// Minimizes the network's robust cost in place, starting from `graph.poses`.
    pub fn optimize(
        &mut self,
        graph: &mut PoseGraph,
        params: &OptimizeParams,
    ) -> Result<OptimizeReport, GraphError> {
        self.validate(graph)?;
        let key = structure_key(graph);
        let reused_symbolic = self.structure.as_ref().is_some_and(|s| s.key == key);
        if !reused_symbolic {
            self.structure = Some(Structure::build(graph, &self.gauge));
        }
        let structure = self.structure.as_mut().expect("built above");
        let (mut lin, mut candidate) = (Linearization::default(), Linearization::default());
        linearize(graph, structure, &mut lin);
        let mut report = OptimizeReport {
            initial_chi2: lin.chi2,
            final_chi2: lin.chi2,
            final_cost: lin.cost,
            iterations: 0,
            stop: StopReason::MaxIterations,
            reused_symbolic,
        };
        if structure.pattern.dim() == 0 {
            report.stop = StopReason::SmallStep;
            return Ok(report);
        }

        // Undamped until a step fails.
        let mut lambda = 0.0;
        let mut nu = 2.0;
        let mut previous_decrease = f64::INFINITY;
        while report.iterations < params.max_iterations {
            let damping = match params.method {
                Method::GaussNewton => 0.0,
                Method::LevenbergMarquardt => lambda,
            };
            // The damping sits in the diagonal entries at the end of the values.
            let start = lin.values.len() - lin.diagonal.len();
            for (v, d) in lin.values[start..].iter_mut().zip(&lin.diagonal) {
                *v = damping * d.max(1e-12);
            }
            let factorized = structure.pattern.factorize(&lin.values);
            lin.values[start..].iter_mut().for_each(|v| *v = 0.0);
            let step = match factorized {
                Ok(()) => structure
                    .pattern
                    .solve(&lin.gradient.iter().map(|g| -g).collect::<Vec<_>>()),
                Err(_) if params.method == Method::LevenbergMarquardt => {
                    lambda = if lambda == 0.0 {
                        params.initial_damping
                    } else {
                        lambda * nu
                    };
                    nu *= 2.0;
                    if lambda > 1e16 {
                        report.stop = StopReason::NoDescent;
                        break;
                    }
                    continue;
                }
                Err(_) => return Err(GraphError::Singular),
            };
            let max_step = step.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let previous = graph.poses.clone();
            apply_step(graph, structure, &step);
            linearize(graph, structure, &mut candidate);
            let cost = candidate.cost;
            let accepted = match params.method {
                Method::GaussNewton => true,
                Method::LevenbergMarquardt => {
                    // Predicted decrease of the quadratic model with this damping.
                    let h_dx = mat_vec(&structure.pattern, &lin.values, &step);
                    let damp: f64 = step
                        .iter()
                        .zip(&lin.diagonal)
                        .map(|(s, d)| damping * d.max(1e-12) * s * s)
                        .sum();
                    let predicted = dot(&step, &h_dx) + 2.0 * damp;
                    let rho = (lin.cost - cost) / predicted.max(f64::MIN_POSITIVE);
                    if rho > 0.0 && cost.is_finite() {
                        lambda *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
                        if lambda < 1e-3 * params.initial_damping {
                            lambda = 0.0;
                        }
                        nu = 2.0;
                        true
                    } else {
                        lambda = if lambda == 0.0 {
                            params.initial_damping
                        } else {
                            lambda * nu
                        };
                        nu *= 2.0;
                        false
                    }
                }
            };
            if !accepted {
                graph.poses = previous;
                if lambda > 1e16 {
                    report.stop = StopReason::NoDescent;
                    break;
                }
                continue;
            }
            report.iterations += 1;
            let decrease = (lin.cost - cost) / lin.cost.max(f64::MIN_POSITIVE);
            std::mem::swap(&mut lin, &mut candidate);
            if max_step < params.min_step {
                report.stop = StopReason::SmallStep;
                break;
            }
            // An undamped step that gained far less than the one before: the quadratic
            // convergence of Gauss-Newton near an optimum.
            let fast = damping == 0.0 && decrease.abs() <= 0.1 * previous_decrease;
            if decrease.abs() < params.min_relative_decrease
                || (fast && decrease.abs() < params.relative_decrease)
            {
                report.stop = StopReason::Converged;
                break;
            }
            previous_decrease = decrease.abs();
        }
        // `lin` is always of the poses the graph holds now.
        report.final_chi2 = lin.chi2;
        report.final_cost = lin.cost;
        Ok(report)
    }

    /// Marginal covariance of node `node`'s (x, y, θ) at the current poses (the inverse of the
    /// normal matrix, block `node`); `None` for the node that fixes the gauge. Call after
    /// [`Optimizer::optimize`] on the same graph.
    pub fn marginal_covariance(
        &mut self,
        graph: &PoseGraph,
        node: usize,
    ) -> Result<Option<Matrix3<f64>>, GraphError> {
        Ok(self.marginal_covariances(graph, &[node])?[0])
    }

    /// [`Optimizer::marginal_covariance`] of several nodes: one factorization, and one solve
    /// with three right-hand sides per node.
    ///
    /// # Panics
    /// If a node is not in the graph.
    pub fn marginal_covariances(
        &mut self,
        graph: &PoseGraph,
        nodes: &[usize],
    ) -> Result<Vec<Option<Matrix3<f64>>>, GraphError> {
        self.validate(graph)?;
        if self
            .structure
            .as_ref()
            .is_none_or(|s| s.key != structure_key(graph))
        {
            self.structure = Some(Structure::build(graph, &self.gauge));
        }
        let structure = self.structure.as_mut().expect("built above");
        let vars: Vec<Option<usize>> = nodes.iter().map(|&n| structure.var_of[n]).collect();
        let solved: Vec<usize> = vars.iter().flatten().copied().collect();
        if solved.is_empty() {
            return Ok(vec![None; nodes.len()]);
        }
        let mut lin = Linearization::default();
        linearize(graph, structure, &mut lin);
        structure
            .pattern
            .factorize(&lin.values)
            .map_err(|_| GraphError::Singular)?;
        let dim = structure.pattern.dim();
        // A few nodes per solve: the right-hand sides are dense, dim() values each.
        let mut blocks = Vec::with_capacity(solved.len());
        for chunk in solved.chunks(32) {
            let mut units = vec![0.0; dim * 3 * chunk.len()];
            for (k, &v) in chunk.iter().enumerate() {
                for c in 0..3 {
                    units[(3 * k + c) * dim + v + c] = 1.0;
                }
            }
            let x = structure.pattern.solve_columns(&units, 3 * chunk.len());
            for (k, &v) in chunk.iter().enumerate() {
                let block = Matrix3::from_fn(|r, c| x[(3 * k + c) * dim + v + r]);
                // Symmetric up to rounding: made exactly so.
                blocks.push((block + block.transpose()) * 0.5);
            }
        }
        let mut blocks = blocks.into_iter();
        Ok(vars.iter().map(|v| v.and_then(|_| blocks.next())).collect())
    }
}

/// Linearizes the network at its current poses into `lin`, reusing its storage.
fn linearize(graph: &PoseGraph, s: &Structure, lin: &mut Linearization) {
    let dim = s.pattern.dim();
    lin.values.clear();
    lin.gradient.clear();
    lin.gradient.resize(dim, 0.0);
    lin.diagonal.clear();
    lin.diagonal.resize(dim, 0.0);
    (lin.cost, lin.chi2) = (0.0, 0.0);
    let zero = Block::zeros();
    for e in &graph.edges {
        let (err, ji, jj) = e.linearize(&graph.poses);
        let chi2 = err.dot(&(e.information * err));
        let w = e.robust.weight(chi2);
        lin.chi2 += chi2;
        lin.cost += e.robust.cost(chi2);
        let omega = e.information * w;
        let (oi, oj) = (ji.transpose() * omega, jj.transpose() * omega);
        let (hii, hjj, hij) = (oi * ji, oj * jj, oi * jj);
        let (a, b) = (s.var_of[e.from], s.var_of[e.to]);
        push_edge_values(&mut lin.values, a, b, &hii, &hjj, &hij);
        accumulate(lin, a, &(oi * err), &hii);
        accumulate(lin, b, &(oj * err), &hjj);
    }
    for g in &graph.gps {
        let (err, j) = g.linearize(&graph.poses);
        let chi2 = err.dot(&(g.information * err));
        let w = g.robust.weight(chi2);
        lin.chi2 += chi2;
        lin.cost += g.robust.cost(chi2);
        let o = j.transpose() * (g.information * w);
        let h = o * j;
        let a = s.var_of[g.node];
        push_edge_values(&mut lin.values, a, None, &h, &zero, &zero);
        accumulate(lin, a, &(o * err), &h);
    }
    lin.values.extend(std::iter::repeat_n(0.0, dim));
}

fn accumulate(lin: &mut Linearization, v: Option<usize>, g: &SVector<f64, 3>, h: &Block) {
    if let Some(v) = v {
        for r in 0..3 {
            lin.gradient[v + r] += g[r];
            lin.diagonal[v + r] += h[(r, r)];
        }
    }
}

fn apply_step(graph: &mut PoseGraph, s: &Structure, step: &[f64]) {
    for (pose, v) in graph.poses.iter_mut().zip(&s.var_of) {
        if let Some(v) = *v {
            pose.x += step[v];
            pose.y += step[v + 1];
            pose.theta = wrap_angle(pose.theta + step[v + 2]);
        }
    }
}

/// H x for H given by its lower-triangle `values` in pattern order.
fn mat_vec(pattern: &SparsePattern, values: &[f64], x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for (&(r, c), v) in pattern.entries().iter().zip(values) {
        y[r] += v * x[c];
        if r != c {
            y[c] += v * x[r];
        }
    }
    y
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
