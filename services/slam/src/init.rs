//! Initial poses for the optimizer. Where odometry is poor, Gauss-Newton from the chained
//! measurements stops in local minima; the chordal initialization (a linear rotation estimate
//! over all edges, then linear translations; Carlone et al. 2015) starts close enough to the
//! global optimum on the standard benchmarks that GTSAM and g2o miss from their defaults.

use crate::linear::{NodeOrder, NotPositiveDefinite, SparsePattern, c64};
use crate::network::{GraphError, PoseGraph};
use crate::se2::Pose2;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// How to initialize the poses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Init {
    /// Keep the poses in the graph (e.g. the file's vertices).
    Given,
    /// Chain the edges i → i+1.
    Odometry,
    /// Compose measurements along a breadth-first spanning tree from node 0.
    Spanning,
    /// Linear rotation estimate over all edges, then linear translations.
    #[default]
    Chordal,
}

/// Why an initialization is impossible.
#[derive(Clone, Debug, PartialEq)]
pub enum InitError {
    /// The network itself is invalid.
    Graph(GraphError),
    /// `Init::Odometry` needs an edge i → i+1 for every i.
    MissingOdometry {
        /// The node with no odometry edge to the next one.
        from: usize,
    },
}

impl std::fmt::Display for InitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InitError::Graph(e) => e.fmt(f),
            InitError::MissingOdometry { from } => {
                write!(
                    f,
                    "no odometry edge from node {from} to node {}: use --init spanning or chordal",
                    from + 1
                )
            }
        }
    }
}

impl std::error::Error for InitError {}

impl From<GraphError> for InitError {
    fn from(e: GraphError) -> InitError {
        InitError::Graph(e)
    }
}

/// Sets `graph.poses` by `init`, with node 0 at the origin (or kept, for `Given`). With GPS
/// edges the result is then moved rigidly onto the fixes (least squares), so the optimizer
/// starts in the east-north frame of the datum.
pub fn initialize(graph: &mut PoseGraph, init: Init) -> Result<(), InitError> {
    graph.validate()?;
    initialize_validated(graph, init, None)
}

/// [`initialize`] of a validated network, the chordal systems ordered by `order` (the
/// network's [`network_order`], which the optimizer keeps for its own system) or by their
/// own.
pub(crate) fn initialize_validated(
    graph: &mut PoseGraph,
    init: Init,
    order: Option<&NodeOrder>,
) -> Result<(), InitError> {
    match init {
        Init::Given => return Ok(()),
        Init::Odometry => odometry(graph)?,
        Init::Spanning => spanning(graph),
        Init::Chordal => {
            let own;
            let order = match order {
                Some(order) => order,
                None => {
                    own = network_order(graph);
                    &own
                }
            };
            chordal(graph, order).map_err(|_| GraphError::Singular)?
        }
    }
    align_to_gps(graph);
    Ok(())
}

/// The fill-reducing order of a network's nodes, linked by its relative edges (GPS edges
/// touch one node each and add no link): the chordal systems' and the optimizer's.
pub(crate) fn network_order(graph: &PoseGraph) -> NodeOrder {
    NodeOrder::new(
        graph.poses.len(),
        graph.edges.iter().map(|e| (e.from, e.to)),
    )
}

/// Moves all poses by the rigid motion that best maps their antenna positions onto the GPS
/// fixes (2D Procrustes, least squares). Needs fixes at two or more distinct places.
fn align_to_gps(graph: &mut PoseGraph) {
    let pairs: Vec<([f64; 2], [f64; 2])> = graph
        .gps
        .iter()
        .map(|g| {
            (
                graph.poses[g.node].transform_point([g.lever_arm_m.x, g.lever_arm_m.y]),
                [g.position_m.x, g.position_m.y],
            )
        })
        .collect();
    // None: under two fixes, or all at one place (no orientation to take).
    let Some(motion) = crate::se2::rigid_fit(&pairs) else {
        return;
    };
    for pose in &mut graph.poses {
        *pose = motion.compose(pose);
    }
}

fn odometry(graph: &mut PoseGraph) -> Result<(), InitError> {
    let n = graph.poses.len();
    let mut step = vec![None; n.saturating_sub(1)];
    for e in &graph.edges {
        if e.to == e.from + 1 && step[e.from].is_none() {
            step[e.from] = Some(e.measurement);
        }
    }
    graph.poses[0] = Pose2::IDENTITY;
    for (i, z) in step.iter().enumerate() {
        let z = z.ok_or(InitError::MissingOdometry { from: i })?;
        graph.poses[i + 1] = graph.poses[i].compose(&z);
    }
    Ok(())
}

/// Breadth-first from node 0 (nodes it cannot reach keep their poses).
fn spanning(graph: &mut PoseGraph) {
    let n = graph.poses.len();
    let mut adjacency: Vec<Vec<(usize, usize)>> = vec![Vec::new(); n];
    for (k, e) in graph.edges.iter().enumerate() {
        adjacency[e.from].push((e.to, k));
        adjacency[e.to].push((e.from, k));
    }
    let mut seen = vec![false; n];
    let mut queue = VecDeque::from([0]);
    seen[0] = true;
    graph.poses[0] = Pose2::IDENTITY;
    while let Some(i) = queue.pop_front() {
        for &(j, k) in &adjacency[i] {
            if !seen[j] {
                seen[j] = true;
                let e = &graph.edges[k];
                let z = if e.from == i {
                    e.measurement
                } else {
                    e.measurement.inverse()
                };
                graph.poses[j] = graph.poses[i].compose(&z);
                queue.push_back(j);
            }
        }
    }
}

/// Chordal relaxation: rotations as free complex numbers r_i (cos θ_i + i sin θ_i) with
/// r_0 = 1, minimizing Σ κ |r_j − e^{iθ_z} r_i|², projected back to angles; then translations
/// with the rotations fixed, minimizing Σ τ |t_j − t_i − R_i t_z|². κ and τ are the edge's
/// rotational and (isotropic) translational information, as in SE-Sync. Both systems have one
/// unknown per node and one pattern (the weighted graph Laplacian's): a Hermitian one for the
/// rotations, and a real one with two right-hand sides (x, y) for the translations.
fn chordal(graph: &mut PoseGraph, order: &NodeOrder) -> Result<(), NotPositiveDefinite> {
    let n = graph.poses.len();
    if n < 2 {
        graph.poses.iter_mut().for_each(|p| *p = Pose2::IDENTITY);
        return Ok(());
    }
    // Node 0 stays at the origin with heading 0; node i's unknown is i − 1.
    let var = |i: usize| i.checked_sub(1);
    let dim = n - 1;
    let mut entries = Vec::with_capacity(3 * graph.edges.len());
    for e in &graph.edges {
        let (vi, vj) = (var(e.from), var(e.to));
        entries.extend(vi.map(|i| (i, i)));
        entries.extend(vj.map(|j| (j, j)));
        if let (Some(i), Some(j)) = (vi, vj) {
            entries.push((i.max(j), i.min(j)));
        }
    }
    let kept: Vec<usize> = (1..n).collect();
    let mut positions = SparsePattern::<f64>::ordered(1, &entries, &order.places_of(&kept));
    let mut rotations: SparsePattern<c64> = positions.sharing();

    // Rotations: the residual r_j − z r_i, z = e^{iθ_z}, is linear in the unknowns; its
    // normal matrix is Hermitian, A_jj = A_ii = κ, A_ji = −κ z.
    let mut values = Vec::with_capacity(entries.len());
    let mut rhs = vec![c64::new(0.0, 0.0); dim];
    for e in &graph.edges {
        let kappa = e.information[(2, 2)];
        let (s, c) = e.measurement.theta.sin_cos();
        let z = c64::new(c, s);
        match (var(e.from), var(e.to)) {
            (Some(i), Some(j)) => {
                let k = c64::new(kappa, 0.0);
                let below = if j > i { -z * kappa } else { -z.conj() * kappa };
                values.extend([k, k, below]);
            }
            // r_0 = 1 fixed: r_j − z, or 1 − z r_i.
            (None, Some(j)) => {
                values.push(c64::new(kappa, 0.0));
                rhs[j] += z * kappa;
            }
            (Some(i), None) => {
                values.push(c64::new(kappa, 0.0));
                rhs[i] += z.conj() * kappa;
            }
            (None, None) => {}
        }
    }
    rotations.factorize(&values)?;
    let r = rotations.solve(&rhs);
    let angles: Vec<f64> = (0..n)
        .map(|i| var(i).map_or(0.0, |v| r[v].im.atan2(r[v].re)))
        .collect();

    // Translations: the residual t_j − t_i − d, d = R_i t_z, t_0 = 0; x and y apart.
    let mut values = Vec::with_capacity(entries.len());
    let mut rhs = vec![0.0; 2 * dim];
    for e in &graph.edges {
        let info = e.information.fixed_view::<2, 2>(0, 0).into_owned();
        let tau = info
            .try_inverse()
            .map_or(0.0, |cov| 2.0 / cov.trace().max(f64::MIN_POSITIVE));
        let (s, c) = angles[e.from].sin_cos();
        let d = [
            c * e.measurement.x - s * e.measurement.y,
            s * e.measurement.x + c * e.measurement.y,
        ];
        let (vi, vj) = (var(e.from), var(e.to));
        for (v, sign) in [(vi, -1.0), (vj, 1.0)] {
            if let Some(v) = v {
                values.push(tau);
                rhs[v] += sign * tau * d[0];
                rhs[dim + v] += sign * tau * d[1];
            }
        }
        if vi.is_some() && vj.is_some() {
            values.push(-tau);
        }
    }
    positions.factorize(&values)?;
    let t = positions.solve_columns(&rhs, 2);
    for (i, pose) in graph.poses.iter_mut().enumerate() {
        *pose = match var(i) {
            None => Pose2::IDENTITY,
            Some(v) => Pose2::new(t[v], t[dim + v], angles[i]),
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::{EdgeKind, RelativeEdge};
    use crate::robust::Robust;
    use nalgebra::Matrix3;

    /// A square loop of four noise-free edges.
    fn square() -> (PoseGraph, Vec<Pose2>) {
        let truth = vec![
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(2.0, 0.0, std::f64::consts::FRAC_PI_2),
            Pose2::new(2.0, 2.0, std::f64::consts::PI),
            Pose2::new(0.0, 2.0, -std::f64::consts::FRAC_PI_2),
        ];
        let mut g = PoseGraph {
            poses: vec![Pose2::IDENTITY; 4],
            ..Default::default()
        };
        for (i, j) in [(0, 1), (1, 2), (2, 3), (3, 0), (0, 2)] {
            g.edges.push(exact_edge(&truth, i, j));
        }
        (g, truth)
    }

    /// An edge from node `i` to `j` measuring their true relative pose exactly.
    fn exact_edge(truth: &[Pose2], i: usize, j: usize) -> RelativeEdge {
        RelativeEdge {
            from: i,
            to: j,
            measurement: truth[i].between(&truth[j]),
            information: Matrix3::from_diagonal(&nalgebra::Vector3::new(10.0, 20.0, 100.0)),
            kind: EdgeKind::Odometry,
            robust: Robust::None,
        }
    }

    #[test]
    fn every_initialization_recovers_a_noise_free_loop() {
        for init in [Init::Odometry, Init::Spanning, Init::Chordal] {
            let (mut g, truth) = square();
            initialize(&mut g, init).unwrap();
            for (p, t) in g.poses.iter().zip(&truth) {
                assert!(
                    (p.x - t.x).abs() < 1e-9 && (p.y - t.y).abs() < 1e-9,
                    "{init:?}: {p:?} vs {t:?}"
                );
                assert!(
                    crate::wrap_angle(p.theta - t.theta).abs() < 1e-9,
                    "{init:?}"
                );
            }
        }
    }

    /// A noise-free network of many nodes, odometry and closures, where the order of the
    /// unknowns is far from the nodes' own.
    #[test]
    fn chordal_recovers_a_noise_free_network() {
        let mut rng = crate::splitmix::SplitMix::new(3);
        let n = 60;
        let truth: Vec<Pose2> = (0..n)
            .map(|_| {
                Pose2::new(
                    rng.uniform(-20.0, 20.0),
                    rng.uniform(-20.0, 20.0),
                    rng.uniform(-3.0, 3.0),
                )
            })
            .collect();
        let mut g = PoseGraph {
            poses: vec![Pose2::IDENTITY; n],
            ..Default::default()
        };
        for i in 0..n - 1 {
            g.edges.push(exact_edge(&truth, i, i + 1));
        }
        for _ in 0..40 {
            let (i, j) = (
                (rng.unit() * n as f64) as usize,
                (rng.unit() * n as f64) as usize,
            );
            if i != j {
                g.edges.push(exact_edge(&truth, i, j));
            }
        }
        initialize(&mut g, Init::Chordal).unwrap();
        let origin = truth[0];
        for (p, t) in g.poses.iter().zip(&truth) {
            let t = origin.between(t);
            assert!(
                (p.x - t.x).abs() < 1e-6 && (p.y - t.y).abs() < 1e-6,
                "{p:?} vs {t:?}"
            );
            assert!(crate::wrap_angle(p.theta - t.theta).abs() < 1e-9);
        }
    }

    #[test]
    fn odometry_needs_a_chain() {
        let (mut g, _) = square();
        g.edges.retain(|e| !(e.from == 1 && e.to == 2));
        assert_eq!(
            initialize(&mut g, Init::Odometry),
            Err(InitError::MissingOdometry { from: 1 })
        );
    }
}
