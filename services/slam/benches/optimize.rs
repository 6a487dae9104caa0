//! Speed of the pose-network optimizer on the public benchmarks, from the default chordal
//! start: initialization and optimization separately (what `levelmap optimize` reports as
//! `init_ms` and `solve_ms`), and both with one optimizer (`total_ms`).
//!
//!     cargo bench -p slam --bench optimize
//!
//! Needs ../shared/data beside the repository (or LEVELMAP_DATA); fails loudly without it.
//! Side by side with g2o and GTSAM: scripts/compare-pose-graph.sh.

use graphio::posegraph::{self, GraphFormat};
use slam::{Init, OptimizeParams, Optimizer, PoseGraph, initialize};

fn main() {
    divan::main();
}

const GRAPHS: [&str; 3] = [
    "pose_graph_2d/se-sync/manhattan.g2o",
    "pose_graph_2d/se-sync/city10000.g2o",
    "pose_graph_2d/se-sync/intel.g2o",
];

fn graph(file: &str) -> PoseGraph {
    posegraph::read(&testdata::shared_data(file), GraphFormat::G2o)
        .expect("read")
        .graph
}

/// The chordal initialization (two sparse linear solves).
#[divan::bench(args = GRAPHS, sample_count = 10)]
fn init_chordal(bencher: divan::Bencher, file: &str) {
    let g = graph(file);
    bencher
        .with_inputs(|| g.clone())
        .bench_local_values(|mut g| initialize(&mut g, Init::Chordal).expect("init"));
}

/// The optimization from the chordal start (symbolic factorization included, as in a
/// first solve).
#[divan::bench(args = GRAPHS, sample_count = 10)]
fn solve_from_chordal(bencher: divan::Bencher, file: &str) {
    let mut g = graph(file);
    initialize(&mut g, Init::Chordal).expect("init");
    bencher
        .with_inputs(|| g.clone())
        .bench_local_values(|mut g| {
            Optimizer::new()
                .optimize(&mut g, &OptimizeParams::default())
                .expect("optimize")
        });
}

/// From the file's edges to the optimum: the chordal initialization and the optimization with
/// one optimizer, which orders the network once for both (what `levelmap optimize` reports
/// as `total_ms`, and what is compared with g2o in scripts/compare-pose-graph.sh).
#[divan::bench(args = GRAPHS, sample_count = 10)]
fn to_the_optimum(bencher: divan::Bencher, file: &str) {
    let g = graph(file);
    bencher
        .with_inputs(|| g.clone())
        .bench_local_values(|mut g| {
            let mut optimizer = Optimizer::new();
            optimizer.initialize(&mut g, Init::Chordal).expect("init");
            optimizer
                .optimize(&mut g, &OptimizeParams::default())
                .expect("optimize")
        });
}
