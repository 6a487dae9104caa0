//! Local matching: a new scan against its robot's last node, by IDC and then the
//! point-to-line refinement (against that node's scan, or the last few nodes' scans).
//!
//! Every match is held to the quality gate where it puts the scan, against the last node's
//! scan (inlier share, free-space conflicts, residual: `matching::validate`). IDC is local:
//! from a poor guess it can settle in a wrong minimum, and such a match does not fit the
//! last scan where it puts it. Then (and when IDC finds nothing) the scan is searched again by
//! the correlative matcher, which has no local minima, over the odometry's 99.9 % window on
//! a grid of the local map's scans, refined by IDC from the pose it finds, and held to the
//! same gate (`sequential_search`); what still fails leaves the node on odometry.

use super::Mapper2d;
use crate::matching::correlative::{SearchWindow, precompute, search};
use crate::matching::{Match, Prior, Reference, Scan2, accept, idc, refine_against};
use crate::se2::Pose2;

/// The odometry window of the correlative search, in standard deviations of the odometry
/// model: √χ²₃(0.999) = 4.03, a 99.9 % bound on the step's error.
const ODOMETRY_WINDOW_SIGMAS: f64 = 4.03;

impl Mapper2d {
    /// The sequential match of `scan` against node `last`, its robot's last node, from the
    /// odometry `step`: IDC's refined against the local map when it passes the gate, else
    /// (with `sequential_search`) the correlative search's, refined and gated the same way
    /// (see the module's docs). `moved`: the scan makes a node (its match may then be made
    /// wrong on purpose, see `WrongMatches`).
    pub(super) fn sequential_match(
        &mut self,
        last: usize,
        scan: &Scan2,
        step: Pose2,
        moved: bool,
    ) -> Option<Match> {
        let first = self.match_to_node(last, scan, step);
        let first = match first {
            Some(m) if moved => self.made_wrong(last, scan, m),
            first => first,
        };
        if first.is_some() || !self.params.sequential_search {
            return first;
        }
        let found = self.search_local_map(last, scan, step)?;
        let m = self.match_to_node(last, scan, found)?;
        self.stats.sequential_recovered += 1;
        Some(m)
    }

    /// The best pose of `scan` (in node `last`'s frame) on a grid of the local map's scans,
    /// within the odometry's window around `step`.
    fn search_local_map(&self, last: usize, scan: &Scan2, step: Pose2) -> Option<Pose2> {
        let p = &self.params.submaps;
        let references = self.submap(last);
        let grids = precompute(references.iter().map(|r| (r.pose, r.scan)), &p.grid)?;
        let (sigma_xy_m, sigma_theta_rad) = self.odometry_sigmas(&step);
        let window = SearchWindow {
            linear_m: ODOMETRY_WINDOW_SIGMAS * sigma_xy_m,
            angular_rad: ODOMETRY_WINDOW_SIGMAS * sigma_theta_rad,
        };
        search(&grids, scan, step, &window, p.min_score, &p.grid).map(|found| found.pose)
    }

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
