//! Initial poses for the optimizer. Where odometry is poor, Gauss-Newton from the chained
//! measurements stops in local minima; the chordal initialization (a linear rotation estimate
//! over all edges, then linear translations; Carlone et al. 2015) starts close enough to the
//! global optimum on the standard benchmarks that GTSAM and g2o miss from their defaults.

use crate::linear::{NotPositiveDefinite, solve_once};
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
    match init {
        Init::Given => return Ok(()),
        Init::Odometry => odometry(graph)?,
        Init::Spanning => spanning(graph),
        Init::Chordal => chordal(graph).map_err(|_| GraphError::Singular)?,
    }
    align_to_gps(graph);
    Ok(())
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

/// Chordal relaxation: rotations as free 2-vectors r_i = (cos θ_i, sin θ_i) with r_0 fixed,
/// minimizing Σ κ |r_j − R(θ_z) r_i|², projected back to angles; then translations with the
/// rotations fixed, minimizing Σ τ |t_j − t_i − R_i t_z|². κ and τ are the edge's rotational
/// and (isotropic) translational information, as in SE-Sync.
fn chordal(graph: &mut PoseGraph) -> Result<(), NotPositiveDefinite> {
    let n = graph.poses.len();
    if n < 2 {
        graph.poses.iter_mut().for_each(|p| *p = Pose2::IDENTITY);
        return Ok(());
    }
    // Unknowns: 2 per node except node 0; index of node i's first unknown is 2(i − 1).
    let var = |i: usize| if i == 0 { None } else { Some(2 * (i - 1)) };
    let dim = 2 * (n - 1);

    // Rotations. Residual r_j − M r_i with M = R(θ_z); r_0 = (1, 0) moves to the right side.
    let mut triplets = Vec::new();
    let mut rhs = vec![0.0; dim];
    for e in &graph.edges {
        let kappa = e.information[(2, 2)];
        let (s, c) = e.measurement.theta.sin_cos();
        let m = [[c, -s], [s, c]];
        let (vi, vj) = (var(e.from), var(e.to));
        add_pair_blocks(
            &mut triplets,
            &mut rhs,
            vi,
            vj,
            kappa,
            m,
            [1.0, 0.0],
            [0.0, 0.0],
        );
    }
    let r = solve_once(dim, 2, &triplets, &rhs)?;
    let theta = |i: usize| var(i).map_or(0.0, |v| r[v + 1].atan2(r[v]));
    let angles: Vec<f64> = (0..n).map(theta).collect();

    // Translations: residual t_j − t_i − R_i t_z, t_0 = 0.
    triplets.clear();
    rhs.iter_mut().for_each(|x| *x = 0.0);
    for e in &graph.edges {
        let info = e.information.fixed_view::<2, 2>(0, 0).into_owned();
        let tau = info
            .try_inverse()
            .map_or(0.0, |cov| 2.0 / cov.trace().max(f64::MIN_POSITIVE));
        let (s, c) = angles[e.from].sin_cos();
        let rotated = [
            c * e.measurement.x - s * e.measurement.y,
            s * e.measurement.x + c * e.measurement.y,
        ];
        let (vi, vj) = (var(e.from), var(e.to));
        add_pair_blocks(
            &mut triplets,
            &mut rhs,
            vi,
            vj,
            tau,
            [[1.0, 0.0], [0.0, 1.0]],
            [0.0, 0.0],
            rotated,
        );
    }
    let t = solve_once(dim, 2, &triplets, &rhs)?;
    for (i, pose) in graph.poses.iter_mut().enumerate() {
        *pose = match var(i) {
            None => Pose2::IDENTITY,
            Some(v) => Pose2::new(t[v], t[v + 1], angles[i]),
        };
    }
    Ok(())
}

/// Normal-equation terms of w |x_j − M x_i − d|² over 2-vectors, with x_0 = `fixed` (node 0
/// has no unknowns): blocks in lower-triangle triplets, right-hand side in `rhs`.
#[allow(clippy::too_many_arguments)]
fn add_pair_blocks(
    triplets: &mut Vec<(usize, usize, f64)>,
    rhs: &mut [f64],
    vi: Option<usize>,
    vj: Option<usize>,
    w: f64,
    m: [[f64; 2]; 2],
    fixed: [f64; 2],
    d: [f64; 2],
) {
    // Residual = x_j − M x_i − d; with x_i or x_j fixed, its part joins the constant.
    let mx_fixed = [
        m[0][0] * fixed[0] + m[0][1] * fixed[1],
        m[1][0] * fixed[0] + m[1][1] * fixed[1],
    ];
    match (vi, vj) {
        (Some(i), Some(j)) => {
            // d/dx_j: I; d/dx_i: −M. H_jj = wI, H_ii = w MᵀM = wI, H_ji = −wM.
            for k in 0..2 {
                triplets.push((j + k, j + k, w));
                triplets.push((i + k, i + k, w));
            }
            for (r, m_row) in m.iter().enumerate() {
                for (c, m_rc) in m_row.iter().enumerate() {
                    let (row, col, v) = if j > i {
                        (j + r, i + c, -w * m_rc)
                    } else {
                        (i + c, j + r, -w * m_rc)
                    };
                    triplets.push((row, col, v));
                }
            }
            for k in 0..2 {
                rhs[j + k] += w * d[k];
                rhs[i + k] -= w * (m[0][k] * d[0] + m[1][k] * d[1]);
            }
        }
        (None, Some(j)) => {
            // x_i fixed: residual x_j − (M x_fixed + d).
            for k in 0..2 {
                triplets.push((j + k, j + k, w));
                rhs[j + k] += w * (mx_fixed[k] + d[k]);
            }
        }
        (Some(i), None) => {
            // x_j fixed: residual −M x_i + (x_fixed − d); Mᵀ M = I.
            for k in 0..2 {
                triplets.push((i + k, i + k, w));
                let g = [fixed[0] - d[0], fixed[1] - d[1]];
                rhs[i + k] += w * (m[0][k] * g[0] + m[1][k] * g[1]);
            }
        }
        (None, None) => {}
    }
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
            g.edges.push(RelativeEdge {
                from: i,
                to: j,
                measurement: truth[i].between(&truth[j]),
                information: Matrix3::from_diagonal(&nalgebra::Vector3::new(10.0, 20.0, 100.0)),
                kind: EdgeKind::Odometry,
                robust: Robust::None,
            });
        }
        (g, truth)
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
