//! A network of two parts that nothing links (two robots that have not met, no GPS): the
//! strict optimizer refuses it, the one for parts solves each part in its own frame, its
//! first node fixed where it was.

use slam::nalgebra::Matrix3;
use slam::{
    EdgeKind, GraphError, OptimizeParams, Optimizer, Pose2, PoseGraph, RelativeEdge, Robust,
};

fn edge(from: usize, to: usize, measurement: Pose2) -> RelativeEdge {
    RelativeEdge {
        from,
        to,
        measurement,
        information: Matrix3::identity(),
        kind: EdgeKind::Odometry,
        robust: Robust::None,
    }
}

/// Two 3-node chains, 1 m steps, a closure on the first; every estimate a little off.
fn two_parts() -> PoseGraph {
    let step = Pose2::new(1.0, 0.0, 0.0);
    PoseGraph {
        poses: vec![
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(1.1, 0.1, 0.05),
            Pose2::new(2.2, -0.1, 0.0),
            Pose2::new(50.0, 20.0, 1.0),
            Pose2::new(50.6, 20.9, 1.1),
            Pose2::new(51.1, 21.7, 0.9),
        ],
        edges: vec![
            edge(0, 1, step),
            edge(1, 2, step),
            edge(0, 2, Pose2::new(2.0, 0.0, 0.0)),
            edge(3, 4, step),
            edge(4, 5, step),
        ],
        gps: Vec::new(),
    }
}

#[test]
fn each_part_is_solved_in_its_own_frame() {
    let mut graph = two_parts();
    assert!(matches!(
        Optimizer::new().optimize(&mut graph.clone(), &OptimizeParams::default()),
        Err(GraphError::Disconnected { .. })
    ));
    assert_eq!(graph.unanchored_part_roots(), vec![0, 3]);
    assert_eq!(graph.component_count(), 2);
    let before = graph.poses.clone();
    Optimizer::for_parts()
        .optimize(&mut graph, &OptimizeParams::default())
        .expect("solved by parts");
    assert_eq!((graph.poses[0], graph.poses[3]), (before[0], before[3]));
    for (from, to) in [(0, 1), (1, 2), (3, 4), (4, 5)] {
        let step = graph.poses[from].between(&graph.poses[to]);
        assert!(
            (step.x - 1.0).abs() < 1e-6 && step.y.abs() < 1e-6 && step.theta.abs() < 1e-6,
            "{from} → {to}: {step:?}"
        );
    }
    let covariances = Optimizer::for_parts()
        .marginal_covariances(&graph, &[0, 3, 5])
        .expect("covariances by parts");
    assert_eq!((covariances[0], covariances[1]), (None, None), "the gauges");
    assert!(covariances[2].is_some());
}
