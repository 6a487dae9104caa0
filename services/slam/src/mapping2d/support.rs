//! Support from the scans for a closure that waits: its older end's neighbours along the
//! chain are matched against its newer end, from the pose the closure predicts. If the closure
//! is right they match there too, and the matches join it as consistent candidates; if it is
//! wrong they match elsewhere or not at all.

use super::Mapper2d;
use crate::matching::{accept, idc};
use crate::se2::Pose2;
use nalgebra::Matrix3;

impl Mapper2d {
    /// Submits a closure; when it waits for support, its older end's neighbours are matched
    /// against its newer end from the pose it predicts, and those matches join the candidates
    /// (support from the scans, where the window has none yet). Returns how many edges that
    /// added.
    pub(super) fn submit_and_verify(
        &mut self,
        from: usize,
        to: usize,
        measurement: Pose2,
        information: Matrix3<f64>,
    ) -> usize {
        let mut added = self.submit_closure(from, to, measurement, information);
        let index = self.candidate_count() - 1;
        let offset = self.params.loop_consistency.support_offset_nodes as isize;
        let (older, newer) = (from.min(to), from.max(to));
        // The closure seen from its older end.
        let seen = if from == older {
            measurement
        } else {
            measurement.inverse()
        };
        for step in [-offset, offset] {
            if offset == 0 || !self.is_pending(index) {
                break;
            }
            let Some(near) = self.chain_neighbour(older, step).filter(|&n| n != newer) else {
                continue;
            };
            let guess = self.graph.poses[near]
                .between(&self.graph.poses[older])
                .compose(&seen);
            let (idc_params, gate) = (&self.params.idc, &self.params.gate);
            let Ok(m) = idc(
                &self.node_scans[near],
                &self.node_scans[newer],
                guess,
                idc_params,
            ) else {
                continue;
            };
            if !accept(&m, gate) {
                continue;
            }
            self.stats.support_matches += 1;
            let information = self.match_information(&m.covariance);
            added += self.submit_closure(near, newer, m.pose, information);
        }
        added
    }
}
