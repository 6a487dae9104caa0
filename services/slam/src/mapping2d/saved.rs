//! A mapper saved and restored: its state but the node scans (its owner keeps them, and
//! they are most of its memory), so that a restart continues exactly where the saved mapper
//! stood instead of mapping every node again. Caches are not saved (the pooled submap grids,
//! the optimizers' symbolic factorizations): they are made again on use and change no result.

use super::Mapper2d;
use super::params::Mapper2dParams;
use crate::incremental::GlobalSolver;
use crate::matching::Scan2;
use crate::optimize::Optimizer;
use serde::{Deserialize, Serialize};

/// A saved mapper, read back ([`Mapper2d::saved`] wrote it): [`Self::restore`] gives it its
/// scans.
#[derive(Debug, Deserialize)]
#[serde(transparent)]
pub struct SavedMapper(Mapper2d);

/// Why a saved mapper cannot continue.
#[derive(Debug, Clone, PartialEq)]
pub enum RestoreError {
    /// It was saved with other parameters: continuing would not map as a replay does.
    Params,
    /// Its parts do not agree on the number of nodes, or the scans given do not.
    Nodes(String),
}

impl std::fmt::Display for RestoreError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RestoreError::Params => write!(f, "saved with other mapping parameters"),
            RestoreError::Nodes(what) => write!(f, "saved state does not hold together: {what}"),
        }
    }
}

impl std::error::Error for RestoreError {}

/// Serializes the mapper by reference (no copy of its state).
#[derive(Serialize)]
#[serde(transparent)]
struct Saving<'a>(&'a Mapper2d);

impl Mapper2d {
    /// Its state to save, but the node scans; `None` while a background solve is out (its
    /// job is not part of the state: save after it is given back).
    pub fn saved(&self) -> Option<impl Serialize + '_> {
        self.background.solver.is_some().then_some(Saving(self))
    }
}

impl SavedMapper {
    /// Nodes it holds.
    pub fn nodes(&self) -> usize {
        self.0.graph.poses.len()
    }

    /// The mapper again, with its node scans (in node order, as it was given them). It must
    /// have been saved with `params`.
    pub fn restore(
        self,
        params: &Mapper2dParams,
        scans: Vec<Scan2>,
    ) -> Result<Mapper2d, RestoreError> {
        let mut mapper = self.0;
        if mapper.params != *params {
            return Err(RestoreError::Params);
        }
        let nodes = mapper.graph.poses.len();
        let lengths = [
            ("scans", scans.len()),
            ("robots", mapper.node_robot.len()),
            ("paths", mapper.node_path_m.len()),
            ("stats", mapper.stats.nodes),
        ];
        if let Some((what, n)) = lengths.iter().find(|(_, n)| *n != nodes) {
            return Err(RestoreError::Nodes(format!("{n} {what} for {nodes} nodes")));
        }
        let edges_ok = mapper
            .graph
            .edges
            .iter()
            .all(|e| e.from < nodes && e.to < nodes);
        let gps_ok = mapper.graph.gps.iter().all(|g| g.node < nodes);
        if !edges_ok || !gps_ok {
            return Err(RestoreError::Nodes(
                "an edge names a node it does not hold".into(),
            ));
        }
        mapper.node_scans = scans;
        mapper.optimizer = Optimizer::for_parts();
        mapper.background.solver = Some(GlobalSolver::resumed(
            &mapper.graph,
            &mapper.background.jobs,
        ));
        Ok(mapper)
    }
}
