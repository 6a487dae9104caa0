//! Loop closure by correlative search against submaps, for when IDC from the current
//! estimate finds nothing: after much drift the right closure is metres and degrees from the
//! guess, beyond IDC's basin. The window is sized from the uncertainty (the path since the
//! submap, as IDC's candidate radius), and widens to every heading after a long stretch
//! without any closure. The correlative pose is refined by IDC against the submap's nearest
//! node and must pass the quality gate; the edge gets IDC's covariance and the loop-closure
//! kernel.

use super::Mapper2d;
use super::submaps::Submap;
use crate::matching::correlative::{CorrelativeMatch, SearchWindow, unambiguous_search};
use crate::matching::{accept, idc};
use crate::network::{EdgeKind, RelativeEdge};
use crate::se2::{Pose2, wrap_angle};

impl Mapper2d {
    /// Tracks `node` in the submaps and, when its robot has had no closure for a while
    /// (`closed` counts the ones IDC just added), searches nearby submaps; returns how many
    /// closures it added.
    pub(super) fn search_submaps(&mut self, node: usize, closed: usize) -> usize {
        let p = self.params.submaps.clone();
        if !p.enabled {
            return 0;
        }
        self.track_submaps(node);
        let robot = self.node_robot[node].0;
        let path = self.node_path_m[node];
        // The IDC closures just added are the last `closed` edges.
        let edges = &self.graph.edges[self.graph.edges.len() - closed..];
        let looped = edges
            .iter()
            .any(|e| path - self.node_path_m[e.from] >= p.closure_min_path_m);
        let state = &mut self.submaps.robots[robot];
        if looped {
            state.last_closure_m = Some(path);
            return 0;
        }
        let since = path - state.last_closure_m.unwrap_or(path);
        if since < p.search_after_m || path - state.last_search_m < p.search_every_m {
            return 0;
        }
        state.last_search_m = path;
        let global = since >= p.global_after_m;
        let candidates = self.submap_candidates(node, global);
        let mut added = 0;
        for &(_, k) in candidates.iter().take(p.max_submaps) {
            self.stats.submap_searches += 1;
            if let Some(edge) = self.match_submap(k, node, global) {
                self.graph.edges.push(edge);
                self.stats.loop_closures += 1;
                self.stats.submap_closures += 1;
                added += 1;
            }
        }
        if added > 0 {
            self.submaps.robots[robot].last_closure_m = Some(path);
        }
        added
    }

    /// The submaps `node` is searched in, nearest (by the grid's centre) first: its robot's,
    /// at least `loop_min_node_gap` nodes back, within the reach of the node's estimate.
    fn submap_candidates(&self, node: usize, global: bool) -> Vec<(f64, usize)> {
        let (robot, place) = self.node_robot[node];
        let path = self.node_path_m[node];
        let here = self.graph.poses[node];
        let mut candidates: Vec<(f64, usize)> = self
            .submaps
            .done
            .iter()
            .enumerate()
            .filter(|(_, s)| {
                s.robot == robot && s.last_place + self.params.loop_min_node_gap <= place
            })
            .filter_map(|(k, s)| {
                let at = self.graph.poses[s.anchor].between(&here);
                (s.distance_to([at.x, at.y]) <= self.reach(s, path, global)).then(|| {
                    let (c, _) = s.centre_and_reach();
                    ((at.x - c[0]).hypot(at.y - c[1]), k)
                })
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        candidates
    }

    /// How far from its estimate a node may be in a submap: IDC's candidate radius.
    fn search_radius(&self, submap: &Submap, path_m: f64) -> f64 {
        self.params.loop_search_radius_m
            + self.params.loop_search_growth * (path_m - submap.last_path_m).max(0.0)
    }

    /// How far from `submap`'s extent a node's estimate may be for the submap to be a
    /// candidate at `path_m`: the search radius, and no farther than the window can reach
    /// (its corner, √2 × its half side, then the returns' range: beyond that no return lands
    /// in the grid, and the search scores nothing). Without the second bound every submap
    /// of a robot's drew a search once its path had grown long enough, however far, and a
    /// node's time grew with the site.
    fn reach(&self, submap: &Submap, path_m: f64, global: bool) -> f64 {
        let (window, _) = self.window(submap, path_m, global);
        let search_radius = self.search_radius(submap, path_m);
        let window_reach =
            std::f64::consts::SQRT_2 * window.linear_m + self.params.submaps.grid.max_range_m;
        search_radius.min(window_reach)
    }

    /// The window of a search in `submap` at `path_m`, the search radius at most the
    /// window's cap (the wide one's when `global`), and the score it asks for.
    fn window(&self, submap: &Submap, path_m: f64, global: bool) -> (SearchWindow, f64) {
        let p = &self.params.submaps;
        let radius = self.search_radius(submap, path_m);
        if global {
            let window = SearchWindow {
                linear_m: radius.min(p.global_linear_window_m),
                angular_rad: std::f64::consts::PI,
            };
            (window, p.global_min_score)
        } else {
            let window = SearchWindow {
                linear_m: radius.min(p.max_linear_window_m),
                angular_rad: p.angular_window_rad,
            };
            (window, p.min_score)
        }
    }

    /// Searches `node`'s scan in submap `k`; the closure edge, refined by IDC, if it holds.
    fn match_submap(&self, k: usize, node: usize, global: bool) -> Option<RelativeEdge> {
        let submap = &self.submaps.done[k];
        let initial = self.graph.poses[submap.anchor].between(&self.graph.poses[node]);
        let (window, min_score) = self.window(submap, self.node_path_m[node], global);
        let found = self.unambiguous_match(k, node, initial, &window, min_score)?;
        let (near, m) = self.refine_in_submap(k, node, &found.pose, true)?;
        Some(RelativeEdge {
            from: near,
            to: node,
            measurement: m.pose,
            information: self.match_information(&m.covariance),
            kind: EdgeKind::LoopClosure,
            robust: self.params.loop_robust,
        })
    }

    /// IDC of `node`'s scan against submap `k`'s node nearest to `found` (the scan's pose in
    /// the submap's frame), from that pose: the closure's node and match, if IDC stays near
    /// the correlative pose and (with `gated`) the quality gate accepts it.
    pub(super) fn refine_in_submap(
        &self,
        k: usize,
        node: usize,
        found: &Pose2,
        gated: bool,
    ) -> Option<(usize, crate::matching::Match)> {
        let p = &self.params.submaps;
        let submap = &self.submaps.done[k];
        let &(near, near_pose) = submap.nodes.iter().min_by(|a, b| {
            let d = |q: &Pose2| (q.x - found.x).hypot(q.y - found.y);
            d(&a.1).total_cmp(&d(&b.1))
        })?;
        let guess = near_pose.between(found);
        let m = idc(
            &self.node_scans[near],
            &self.node_scans[node],
            guess,
            &self.params.idc,
        )
        .ok()?;
        let shift = (m.pose.x - guess.x).hypot(m.pose.y - guess.y);
        let turn = wrap_angle(m.pose.theta - guess.theta).abs();
        ((!gated || accept(&m, &self.params.gate))
            && shift <= p.refine_max_shift_m
            && turn <= p.refine_max_turn_rad)
            .then_some((near, m))
    }

    /// The best pose of `node`'s scan in submap `k`, within `window` around `initial` and
    /// scoring at least `min_score`, unless a pose elsewhere (beyond `ambiguity_radius_m`)
    /// scores nearly as well (`max_runner_up_ratio`): a corridor, a row of like doors or
    /// lamp posts fits shifted poses too, and such a best pose is as likely wrong as right.
    fn unambiguous_match(
        &self,
        k: usize,
        node: usize,
        initial: Pose2,
        window: &SearchWindow,
        min_score: f64,
    ) -> Option<CorrelativeMatch> {
        let p = &self.params.submaps;
        let grids = self.pooled_grids(k);
        let (ratio, radius) = (p.max_runner_up_ratio, p.ambiguity_radius_m);
        let scan = &self.node_scans[node];
        unambiguous_search(
            &grids, scan, initial, window, min_score, ratio, radius, &p.grid,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::super::Mapper2dParams;
    use super::super::tests::scan_at;
    use super::*;
    use crate::matching::correlative::search;

    /// However long a robot's path, a submap is a candidate only as far as the window reaches:
    /// beyond that no return lands in its grid, and the search finds nothing.
    #[test]
    fn a_submap_beyond_the_windows_reach_is_no_candidate() {
        let mut mapper = Mapper2d::new(Mapper2dParams::default());
        for k in 0..26 {
            let pose = Pose2::new(-6.0 + 0.5 * k as f64, 0.0, 0.0);
            mapper.add_scan(pose, scan_at(&pose, k)).expect("add");
        }
        let submap = mapper.submaps.done.first().expect("a submap finished");
        let p = &mapper.params.submaps;
        let window_reach = std::f64::consts::SQRT_2 * p.max_linear_window_m + p.grid.max_range_m;
        let near_path = mapper.reach(submap, submap.last_path_m, false);
        assert_eq!(near_path, mapper.params.loop_search_radius_m);
        assert_eq!(mapper.reach(submap, 1e4, false), window_reach, "bounded");
        let (window, _) = mapper.window(submap, 1e4, false);
        let (centre, half_side) = submap.centre_and_reach();
        let beyond = [centre[0] + half_side + window_reach + 0.2, centre[1]];
        assert!(submap.distance_to(beyond) > window_reach);
        let grids = mapper.pooled_grids(0);
        let scan = &mapper.node_scans[submap.nodes[5].0];
        let initial = Pose2::new(beyond[0], beyond[1], 0.0);
        let found = search(&grids, scan, initial, &window, 1e-6, &p.grid);
        assert!(found.is_none(), "{found:?}");
        // Within the reach, the same scan is found where it was taken.
        let (n, at) = submap.nodes[5];
        let initial = at.compose(&Pose2::new(window.linear_m * 0.5, 0.0, 0.0));
        let found = search(
            &grids,
            &mapper.node_scans[n],
            initial,
            &window,
            0.5,
            &p.grid,
        );
        let found = found.expect("found within the window");
        assert!(
            (found.pose.x - at.x).hypot(found.pose.y - at.y) < 0.2,
            "{found:?}"
        );
        // The candidates: the newest node after a long drive is searched in the submap where
        // it is, and not once its estimate is 100 m off, though the radius would allow it.
        mapper.params.loop_min_node_gap = 0;
        let newest = mapper.graph.poses.len() - 1;
        mapper.node_path_m[newest] = 1e4;
        let candidates = mapper.submap_candidates(newest, false);
        assert!(candidates.iter().any(|&(_, k)| k == 0), "{candidates:?}");
        mapper.graph.poses[newest].x += 100.0;
        let submap = &mapper.submaps.done[0];
        assert!(mapper.search_radius(submap, 1e4) > 1000.0);
        let candidates = mapper.submap_candidates(newest, false);
        assert!(candidates.is_empty(), "{candidates:?}");
    }
}
