//! The pose network (paper 4.1–4.3): nodes are collection positions, edges are relative pose
//! measurements (odometry, scan matches, loop closures, matches between robots) and absolute
//! GPS positions, each with an information matrix and a robust kernel.

use crate::robust::Robust;
use crate::se2::{Pose2, wrap_angle};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Where a relative edge comes from (maps and reports count edges by kind).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum EdgeKind {
    /// Dead reckoning between successive nodes of one robot.
    Odometry,
    /// A scan match between successive nodes of one robot.
    ScanMatch,
    /// A scan match closing a loop within one robot's chain.
    LoopClosure,
    /// A scan match between nodes of two robots.
    InterRobot,
}

impl EdgeKind {
    /// Every kind, in declaration order.
    pub const ALL: [EdgeKind; 4] = [
        EdgeKind::Odometry,
        EdgeKind::ScanMatch,
        EdgeKind::LoopClosure,
        EdgeKind::InterRobot,
    ];
}

/// A relative pose measurement: pose `to` seen from pose `from`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RelativeEdge {
    /// The node the measurement is seen from.
    pub from: usize,
    /// The node measured.
    pub to: usize,
    /// Pose `to` in the frame of pose `from` (m, rad).
    pub measurement: Pose2,
    /// Information (inverse covariance) of (x, y, θ), in the measurement's frame (g2o's
    /// convention).
    pub information: Matrix3<f64>,
    /// Where it comes from.
    pub kind: EdgeKind,
    /// Its robust kernel.
    pub robust: Robust,
}

/// An absolute position of a GPS antenna in the local east-north frame of the map datum.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GpsEdge {
    /// The node whose antenna was fixed.
    pub node: usize,
    /// Antenna position, east and north of the datum (m).
    pub position_m: Vector2<f64>,
    /// Information of the position (1/m²), east-north.
    pub information: Matrix2<f64>,
    /// Antenna position in the robot frame (m): the lever arm.
    pub lever_arm_m: Vector2<f64>,
    /// Its robust kernel (multipath jumps).
    pub robust: Robust,
}

/// The network: node poses (map frame; east-north when GPS is used) and its edges.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseGraph {
    /// Node poses, by node index (m, rad).
    pub poses: Vec<Pose2>,
    /// Relative measurements between nodes.
    pub edges: Vec<RelativeEdge>,
    /// Absolute GPS positions of nodes' antennas.
    pub gps: Vec<GpsEdge>,
}

/// Why a network cannot be optimized.
#[derive(Clone, Debug, PartialEq)]
pub enum GraphError {
    /// An edge names a node that does not exist.
    MissingNode {
        /// The edge: its index among the relative edges, GPS edges numbered after them.
        edge: usize,
        /// The node it names.
        node: usize,
        /// Nodes in the graph.
        nodes: usize,
    },
    /// An edge's measurement or information has a NaN or infinity.
    NotFinite {
        /// The edge, numbered as in `MissingNode`.
        edge: usize,
    },
    /// An information matrix is not symmetric positive definite.
    NotPositiveDefinite {
        /// The edge, numbered as in `MissingNode`.
        edge: usize,
    },
    /// An edge from a node to itself.
    SelfLoop {
        /// The edge, numbered as in `MissingNode`.
        edge: usize,
    },
    /// Nodes that no chain of relative edges links to node 0 (and no GPS anchors).
    Disconnected {
        /// How many nodes.
        unreachable: usize,
        /// One of them.
        example: usize,
    },
    /// A node pose is not finite.
    BadPose {
        /// The node.
        node: usize,
    },
    /// The linear system could not be solved (numerically singular).
    Singular,
}

impl std::fmt::Display for GraphError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GraphError::MissingNode { edge, node, nodes } => {
                write!(
                    f,
                    "edge {edge} refers to node {node}, but the graph has {nodes} nodes"
                )
            }
            GraphError::NotFinite { edge } => {
                write!(f, "edge {edge} has a value that is not finite")
            }
            GraphError::NotPositiveDefinite { edge } => {
                write!(
                    f,
                    "edge {edge}: information matrix is not symmetric positive definite"
                )
            }
            GraphError::SelfLoop { edge } => write!(f, "edge {edge} links a node to itself"),
            GraphError::Disconnected {
                unreachable,
                example,
            } => write!(
                f,
                "graph is disconnected: {unreachable} nodes (e.g. node {example}) have no path of edges to node 0"
            ),
            GraphError::BadPose { node } => write!(f, "node {node} has a pose that is not finite"),
            GraphError::Singular => write!(f, "the normal equations are singular"),
        }
    }
}

impl std::error::Error for GraphError {}

/// Index of an edge in [`GraphError`]s for GPS edges: they follow the relative edges.
fn gps_edge_index(graph: &PoseGraph, k: usize) -> usize {
    graph.edges.len() + k
}

/// True when `m` is finite, symmetric (to rounding) and positive definite.
pub fn is_information<const D: usize>(m: &nalgebra::SMatrix<f64, D, D>) -> bool {
    let scale = m
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    m.iter().all(|v| v.is_finite())
        && (0..D).all(|i| (0..D).all(|j| (m[(i, j)] - m[(j, i)]).abs() <= 1e-9 * scale))
        && m.cholesky().is_some()
}

impl PoseGraph {
    /// Checks node references, finiteness, information matrices and connectivity.
    pub fn validate(&self) -> Result<(), GraphError> {
        self.validate_parts()?;
        self.check_connected()
    }

    /// [`PoseGraph::validate`] without the connectivity check: for a network whose parts
    /// may float, each with its own gauge ([`PoseGraph::unanchored_part_roots`]).
    pub fn validate_parts(&self) -> Result<(), GraphError> {
        let n = self.poses.len();
        if let Some(node) = self.poses.iter().position(|p| !p.is_finite()) {
            return Err(GraphError::BadPose { node });
        }
        for (k, e) in self.edges.iter().enumerate() {
            for node in [e.from, e.to] {
                if node >= n {
                    return Err(GraphError::MissingNode {
                        edge: k,
                        node,
                        nodes: n,
                    });
                }
            }
            if e.from == e.to {
                return Err(GraphError::SelfLoop { edge: k });
            }
            if !e.measurement.is_finite() || e.information.iter().any(|v| !v.is_finite()) {
                return Err(GraphError::NotFinite { edge: k });
            }
            if !is_information(&e.information) {
                return Err(GraphError::NotPositiveDefinite { edge: k });
            }
        }
        for (k, g) in self.gps.iter().enumerate() {
            let edge = gps_edge_index(self, k);
            if g.node >= n {
                return Err(GraphError::MissingNode {
                    edge,
                    node: g.node,
                    nodes: n,
                });
            }
            if g.position_m
                .iter()
                .chain(g.lever_arm_m.iter())
                .chain(g.information.iter())
                .any(|v| !v.is_finite())
            {
                return Err(GraphError::NotFinite { edge });
            }
            if !is_information(&g.information) {
                return Err(GraphError::NotPositiveDefinite { edge });
            }
        }
        Ok(())
    }

    /// Every node must be linked to node 0 by relative edges, unless GPS fixes anchor the map
    /// (then every connected part needs at least two fixes at distinct nodes).
    fn check_connected(&self) -> Result<(), GraphError> {
        let n = self.poses.len();
        let components = self.components();
        let unreachable: Vec<usize> = (0..n).filter(|&i| components[i] != components[0]).collect();
        if unreachable.is_empty() {
            return Ok(());
        }
        // With GPS, each component must hold fixes on two different nodes (position and
        // orientation); otherwise it floats.
        let anchored = self.gps_anchored_parts(&components);
        let floating: Vec<usize> = unreachable
            .into_iter()
            .filter(|&i| !anchored[components[i]])
            .collect();
        match floating.first() {
            None => Ok(()),
            Some(&example) => Err(GraphError::Disconnected {
                unreachable: floating.len(),
                example,
            }),
        }
    }

    /// Connected-component label of every node, through relative edges.
    pub fn components(&self) -> Vec<usize> {
        let n = self.poses.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        for e in &self.edges {
            let (a, b) = (find(&mut parent, e.from), find(&mut parent, e.to));
            parent[a.max(b)] = a.min(b);
        }
        (0..n).map(|i| find(&mut parent, i)).collect()
    }

    /// The first node of every connected part that GPS fixes at two or more distinct nodes
    /// do not anchor, in order: where each such part's gauge is fixed when parts may float.
    pub fn unanchored_part_roots(&self) -> Vec<usize> {
        let components = self.components();
        let anchored = self.gps_anchored_parts(&components);
        (0..self.poses.len())
            .filter(|&i| components[i] == i && !anchored[i])
            .collect()
    }

    /// Whether GPS fixes anchor each connected part (`components`' labels, indexed by
    /// label): fixes at two or more distinct nodes of it. One pass without hashing: the
    /// mapper asks at every node, over every fix of the map.
    fn gps_anchored_parts(&self, components: &[usize]) -> Vec<bool> {
        let n = self.poses.len();
        let (mut first_fixed, mut anchored) = (vec![usize::MAX; n], vec![false; n]);
        for g in &self.gps {
            let part = components[g.node];
            if anchored[part] {
                continue;
            }
            if first_fixed[part] == usize::MAX {
                first_fixed[part] = g.node;
            } else if first_fixed[part] != g.node {
                anchored[part] = true;
            }
        }
        anchored
    }

    /// How many connected parts the relative edges make (GPS edges link nothing).
    pub fn component_count(&self) -> usize {
        let labels = self.components();
        labels.iter().enumerate().filter(|&(i, &c)| i == c).count()
    }

    /// Σ eᵀΩe over all edges, without robust kernels (g2o's convention for relative edges).
    pub fn chi2(&self) -> f64 {
        self.edges.iter().map(|e| e.chi2(&self.poses)).sum::<f64>()
            + self.gps.iter().map(|g| g.chi2(&self.poses)).sum::<f64>()
    }
}

impl RelativeEdge {
    /// g2o's EdgeSE2 error `[R_zᵀ(R_iᵀ(t_j − t_i) − t_z) ; wrap(θ_j − θ_i − θ_z)]`.
    pub fn error(&self, poses: &[Pose2]) -> Vector3<f64> {
        let (pi, pj, z) = (&poses[self.from], &poses[self.to], &self.measurement);
        let (si, ci) = pi.theta.sin_cos();
        let (sz, cz) = z.theta.sin_cos();
        let (dx, dy) = (pj.x - pi.x, pj.y - pi.y);
        let (ax, ay) = (ci * dx + si * dy - z.x, -si * dx + ci * dy - z.y);
        Vector3::new(
            cz * ax + sz * ay,
            -sz * ax + cz * ay,
            wrap_angle(pj.theta - pi.theta - z.theta),
        )
    }

    /// The error and its Jacobians with respect to (x, y, θ) of `from` and of `to`.
    pub fn linearize(&self, poses: &[Pose2]) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
        let (pi, pj, z) = (&poses[self.from], &poses[self.to], &self.measurement);
        let (si, ci) = pi.theta.sin_cos();
        let (sz, cz) = z.theta.sin_cos();
        let (dx, dy) = (pj.x - pi.x, pj.y - pi.y);
        let (ax, ay) = (ci * dx + si * dy - z.x, -si * dx + ci * dy - z.y);
        let e = Vector3::new(
            cz * ax + sz * ay,
            -sz * ax + cz * ay,
            wrap_angle(pj.theta - pi.theta - z.theta),
        );
        // A = R_zᵀ R_iᵀ; d(R_iᵀ d)/dθ_i = (−s dx + c dy, −c dx − s dy).
        let (a11, a12) = (cz * ci - sz * si, cz * si + sz * ci);
        let (a21, a22) = (-sz * ci - cz * si, -sz * si + cz * ci);
        let (gx, gy) = (-si * dx + ci * dy, -ci * dx - si * dy);
        let (h1, h2) = (cz * gx + sz * gy, -sz * gx + cz * gy);
        let jj = Matrix3::new(a11, a12, 0.0, a21, a22, 0.0, 0.0, 0.0, 1.0);
        let ji = Matrix3::new(-a11, -a12, h1, -a21, -a22, h2, 0.0, 0.0, -1.0);
        (e, ji, jj)
    }

    /// The squared Mahalanobis error eᵀΩe at `poses` (unitless).
    pub fn chi2(&self, poses: &[Pose2]) -> f64 {
        let e = self.error(poses);
        e.dot(&(self.information * e))
    }
}

impl GpsEdge {
    /// The edge for a WGS84 fix of node `node`'s antenna: its position in the datum's
    /// east-north frame (exact, through ECEF) and the information of its east-north
    /// covariance (m²). `None` when the covariance is not positive definite or a value is not
    /// finite.
    pub fn from_fix(
        datum: &crate::geodesy::GeoDatum,
        node: usize,
        fix: &crate::geodesy::Geodetic,
        covariance_en_m2: Matrix2<f64>,
        lever_arm_m: Vector2<f64>,
        robust: Robust,
    ) -> Option<GpsEdge> {
        let enu = datum.geodetic_to_enu(fix);
        let information = covariance_en_m2.try_inverse()?;
        let edge = GpsEdge {
            node,
            position_m: Vector2::new(enu.x, enu.y),
            information,
            lever_arm_m,
            robust,
        };
        (edge.position_m.iter().all(|v| v.is_finite()) && is_information(&edge.information))
            .then_some(edge)
    }

    /// Antenna position predicted by the node pose, minus the fix (m).
    pub fn error(&self, poses: &[Pose2]) -> Vector2<f64> {
        self.error_at(&poses[self.node])
    }

    /// [`Self::error`] with the node at pose `p`.
    pub fn error_at(&self, p: &Pose2) -> Vector2<f64> {
        let a = p.transform_point([self.lever_arm_m.x, self.lever_arm_m.y]);
        Vector2::new(a[0] - self.position_m.x, a[1] - self.position_m.y)
    }

    /// The error and its Jacobian with respect to (x, y, θ) of the node.
    pub fn linearize(&self, poses: &[Pose2]) -> (Vector2<f64>, nalgebra::Matrix2x3<f64>) {
        let p = &poses[self.node];
        let (s, c) = p.theta.sin_cos();
        let (lx, ly) = (self.lever_arm_m.x, self.lever_arm_m.y);
        let j = nalgebra::Matrix2x3::new(1.0, 0.0, -s * lx - c * ly, 0.0, 1.0, c * lx - s * ly);
        (self.error(poses), j)
    }

    /// The squared Mahalanobis error eᵀΩe at `poses` (unitless).
    pub fn chi2(&self, poses: &[Pose2]) -> f64 {
        let e = self.error(poses);
        e.dot(&(self.information * e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(from: usize, to: usize, z: Pose2, info: Matrix3<f64>) -> RelativeEdge {
        RelativeEdge {
            from,
            to,
            measurement: z,
            information: info,
            kind: EdgeKind::Odometry,
            robust: Robust::None,
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let poses = vec![Pose2::new(1.0, 2.0, 0.4), Pose2::new(3.5, 1.2, -2.6)];
        let e = edge(0, 1, Pose2::new(2.0, -0.5, 3.0), Matrix3::identity());
        let (_, ji, jj) = e.linearize(&poses);
        let h = 1e-7;
        for (node, jac) in [(0, ji), (1, jj)] {
            for d in 0..3 {
                let mut plus = poses.clone();
                let mut minus = poses.clone();
                let bump = |p: &mut Pose2, v: f64| match d {
                    0 => p.x += v,
                    1 => p.y += v,
                    _ => p.theta += v,
                };
                bump(&mut plus[node], h);
                bump(&mut minus[node], -h);
                let mut diff = e.error(&plus) - e.error(&minus);
                diff[2] = wrap_angle(diff[2]);
                let numeric = diff / (2.0 * h);
                for r in 0..3 {
                    assert!(
                        (numeric[r] - jac[(r, d)]).abs() < 1e-6,
                        "node {node} d{d} row {r}: {numeric} vs {jac}"
                    );
                }
            }
        }
    }

    #[test]
    fn gps_jacobian_matches_finite_differences() {
        let poses = vec![Pose2::new(1.0, 2.0, 0.9)];
        let g = GpsEdge {
            node: 0,
            position_m: Vector2::new(0.0, 0.0),
            information: Matrix2::identity(),
            lever_arm_m: Vector2::new(0.4, -0.2),
            robust: Robust::None,
        };
        let (_, j) = g.linearize(&poses);
        let h = 1e-7;
        let mut plus = poses.clone();
        plus[0].theta += h;
        let mut minus = poses.clone();
        minus[0].theta -= h;
        let numeric = (g.error(&plus) - g.error(&minus)) / (2.0 * h);
        assert!((numeric - j.column(2)).norm() < 1e-6);
    }

    #[test]
    fn gps_edge_from_a_wgs84_fix() {
        let datum = crate::geodesy::GeoDatum {
            origin: crate::geodesy::Geodetic {
                latitude_deg: 52.39,
                longitude_deg: 9.71,
                height_m: 55.0,
            },
        };
        let fix = datum.enu_to_geodetic(&nalgebra::Vector3::new(12.0, -7.0, 0.0));
        let e = GpsEdge::from_fix(
            &datum,
            0,
            &fix,
            Matrix2::identity() * 0.25,
            Vector2::zeros(),
            Robust::None,
        )
        .unwrap();
        assert!((e.position_m - Vector2::new(12.0, -7.0)).norm() < 1e-6);
        assert!((e.information[(0, 0)] - 4.0).abs() < 1e-12);
        assert!(
            GpsEdge::from_fix(
                &datum,
                0,
                &fix,
                -Matrix2::identity(),
                Vector2::zeros(),
                Robust::None
            )
            .is_none()
        );
    }

    #[test]
    fn validation_names_the_problem() {
        let mut g = PoseGraph {
            poses: vec![Pose2::IDENTITY; 3],
            ..Default::default()
        };
        g.edges
            .push(edge(0, 1, Pose2::new(1.0, 0.0, 0.0), Matrix3::identity()));
        assert_eq!(
            g.validate(),
            Err(GraphError::Disconnected {
                unreachable: 1,
                example: 2
            })
        );
        g.edges
            .push(edge(1, 5, Pose2::IDENTITY, Matrix3::identity()));
        assert_eq!(
            g.validate(),
            Err(GraphError::MissingNode {
                edge: 1,
                node: 5,
                nodes: 3
            })
        );
        g.edges[1] = edge(1, 2, Pose2::IDENTITY, -Matrix3::identity());
        assert_eq!(
            g.validate(),
            Err(GraphError::NotPositiveDefinite { edge: 1 })
        );
        g.edges[1] = edge(1, 2, Pose2::new(f64::NAN, 0.0, 0.0), Matrix3::identity());
        assert_eq!(g.validate(), Err(GraphError::NotFinite { edge: 1 }));
        g.edges[1] = edge(1, 2, Pose2::IDENTITY, Matrix3::identity());
        assert_eq!(g.validate(), Ok(()));
    }
}
