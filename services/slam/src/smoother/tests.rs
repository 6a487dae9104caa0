use super::eliminate::{linearize_edge, packed};
use super::*;
use crate::network::EdgeKind;
use crate::robust::Robust;
use crate::splitmix::SplitMix;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

fn edge(from: usize, to: usize, measurement: Pose2) -> RelativeEdge {
    RelativeEdge {
        from,
        to,
        measurement,
        information: Matrix3::from_diagonal(&Vector3::new(100.0, 100.0, 400.0)),
        kind: EdgeKind::Odometry,
        robust: Robust::None,
    }
}

/// A walk of `n` nodes on a 4 × 4 m lattice of places (so it comes back often), noisy
/// odometry, and a closure to every earlier visit of the same place seen from within
/// `closures_back` nodes of history or more: `(truth, node by node: first guess and edges)`.
fn lattice_walk(n: usize, seed: u64) -> (Vec<Pose2>, Vec<(Pose2, Vec<RelativeEdge>)>) {
    let mut rng = SplitMix::new(seed);
    let mut truth = vec![Pose2::IDENTITY];
    let mut steps = vec![(Pose2::IDENTITY, Vec::new())];
    let mut guess = Pose2::IDENTITY;
    for k in 1..n {
        let last = truth[k - 1];
        let turn = match (rng.unit() * 4.0) as u32 {
            0 => std::f64::consts::FRAC_PI_2,
            1 => -std::f64::consts::FRAC_PI_2,
            _ => 0.0,
        };
        let mut next = last.compose(&Pose2::new(1.0, 0.0, turn));
        if next.x.abs() > 2.5 || next.y.abs() > 2.5 {
            next = last.compose(&Pose2::new(0.0, 0.0, std::f64::consts::PI));
            next = next.compose(&Pose2::new(1.0, 0.0, 0.0));
        }
        truth.push(next);
        let noise = |rng: &mut SplitMix, s: f64| s * rng.gaussian();
        let step = last.between(&next);
        let odometry = Pose2::new(
            step.x + noise(&mut rng, 0.05),
            step.y + noise(&mut rng, 0.05),
            step.theta + noise(&mut rng, 0.02),
        );
        let mut edges = vec![edge(k - 1, k, odometry)];
        for (j, old) in truth[..k - 1].iter().enumerate() {
            let same_place = (old.x - next.x).hypot(old.y - next.y) < 0.1;
            if same_place && k - j > 3 && rng.unit() < 0.5 {
                let seen = old.between(&next);
                edges.push(edge(
                    j,
                    k,
                    Pose2::new(
                        seen.x + noise(&mut rng, 0.02),
                        seen.y + noise(&mut rng, 0.02),
                        seen.theta + noise(&mut rng, 0.01),
                    ),
                ));
            }
        }
        guess = guess.compose(&odometry);
        steps.push((guess, edges));
    }
    (truth, steps)
}

/// The Gauss-Newton step of all of `edges` at `theta`, node 0 held, by a dense solve.
fn dense_step(theta: &[Pose2], edges: &[RelativeEdge]) -> Vec<Pose2> {
    let dim = 3 * (theta.len() - 1);
    let (mut h, mut g) = (DMatrix::<f64>::zeros(dim, dim), DVector::<f64>::zeros(dim));
    for e in edges {
        let q = linearize_edge(e, theta);
        let (vars, qh, qg) = (q.vars(), q.h(), q.g());
        let k = 3 * vars.len();
        for (a, &va) in vars.iter().enumerate() {
            for r in 0..3 {
                let row = 3 * (va as usize - 1) + r;
                g[row] += qg[3 * a + r];
                for (b, &vb) in vars.iter().enumerate() {
                    for c in 0..3 {
                        let (i, j) = (3 * a + r, 3 * b + c);
                        let (i, j) = (i.min(j), i.max(j));
                        h[(row, 3 * (vb as usize - 1) + c)] += qh[packed(k, i) + j - i];
                    }
                }
            }
        }
    }
    let step = h.cholesky().expect("positive definite").solve(&g);
    let mut out = vec![theta[0]];
    for v in 1..theta.len() {
        let d = [step[3 * v - 3], step[3 * v - 2], step[3 * v - 1]];
        out.push(moved(&theta[v], &d));
    }
    out
}

fn farthest(a: &[Pose2], b: &[Pose2]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            (p.x - q.x)
                .abs()
                .max((p.y - q.y).abs())
                .max(wrap_angle(p.theta - q.theta).abs())
        })
        .fold(0.0, f64::max)
}

#[test]
fn without_relinearizing_every_update_is_the_exact_linear_solve() {
    let params = SmootherParams {
        relinearize_translation: f64::INFINITY,
        relinearize_rotation: f64::INFINITY,
        max_relinearizations: 0,
        wildfire: 0.0,
    };
    for seed in 1..=4 {
        let (_, steps) = lattice_walk(120, seed);
        let mut smoother = IncrementalSmoother::new(params);
        let (mut theta, mut edges) = (Vec::new(), Vec::new());
        let mut closures = 0;
        for (k, (guess, new_edges)) in steps.iter().enumerate() {
            smoother.update(&[*guess], new_edges).expect("update");
            theta.push(*guess);
            edges.extend(new_edges.iter().cloned());
            closures += new_edges.len().saturating_sub(1);
            if k > 0 {
                let off = farthest(&smoother.estimates(), &dense_step(&theta, &edges));
                assert!(off < 1e-9, "seed {seed}, node {k}: {off}");
            }
        }
        assert!(closures > 20, "seed {seed}: only {closures} closures");
    }
}

#[cfg(feature = "solver")]
#[test]
fn every_newest_node_is_the_batch_optimum() {
    use crate::optimize::{OptimizeParams, Optimizer};
    let (truth, steps) = lattice_walk(150, 7);
    let mut smoother = IncrementalSmoother::default();
    let mut graph = crate::network::PoseGraph::default();
    let (mut worst, mut worst_at, mut rounds) = (0.0f64, 0, 0);
    for (k, (guess, new_edges)) in steps.iter().enumerate() {
        rounds += smoother
            .update(&[*guess], new_edges)
            .expect("update")
            .rounds;
        graph.poses.push(*guess);
        graph.edges.extend(new_edges.iter().cloned());
        if k > 0 {
            let mut batch = graph.clone();
            Optimizer::new()
                .optimize(&mut batch, &OptimizeParams::default())
                .expect("batch");
            let off = farthest(&[smoother.estimate(k)], &[batch.poses[k]]);
            if off > worst {
                (worst, worst_at) = (off, k);
            }
        }
    }
    assert!(
        worst < 1e-3,
        "newest node {worst_at} off the batch by {worst}"
    );
    // The lattice's loops bend the odometry far enough that relinearizing is needed.
    assert!(rounds > steps.len() as u32, "{rounds} rounds");
    let estimates = smoother.estimates();
    let truth_error = farthest(&estimates, &truth);
    assert!(truth_error < 0.3, "{truth_error}");
}

#[test]
fn a_closure_to_node_zero_and_several_nodes_at_once() {
    let (_, steps) = lattice_walk(40, 3);
    let mut smoother = IncrementalSmoother::new(SmootherParams {
        relinearize_translation: f64::INFINITY,
        relinearize_rotation: f64::INFINITY,
        max_relinearizations: 0,
        wildfire: 0.0,
    });
    let (mut theta, mut edges) = (Vec::new(), Vec::new());
    for chunk in steps.chunks(7) {
        let guesses: Vec<Pose2> = chunk.iter().map(|s| s.0).collect();
        let new_edges: Vec<RelativeEdge> = chunk.iter().flat_map(|s| s.1.clone()).collect();
        smoother.update(&guesses, &new_edges).expect("update");
        theta.extend(guesses);
        edges.extend(new_edges);
    }
    let back_home = edge(theta.len() - 1, 0, Pose2::new(0.3, -0.2, 0.1));
    smoother
        .update(&[], std::slice::from_ref(&back_home))
        .expect("closure to 0");
    edges.push(back_home);
    let off = farthest(&smoother.estimates(), &dense_step(&theta, &edges));
    assert!(off < 1e-9, "{off}");
}

#[test]
fn updates_that_cannot_be_taken_are_refused_before_any_change() {
    let mut smoother = IncrementalSmoother::default();
    smoother.update(&[Pose2::IDENTITY], &[]).expect("node 0");
    let step = Pose2::new(1.0, 0.0, 0.0);
    assert_eq!(
        smoother.update(&[step], &[]),
        Err(SmootherError::Unlinked(1))
    );
    assert_eq!(
        smoother.update(&[step], &[edge(0, 2, step)]),
        Err(SmootherError::BadEdge {
            from: 0,
            to: 2,
            nodes: 2
        })
    );
    assert_eq!(smoother.len(), 1);
    smoother
        .update(&[step], &[edge(0, 1, step)])
        .expect("linked");
    assert!(farthest(&smoother.estimates(), &[Pose2::IDENTITY, step]) < 1e-12);
}

#[test]
fn a_wildfire_leaves_far_steps_stale_until_solve_all() {
    let (_, steps) = lattice_walk(120, 5);
    let mut smoother = IncrementalSmoother::new(SmootherParams {
        relinearize_translation: f64::INFINITY,
        relinearize_rotation: f64::INFINITY,
        max_relinearizations: 0,
        wildfire: 1.0,
    });
    let (mut theta, mut edges) = (Vec::new(), Vec::new());
    for (guess, new_edges) in &steps {
        smoother.update(&[*guess], new_edges).expect("update");
        theta.push(*guess);
        edges.extend(new_edges.iter().cloned());
    }
    let exact = dense_step(&theta, &edges);
    assert!(farthest(&smoother.estimates(), &exact) > 1e-3);
    smoother.solve_all();
    let off = farthest(&smoother.estimates(), &exact);
    assert!(off < 1e-9, "{off}");
    let shape = smoother.shape();
    assert!(
        shape.depth_max >= 2 && shape.separator_max >= 1,
        "{shape:?}"
    );
}
