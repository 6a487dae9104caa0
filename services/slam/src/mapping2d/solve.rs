//! When the network is optimized: at once, or deferred to the caller, and never while a
//! part of it is not anchored yet.

use super::Mapper2d;
use crate::network::GraphError;
use crate::optimize::OptimizeReport;

impl Mapper2d {
    /// Optimizes now, or marks it pending with `defer_optimization`.
    pub(super) fn optimize_when_anchored(&mut self) -> Result<(), GraphError> {
        if self.params.defer_optimization {
            self.optimization_pending = true;
            return Ok(());
        }
        self.optimize_anchored().map(drop)
    }

    /// Runs the optimization that scans added since the last one called for (with
    /// `defer_optimization`); returns whether one ran.
    pub fn optimize_pending(&mut self) -> Result<bool, GraphError> {
        if !std::mem::take(&mut self.optimization_pending) {
            return Ok(false);
        }
        self.optimize_anchored()
    }

    /// Optimizes now, pending or not, unless a part of the network is not anchored yet;
    /// returns whether it ran.
    pub fn optimize_now(&mut self) -> Result<bool, GraphError> {
        self.optimization_pending = false;
        self.optimize_anchored()
    }

    /// Optimizes unless a part of the network is not anchored yet; returns whether it ran.
    fn optimize_anchored(&mut self) -> Result<bool, GraphError> {
        match self.optimize() {
            Ok(_) => Ok(true),
            Err(GraphError::Disconnected { .. } | GraphError::Singular) => {
                self.stats.deferred_optimizations += 1;
                Ok(false)
            }
            Err(e) => Err(e),
        }
    }

    /// Optimizes the whole network now and records the report.
    pub(super) fn optimize(&mut self) -> Result<OptimizeReport, GraphError> {
        let report = self
            .optimizer
            .optimize(&mut self.graph, &self.params.optimize)?;
        self.stats.optimizations += 1;
        self.last_optimization = Some(report);
        Ok(report)
    }
}
