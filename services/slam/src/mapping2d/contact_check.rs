//! The check a first contact must pass: the two robots' stretches of path around the match
//! agree. A submap outdoors holds a few dozen landmark returns, and a wrong pose that fits
//! them (a row of lamp posts shifted by one post, turned by a path's angle) is common. Over
//! a longer stretch of each robot's path, placed by the match, the landmarks one robot saw
//! near the other's path must be where the other saw landmarks too: at a wrong pose most of
//! them land where the other robot, passing close by, saw nothing. The check runs both ways
//! (each robot's returns near the other's path), since one robot may pass a place on its
//! edge and see little of what the other saw.

use super::Mapper2d;
use crate::se2::Pose2;
use serde::{Deserialize, Serialize};
use std::collections::HashSet;

/// How two robots' stretches of path around a match must agree.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactCheckParams {
    /// Each robot's nodes within this much path (m) either side of the match's node: two
    /// submaps each way, so a stretch holds the match's submap and what lies around it
    /// (corners, the ends of rows of lamp posts).
    pub stretch_m: f64,
    /// A return is one the other robot should have seen when it lies within this distance
    /// (m) of one of the other's nodes on its stretch: well inside the 20 m range the grids
    /// keep, so occlusion and the leveled scan's cut rarely hide it.
    pub seen_within_m: f64,
    /// A return agrees when one of the other robot's returns lies in its cell or a
    /// neighbouring one, of this side (m): a match's error at 0.1 m cells plus the
    /// estimates' drift along a stretch.
    pub hit_m: f64,
    /// Both ways, at least this share of the returns the other robot should have seen must
    /// agree. In the park (scattered starts without GPS, seeds 1–10, every search's best
    /// pose with enough returns judged against the truth): 101 of 139 true matches reached
    /// 0.7, and 6 of 5,069 wrong ones (none of which found a second that agreed).
    pub min_share: f64,
    /// Each way, at least this many returns the other should have seen…
    pub min_expected: usize,
    /// …and both ways together at least this many: a share of a few returns says little.
    pub min_expected_both: usize,
}

impl Default for ContactCheckParams {
    fn default() -> Self {
        ContactCheckParams {
            stretch_m: 20.0,
            seen_within_m: 12.0,
            hit_m: 0.3,
            min_share: 0.7,
            min_expected: 5,
            min_expected_both: 30,
        }
    }
}

/// Of one robot's returns the other should have seen, how many agree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Agreement {
    agreeing: usize,
    expected: usize,
}

impl Agreement {
    fn share(&self) -> f64 {
        self.agreeing as f64 / self.expected.max(1) as f64
    }
}

impl Mapper2d {
    /// Whether the stretches of path around node `a` and node `b` (another robot's) agree
    /// when `b` lies at `b_in_a` in `a`'s frame.
    pub(super) fn stretches_agree(
        &self,
        a: usize,
        b: usize,
        b_in_a: &Pose2,
        p: &ContactCheckParams,
    ) -> bool {
        let ab = self.stretch_agreement(b, a, b_in_a, p);
        let ba = self.stretch_agreement(a, b, &b_in_a.inverse(), p);
        ab.share().min(ba.share()) >= p.min_share
            && ab.expected.min(ba.expected) >= p.min_expected
            && ab.expected + ba.expected >= p.min_expected_both
    }

    /// The nodes of `around`'s robot within `half_m` of path of it, with their poses in
    /// `around`'s frame (today's estimates).
    fn stretch_of(&self, around: usize, half_m: f64) -> Vec<(usize, Pose2)> {
        let path = &self.node_path_m;
        let base = self.graph.poses[around];
        let mut stretch = vec![(around, Pose2::IDENTITY)];
        for step in [-1, 1] {
            let mut n = around;
            while let Some(next) = self.chain_neighbour(n, step) {
                if (path[next] - path[around]).abs() > half_m {
                    break;
                }
                stretch.push((next, base.between(&self.graph.poses[next])));
                n = next;
            }
        }
        stretch
    }

    /// Of the returns on `from`'s stretch, placed in `to`'s frame by `from_in_to`, those
    /// `to`'s robot should have seen and those that land on its returns.
    fn stretch_agreement(
        &self,
        from: usize,
        to: usize,
        from_in_to: &Pose2,
        p: &ContactCheckParams,
    ) -> Agreement {
        let range_m = self.params.submaps.grid.max_range_m;
        let cell = |q: [f64; 2]| {
            (
                (q[0] / p.hit_m).floor() as i64,
                (q[1] / p.hit_m).floor() as i64,
            )
        };
        let returns = |stretch: &[(usize, Pose2)]| -> Vec<[f64; 2]> {
            stretch
                .iter()
                .flat_map(|(n, pose)| {
                    self.node_scans[*n]
                        .points()
                        .iter()
                        .filter(|q| q[0].hypot(q[1]) <= range_m)
                        .map(move |&q| pose.transform_point(q))
                })
                .collect()
        };
        let seen_by = self.stretch_of(to, p.stretch_m);
        let hits: HashSet<(i64, i64)> = returns(&seen_by).into_iter().map(cell).collect();
        let placed: Vec<(usize, Pose2)> = self
            .stretch_of(from, p.stretch_m)
            .into_iter()
            .map(|(n, pose)| (n, from_in_to.compose(&pose)))
            .collect();
        let mut counted = HashSet::new();
        let mut agreement = Agreement {
            agreeing: 0,
            expected: 0,
        };
        for q in returns(&placed) {
            let (i, j) = cell(q);
            let near_path = seen_by
                .iter()
                .any(|(_, at)| (at.x - q[0]).hypot(at.y - q[1]) <= p.seen_within_m);
            // One count per cell: a wall's many returns are one landmark's worth.
            if !near_path || !counted.insert((i, j)) {
                continue;
            }
            agreement.expected += 1;
            let agrees = (-1..=1).any(|di| (-1..=1).any(|dj| hits.contains(&(i + di, j + dj))));
            agreement.agreeing += usize::from(agrees);
        }
        agreement
    }
}

#[cfg(test)]
mod tests {
    use super::super::{FirstContactParams, Mapper2dParams, Placed};
    use super::*;
    use crate::matching::Scan2;
    use crate::matching::synthetic::{Scene, uniform_bearings};
    use std::f64::consts::PI;

    /// Lamp posts every 8 m on both sides of a straight path along x, and trees scattered
    /// off it without a pattern: one post's spacing along the path fits the posts, not the
    /// trees.
    fn posts_and_trees() -> Scene {
        let posts =
            (-8..=8).flat_map(|i| [([8.0 * i as f64, 4.0], 0.1), ([8.0 * i as f64, -4.0], 0.1)]);
        // A fixed scatter (a Weyl sequence), 6–14 m off the path on either side.
        let trees = (0..40).map(|i| {
            let u = (i as f64 * 0.618_034).fract();
            let v = (i as f64 * 0.414_214).fract();
            let side = if i % 2 == 0 { 1.0 } else { -1.0 };
            ([-60.0 + 120.0 * u, side * (6.0 + 8.0 * v)], 0.3)
        });
        Scene {
            walls: Vec::new(),
            trunks: posts.chain(trees).collect(),
        }
    }

    /// A robot drives along the path from `start_x` for 50 m, a scan every 2 m, its
    /// odometry exact in a frame of its own (its start); returns its nodes' true poses.
    fn drive(
        mapper: &mut Mapper2d,
        robot: usize,
        scene: &Scene,
        start_x: f64,
    ) -> Vec<(usize, Pose2)> {
        let bearings = uniform_bearings(1440, -PI, PI / 720.0);
        let start = Pose2::new(start_x, 0.0, 0.0);
        let mut nodes = Vec::new();
        for k in 0..=25 {
            let truth = Pose2::new(start_x + 2.0 * k as f64, 0.0, 0.0);
            let ranges = scene.scan(&truth, &bearings, 40.0, 0.01, (robot * 100 + k) as u64);
            let scan = Scan2::from_polar(&bearings, &ranges, 40.0).expect("same lengths");
            let odometry = start.between(&truth);
            if let Placed::Node(n) = mapper.add_robot_scan(robot, odometry, scan, &[]).unwrap() {
                nodes.push((n, truth));
            }
        }
        nodes
    }

    /// Two robots drive the same stretch of the path from different starts: at the true
    /// pose between their nodes the stretches agree; shifted by one post's spacing (where
    /// the posts alone fit as well) they do not.
    #[test]
    fn a_match_shifted_by_a_row_of_posts_fails_and_the_true_one_holds() {
        let scene = posts_and_trees();
        let mut mapper = Mapper2d::new(Mapper2dParams {
            first_contact: FirstContactParams {
                enabled: false,
                ..Default::default()
            },
            ..Default::default()
        });
        let first = drive(&mut mapper, 0, &scene, -30.0);
        let second = drive(&mut mapper, 1, &scene, -24.0);
        let (a, at_a) = first[first.len() / 2];
        let (b, at_b) = second[second.len() / 2];
        let p = ContactCheckParams::default();
        let truth = at_a.between(&at_b);
        assert!(mapper.stretches_agree(a, b, &truth, &p), "the true pose");
        for shift in [-8.0, 8.0] {
            let wrong = at_a.between(&Pose2::new(at_b.x + shift, at_b.y, at_b.theta));
            let one_way = mapper.stretch_agreement(b, a, &wrong, &p);
            assert!(one_way.expected >= p.min_expected, "{one_way:?}");
            assert!(
                !mapper.stretches_agree(a, b, &wrong, &p),
                "shifted {shift} m: {one_way:?}"
            );
        }
    }
}
