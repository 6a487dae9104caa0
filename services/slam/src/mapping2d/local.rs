//! Local matching: a new scan against its robot's last node, by IDC and then the
//! point-to-line refinement (against that node's scan, or the last few nodes' scans).

use super::Mapper2d;
use crate::matching::{Match, Prior, Reference, Scan2, accept, idc, refine_against};
use crate::se2::Pose2;

impl Mapper2d {
    /// The match of `scan` against node `last` from `guess` (the scan's frame in the node's
    /// frame) when the gate accepts it: IDC's, refined when refinement is on and the
    /// refined match passes the gate too.
    pub(super) fn match_to_node(&self, last: usize, scan: &Scan2, guess: Pose2) -> Option<Match> {
        let p = &self.params;
        let m = idc(&self.node_scans[last], scan, guess, &p.idc)
            .ok()
            .filter(|m| accept(m, &p.gate))?;
        if !p.refine.enabled {
            return Some(m);
        }
        let references = self.submap(last);
        // The guess is odometry: with `odometry_prior` it holds the directions the scans
        // leave open.
        let prior = p.refine.odometry_prior.then(|| Prior {
            pose: guess,
            information: self.odometry_information(&guess),
        });
        refine_against(&references, scan, &m, prior.as_ref(), &p.idc, &p.refine)
            .ok()
            .filter(|r| accept(r, &p.gate))
            .or(Some(m))
    }

    /// Node `last`'s scan and those of the `submap_extra_nodes` nodes before it on its
    /// robot's chain, at their current estimates in `last`'s frame.
    fn submap(&self, last: usize) -> Vec<Reference<'_>> {
        let here = self.graph.poses[last];
        let extra = self.params.refine.submap_extra_nodes as isize;
        let earlier = (1..=extra).map_while(|k| self.chain_neighbour(last, -k));
        std::iter::once(last)
            .chain(earlier)
            .map(|j| Reference {
                scan: &self.node_scans[j],
                pose: here.between(&self.graph.poses[j]),
            })
            .collect()
    }
}
