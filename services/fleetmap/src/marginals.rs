//! Marginal covariances of nodes, answered from a fleet's current view. One optimizer per
//! fleet keeps the network's symbolic factorization while its structure stays the same.

use crate::view::FleetView;
use slam::nalgebra::Matrix3;
use std::collections::HashMap;
use std::sync::Mutex;

/// Per fleet, the optimizer that answers covariance queries.
#[derive(Debug, Default)]
pub struct Marginals {
    optimizers: Mutex<HashMap<String, slam::Optimizer>>,
}

impl Marginals {
    /// The (x, y, θ) covariance of each of `nodes` at the view's poses; `None` for a node
    /// that fixes a gauge (the first node of a part GPS does not anchor). CPU work: call it off the async threads.
    pub fn of(
        &self,
        view: &FleetView,
        nodes: &[usize],
    ) -> Result<Vec<Option<Matrix3<f64>>>, slam::GraphError> {
        let graph = slam::PoseGraph {
            poses: view.poses.to_vec(),
            edges: view.edges.to_vec(),
            gps: view.gps.to_vec(),
        };
        let mut optimizers = self.optimizers.lock().expect("marginals lock");
        // The mapper's parts float until they meet: each has its own gauge.
        let optimizer = optimizers
            .entry(view.id.clone())
            .or_insert_with(slam::Optimizer::for_parts);
        optimizer.marginal_covariances(&graph, nodes)
    }
}
