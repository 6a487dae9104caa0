//! GPS constraints with multipath jumps (simulated park run with ground truth): the robust
//! kernel keeps the trajectory within the GPS noise, while plain least squares is pulled off
//! towards the jumps.

use slam::nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use slam::{
    EdgeKind, GpsEdge, Init, OptimizeParams, Optimizer, Pose2, PoseGraph, RelativeEdge, Robust,
    initialize,
};

/// A lap of the park: one node per GPS period, noisy odometry between them, GPS fixes with
/// the simulator's dropouts and multipath episodes. Returns the graph, the true poses, and
/// which nodes have a multipath fix.
fn park_run(gps_robust: Robust) -> (PoseGraph, Vec<Pose2>, Vec<bool>) {
    let world = sim::World::park();
    let route = sim::Route::park_loop(0).expect("loop 0");
    let truth = route.truth(&world);
    let lap_ns = route.lap_ns().expect("closed loop");
    let gps = sim::Gps {
        multipath_probability: 0.06,
        // In the plane of the robot, so that the 2D network models it exactly.
        antenna_in_robot_m: Vector3::new(0.3, 0.0, 0.0),
        ..Default::default()
    };
    let mut rng = sim::Rng::new(42);
    let fixes = gps.fixes(&truth, 0, lap_ns, &mut rng);
    let planar = |t: u64| Pose2::from_isometry3(&truth(t));
    let stamps: Vec<u64> = (0..=lap_ns / gps.period_ns)
        .map(|k| k * gps.period_ns)
        .collect();
    let true_poses: Vec<Pose2> = stamps.iter().map(|&t| planar(t)).collect();

    let mut graph = PoseGraph {
        poses: vec![Pose2::IDENTITY; stamps.len()],
        ..Default::default()
    };
    let (sigma_xy, sigma_theta) = (0.03, 0.4f64.to_radians());
    for k in 0..stamps.len() - 1 {
        let z = true_poses[k].between(&true_poses[k + 1]);
        let noisy = Pose2::new(
            z.x + sigma_xy * rng.normal() + 0.01, // a small bias: odometry alone drifts
            z.y + sigma_xy * rng.normal(),
            z.theta + sigma_theta * rng.normal(),
        );
        graph.edges.push(RelativeEdge {
            from: k,
            to: k + 1,
            measurement: noisy,
            information: Matrix3::from_diagonal(&Vector3::new(
                1.0 / (sigma_xy * sigma_xy),
                1.0 / (sigma_xy * sigma_xy),
                1.0 / (sigma_theta * sigma_theta),
            )),
            kind: EdgeKind::Odometry,
            robust: Robust::None,
        });
    }
    let mut multipath = vec![false; stamps.len()];
    for fix in &fixes {
        let node = (fix.stamp_ns / gps.period_ns) as usize;
        multipath[node] |= fix.multipath;
        graph.gps.push(GpsEdge {
            node,
            position_m: Vector2::new(fix.enu_m.x, fix.enu_m.y),
            information: Matrix2::identity() / (fix.sigma_horizontal_m * fix.sigma_horizontal_m),
            lever_arm_m: Vector2::new(0.3, 0.0),
            robust: gps_robust,
        });
    }
    (graph, true_poses, multipath)
}

/// Position errors (m) after optimizing with the given GPS kernel.
fn errors(gps_robust: Robust) -> (Vec<f64>, Vec<bool>) {
    let (mut graph, truth, multipath) = park_run(gps_robust);
    assert!(
        multipath.iter().filter(|m| **m).count() >= 5,
        "the run needs multipath episodes"
    );
    initialize(&mut graph, Init::Odometry).expect("initialize");
    Optimizer::new()
        .optimize(&mut graph, &OptimizeParams::default())
        .expect("optimize");
    let e = graph
        .poses
        .iter()
        .zip(&truth)
        .map(|(p, t)| (p.x - t.x).hypot(p.y - t.y))
        .collect();
    (e, multipath)
}

fn rmse(e: &[f64]) -> f64 {
    (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
}

#[test]
fn robust_kernel_ignores_multipath_that_pulls_least_squares_off() {
    let (plain, multipath) = errors(Robust::None);
    let (robust, _) = errors(Robust::Cauchy { c: 2.0 });
    let at_jumps = |e: &[f64]| {
        e.iter()
            .zip(&multipath)
            .filter(|(_, m)| **m)
            .map(|(v, _)| *v)
            .fold(0.0, f64::max)
    };
    println!(
        "rmse: plain {:.3} m, robust {:.3} m; worst at multipath nodes: plain {:.3} m, robust {:.3} m ({} multipath nodes of {})",
        rmse(&plain),
        rmse(&robust),
        at_jumps(&plain),
        at_jumps(&robust),
        multipath.iter().filter(|m| **m).count(),
        multipath.len()
    );
    // Within the GPS noise (σ 0.5 m per axis) with the kernel; pulled off without it.
    assert!(rmse(&robust) < 0.3, "robust rmse {}", rmse(&robust));
    assert!(
        at_jumps(&robust) < 0.6,
        "robust worst at jumps {}",
        at_jumps(&robust)
    );
    assert!(
        at_jumps(&plain) > 1.0,
        "plain least squares should be pulled off: {}",
        at_jumps(&plain)
    );
    assert!(at_jumps(&plain) > 2.0 * at_jumps(&robust));
}
