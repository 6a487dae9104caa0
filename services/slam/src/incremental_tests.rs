use super::*;
use crate::network::EdgeKind;
use crate::robust::Robust;
use nalgebra::Matrix3;

fn edge(from: usize, to: usize, measurement: Pose2) -> RelativeEdge {
    RelativeEdge {
        from,
        to,
        measurement,
        information: Matrix3::from_diagonal(&nalgebra::Vector3::new(100.0, 100.0, 400.0)),
        kind: EdgeKind::Odometry,
        robust: Robust::None,
    }
}

/// A square loop of `n` nodes (steps of 1 m, turning 90° every `n / 4`), odometry with a
/// bias in heading, and a closure from the last node back to the first.
fn square(n: usize) -> (PoseGraph, Vec<RelativeEdge>) {
    let side = n / 4;
    let mut truth = vec![Pose2::IDENTITY];
    for k in 1..n {
        let turn = if k % side == 0 {
            std::f64::consts::FRAC_PI_2
        } else {
            0.0
        };
        let last = truth[k - 1];
        truth.push(last.compose(&Pose2::new(1.0, 0.0, turn)));
    }
    let mut graph = PoseGraph {
        poses: vec![Pose2::IDENTITY],
        ..PoseGraph::default()
    };
    let mut edges = Vec::new();
    for k in 1..n {
        let step = truth[k - 1].between(&truth[k]);
        let biased = Pose2::new(step.x, step.y, step.theta + 0.01);
        edges.push(edge(k - 1, k, biased));
    }
    edges.push(edge(n - 1, 0, truth[n - 1].between(&truth[0])));
    for e in &edges[..n - 1] {
        let pose = graph.poses[e.from].compose(&e.measurement);
        graph.poses.push(pose);
        graph.edges.push(e.clone());
    }
    (graph, edges)
}

fn far(a: &[Pose2], b: &[Pose2]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p.x - q.x).hypot(p.y - q.y) + (p.theta - q.theta).abs())
        .fold(0.0, f64::max)
}

/// Solves the window of `variables`, the rest of `graph` held.
fn window(graph: &mut PoseGraph, variables: std::ops::Range<usize>) {
    let mut adjacency = Adjacency::default();
    adjacency.sync(graph);
    let variables: Vec<usize> = variables.collect();
    solve_window(graph, &adjacency, &variables, &OptimizeParams::default()).expect("window");
}

#[test]
fn a_window_of_every_node_but_the_first_is_the_full_solve() {
    let (mut graph, edges) = square(40);
    graph.edges.push(edges[39].clone());
    let mut full = graph.clone();
    Optimizer::new()
        .optimize(&mut full, &OptimizeParams::default())
        .expect("full");
    window(&mut graph, 1..40);
    assert!(far(&graph.poses, &full.poses) < 1e-9);
}

#[test]
fn a_window_moves_only_its_variables_and_pulls_them_toward_the_closure() {
    let (mut graph, edges) = square(40);
    graph.edges.push(edges[39].clone());
    let before = graph.clone();
    window(&mut graph, 30..40);
    assert_eq!(graph.poses[..30], before.poses[..30], "held");
    let closure = &graph.edges[39];
    assert!(closure.chi2(&graph.poses) < 0.01 * closure.chi2(&before.poses));
}

#[test]
fn a_background_solve_applied_late_carries_the_nodes_added_meanwhile() {
    let (mut graph, edges) = square(40);
    let params = OptimizeParams::default();
    let mut source = JobSource::default();
    let mut solver = GlobalSolver::default();
    // The closure arrives; the job is made; two more nodes of the chain arrive before the
    // result does.
    graph.edges.push(edges[39].clone());
    let job = source.job(&graph, &params);
    assert_eq!(job.nodes(), 40);
    for k in 40..42 {
        let step = Pose2::new(1.0, 0.0, 0.0);
        graph.poses.push(graph.poses[k - 1].compose(&step));
        graph.edges.push(edge(k - 1, k, step));
    }
    let result = solver.solve(job);
    let mut batch = PoseGraph {
        poses: graph.poses[..40].to_vec(),
        edges: graph.edges[..40].to_vec(),
        gps: Vec::new(),
    };
    Optimizer::for_parts()
        .optimize(&mut batch, &params)
        .expect("batch");
    apply_solve(&mut graph, &result, |_| 0).expect("applied");
    assert!(far(&graph.poses[..40], &batch.poses) < 1e-9);
    // The new nodes kept their steps from the last solved node.
    for k in 40..42 {
        let step = graph.poses[k - 1].between(&graph.poses[k]);
        assert!(
            far(&[step], &[Pose2::new(1.0, 0.0, 0.0)]) < 1e-9,
            "{step:?}"
        );
    }
    // The next job brings only what is new, and the solver ends where a batch solve does.
    let result = solver.solve(source.job(&graph, &params));
    apply_solve(&mut graph, &result, |_| 0).expect("applied");
    let mut batch = graph.clone();
    Optimizer::for_parts()
        .optimize(&mut batch, &params)
        .expect("batch");
    assert!(far(&graph.poses, &batch.poses) < 1e-6);
}

#[test]
fn a_failed_background_solve_moves_nothing() {
    // Two parts without GPS, and a gauge that holds no node of one of them.
    let mut graph = PoseGraph {
        poses: vec![Pose2::IDENTITY; 3],
        edges: vec![edge(0, 1, Pose2::new(1.0, 0.0, 0.0))],
        gps: Vec::new(),
    };
    let result = SolveResult {
        started: graph.poses.clone(),
        outcome: Err(GraphError::Singular),
    };
    let before = graph.clone();
    assert_eq!(
        apply_solve(&mut graph, &result, |_| 0),
        Err(GraphError::Singular)
    );
    assert_eq!(graph, before);
    graph.poses[2] = Pose2::new(5.0, 0.0, 0.0);
    let before = graph.clone();
    let mut adjacency = Adjacency::default();
    adjacency.sync(&graph);
    // Node 2 is linked to nothing held: the window would float.
    let got = solve_window(&mut graph, &adjacency, &[2], &OptimizeParams::default());
    assert_eq!(got, Err(GraphError::Singular));
    assert_eq!(graph, before);
}
