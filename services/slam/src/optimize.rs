//! Nonlinear least squares on the pose network: Gauss-Newton or Levenberg-Marquardt, with
//! sparse Cholesky (faer) whose symbolic factorization is kept while the network's structure
//! stays the same (warm restarts as the mapper adds measurements reuse it too).
//!
//! Beyond the paper, which solves a linear system: the full nonlinear problem on SE(2), with
//! robust kernels by iteratively reweighted least squares.

use crate::init::{Init, InitError, initialize_validated, network_order};
use crate::linear::{NodeOrder, SparsePattern};
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

/// Near an optimum the normal matrix barely changes from step to step: after an undamped
/// step that moved no variable by more than this (m or rad, about 3°), the Jacobians, and with
/// them the matrix, are within a few percent of those the step was solved with, so the next
/// step is first solved with the same factor (a chord step). Where that step only confirms
/// convergence, as the last step from the chordal start does, it saves a factorization; a
/// chord step that does not lower the cost is taken back and the step made with a new factor.
/// At most one chord step follows a factorization.
const CHORD_STEP_LIMIT: f64 = 0.05;

/// The optimizer, with the fill-reducing order and the symbolic factorization of the last
/// network structure it saw.
#[derive(Debug, Default)]
pub struct Optimizer {
    structure: Option<Structure>,
    order: Option<KeyedOrder>,
    gauge: Gauge,
}

/// A network's node order with what it was computed from: the node count and the edges.
#[derive(Debug)]
struct KeyedOrder {
    nodes: usize,
    links: Vec<(usize, usize)>,
    order: NodeOrder,
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
    fn build(graph: &PoseGraph, gauge: &Gauge, order: &NodeOrder) -> Structure {
        let n = graph.poses.len();
        let fixed = match gauge {
            Gauge::FloatingParts => graph.unanchored_part_roots(),
            Gauge::Nodes(nodes) => nodes.clone(),
            // Without GPS the network floats: node 0 fixes it.
            Gauge::FirstNode if graph.gps.is_empty() => vec![0],
            Gauge::FirstNode => Vec::new(),
        };
        let mut var_of = vec![None; n];
        let mut kept = Vec::with_capacity(n);
        for (i, v) in var_of.iter_mut().enumerate() {
            if fixed.binary_search(&i).is_err() {
                *v = Some(3 * kept.len());
                kept.push(i);
            }
        }
        // The nonzero 3×3 blocks, in the order `linearize` gives their values.
        let block = |v: Option<usize>| v.map(|v| v / 3);
        let mut nonzero = Vec::with_capacity(3 * graph.edges.len() + graph.gps.len() + kept.len());
        for e in &graph.edges {
            push_edge_blocks(&mut nonzero, block(var_of[e.from]), block(var_of[e.to]));
        }
        for g in &graph.gps {
            push_edge_blocks(&mut nonzero, block(var_of[g.node]), None);
        }
        // The diagonal blocks once more, for the damping.
        nonzero.extend((0..kept.len()).map(|b| (b, b)));
        Structure {
            key: structure_key(graph),
            var_of,
            pattern: SparsePattern::ordered(3, &nonzero, &order.places_of(&kept)),
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

/// The blocks an edge between variable blocks `a` and `b` touches, in the order
/// [`push_edge_values`] gives their values: the diagonal blocks, then the one below it.
fn push_edge_blocks(nonzero: &mut Vec<(usize, usize)>, a: Option<usize>, b: Option<usize>) {
    nonzero.extend(a.map(|a| (a, a)));
    nonzero.extend(b.map(|b| (b, b)));
    if let (Some(a), Some(b)) = (a, b) {
        nonzero.push((a.max(b), a.min(b)));
    }
}

/// Values for [`push_edge_blocks`]: diagonal blocks `haa`, `hbb`, and `hab` = Jaᵀ Ω Jb.
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

    /// Sets `graph.poses` by `init` as [`crate::initialize`] does, keeping the network's
    /// fill-reducing order for the solves that follow (the chordal initialization's systems
    /// and the optimizer's are on the same graph).
    pub fn initialize(&mut self, graph: &mut PoseGraph, init: Init) -> Result<(), InitError> {
        graph.validate()?;
        let order = (init == Init::Chordal).then(|| self.order_of(graph));
        initialize_validated(graph, init, order)
    }

    /// The network's node order, computed again only when its edges changed.
    fn order_of(&mut self, graph: &PoseGraph) -> &NodeOrder {
        let same = self.order.as_ref().is_some_and(|o| {
            o.nodes == graph.poses.len()
                && o.links.len() == graph.edges.len()
                && o.links
                    .iter()
                    .zip(&graph.edges)
                    .all(|(&link, e)| link == (e.from, e.to))
        });
        if !same {
            self.order = Some(KeyedOrder {
                nodes: graph.poses.len(),
                links: graph.edges.iter().map(|e| (e.from, e.to)).collect(),
                order: network_order(graph),
            });
        }
        &self.order.as_ref().expect("set above").order
    }

    /// The structure of `graph`, built again only when it changed; true if it was kept.
    fn structure_of(&mut self, graph: &PoseGraph) -> bool {
        let key = structure_key(graph);
        if self.structure.as_ref().is_some_and(|s| s.key == key) {
            return true;
        }
        let gauge = self.gauge.clone();
        let structure = Structure::build(graph, &gauge, self.order_of(graph));
        self.structure = Some(structure);
        false
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
        let reused_symbolic = self.structure_of(graph);
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
        // The last factor is undamped and its step was small: the next step tries it first.
        let mut chord_ready = false;
        while report.iterations < params.max_iterations {
            let damping = match params.method {
                Method::GaussNewton => 0.0,
                Method::LevenbergMarquardt => lambda,
            };
            let chord = chord_ready && damping == 0.0;
            chord_ready = false;
            // The damping sits in the diagonal blocks at the end of the values (lower
            // triangles row by row: the diagonal is at 0, 2 and 5 of each).
            let start = lin.values.len() - 2 * lin.diagonal.len();
            for (block, d) in lin.values[start..]
                .chunks_exact_mut(6)
                .zip(lin.diagonal.chunks_exact(3))
            {
                for (k, d) in [0, 2, 5].into_iter().zip(d) {
                    block[k] = damping * d.max(1e-12);
                }
            }
            let factorized = if chord {
                Ok(())
            } else {
                structure.pattern.factorize(&lin.values)
            };
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
                // A chord step must lower the cost; otherwise a fresh factor is made.
                _ if chord => cost < lin.cost,
                Method::GaussNewton => true,
                Method::LevenbergMarquardt => {
                    // The gain ratio ρ: the decrease over the quadratic model's prediction
                    // with this damping. Undamped, only its sign matters (the damping stays
                    // zero), and that is the decrease's: the product H·step is not needed.
                    let rho = if damping == 0.0 {
                        lin.cost - cost
                    } else {
                        let h_dx = structure.pattern.multiply(&lin.values, &step);
                        let damp: f64 = step
                            .iter()
                            .zip(&lin.diagonal)
                            .map(|(s, d)| damping * d.max(1e-12) * s * s)
                            .sum();
                        let predicted = dot(&step, &h_dx) + 2.0 * damp;
                        (lin.cost - cost) / predicted.max(f64::MIN_POSITIVE)
                    };
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
            chord_ready = !chord && damping == 0.0 && max_step <= CHORD_STEP_LIMIT;
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
        self.structure_of(graph);
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
    lin.values.extend(std::iter::repeat_n(0.0, 2 * dim));
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

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
