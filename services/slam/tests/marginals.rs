//! Marginal covariances of a pose chain, against the values worked out by hand: along a
//! straight chain from the fixed first node, x and θ variances add per edge, and y also
//! collects each earlier heading error times its lever arm.

use slam::nalgebra::Matrix3;
use slam::{EdgeKind, Optimizer, Pose2, PoseGraph, RelativeEdge, Robust};

/// Nodes 1 m apart along x, unit information on every odometry edge.
fn chain(nodes: usize) -> PoseGraph {
    PoseGraph {
        poses: (0..nodes).map(|k| Pose2::new(k as f64, 0.0, 0.0)).collect(),
        edges: (0..nodes - 1)
            .map(|k| RelativeEdge {
                from: k,
                to: k + 1,
                measurement: Pose2::new(1.0, 0.0, 0.0),
                information: Matrix3::identity(),
                kind: EdgeKind::Odometry,
                robust: Robust::None,
            })
            .collect(),
        gps: Vec::new(),
    }
}

#[test]
fn a_straight_chain_has_the_hand_worked_covariances() {
    let graph = chain(4);
    let mut optimizer = Optimizer::new();
    let covs = optimizer
        .marginal_covariances(&graph, &[2, 0, 1, 3])
        .expect("covariances");
    assert_eq!(covs[1], None, "node 0 fixes the gauge");
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    // Node k (k edges from the fixed node): var x = k, var θ = k; the heading error of
    // edge j (0 < j < k) swings node k by its lever arm k − j:
    // var y = k + Σ (k − j)², cov(y, θ) = Σ (k − j).
    for (k, cov) in [(2usize, covs[0]), (1, covs[2]), (3, covs[3])] {
        let c = cov.expect("solved node");
        let kf = k as f64;
        let lever: f64 = (1..k).map(|j| (k - j) as f64).sum();
        let lever2: f64 = (1..k).map(|j| ((k - j) as f64).powi(2)).sum();
        assert!(close(c[(0, 0)], kf), "node {k}: {c}");
        assert!(close(c[(2, 2)], kf), "node {k}: {c}");
        assert!(close(c[(1, 1)], kf + lever2), "node {k}: {c}");
        assert!(
            close(c[(1, 2)], lever) && close(c[(2, 1)], lever),
            "node {k}: {c}"
        );
        assert!(
            close(c[(0, 1)], 0.0) && close(c[(0, 2)], 0.0),
            "node {k}: {c}"
        );
    }
    // One node at a time gives the same.
    let one = optimizer.marginal_covariance(&graph, 3).unwrap().unwrap();
    assert!((one - covs[3].unwrap()).abs().max() < 1e-12);
}
