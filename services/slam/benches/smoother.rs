//! Speed of the incremental smoother: a whole graph replayed node by node, each node an
//! update with the edges it brings (what `levelmap bench-incremental --solver bayes-tree`
//! times one update at a time, with its checks against batch solves).
//!
//!     cargo bench -p slam --bench smoother
//!
//! Needs ../shared/data beside the repository (or LEVELMAP_DATA); fails loudly without it.
//! Side by side with GTSAM's ISAM2: scripts/isam2-replay.py.

use graphio::posegraph::{self, GraphFormat};
use slam::{IncrementalSmoother, PoseGraph, RelativeEdge, SmootherParams};

fn main() {
    divan::main();
}

const GRAPHS: [&str; 2] = [
    "pose_graph_2d/se-sync/intel.g2o",
    "pose_graph_2d/se-sync/manhattan.g2o",
];

/// The graph and, for each node, the edges whose later node it is.
fn replay_of(file: &str) -> (PoseGraph, Vec<Vec<RelativeEdge>>) {
    let graph = posegraph::read(&testdata::shared_data(file), GraphFormat::G2o)
        .expect("read")
        .graph;
    let mut brought = vec![Vec::new(); graph.poses.len()];
    for e in &graph.edges {
        brought[e.from.max(e.to)].push(e.clone());
    }
    (graph, brought)
}

/// Every node placed from an earlier node through its edge, then the update.
#[divan::bench(args = GRAPHS, sample_count = 5)]
fn replay(bencher: divan::Bencher, file: &str) {
    let (graph, brought) = replay_of(file);
    bencher.bench_local(|| {
        let mut smoother = IncrementalSmoother::new(SmootherParams::default());
        smoother.update(&[graph.poses[0]], &[]).expect("node 0");
        for (i, edges) in brought.iter().enumerate().skip(1) {
            let e = edges
                .iter()
                .find(|e| e.to == i && e.from < i)
                .expect("an edge from an earlier node");
            let guess = smoother.estimate(e.from).compose(&e.measurement);
            smoother.update(&[guess], edges).expect("update");
        }
        smoother
    });
}
