//! Wrong loop closures on purpose, to see the consistency check work: plausible-looking ones
//! (the relative pose of two nodes' current estimates, off by a little), as a matcher fooled
//! by a similar place or caught in a local minimum would give them.

use super::Mapper2d;
use crate::network::{GraphError, PoseGraph};
use crate::se2::Pose2;
use crate::splitmix::SplitMix;
use std::f64::consts::TAU;

/// Seeded generator of wrong closures, fed to a mapper as external candidates.
#[derive(Clone, Debug)]
pub struct WrongClosures {
    fraction: f64,
    draw: SplitMix,
    /// Wrong closures owed (a fraction of the matches seen).
    owed: f64,
    matches_seen: usize,
    /// Each wrong closure given: from, to, measurement.
    injected: Vec<(usize, usize, Pose2)>,
}

/// How far a wrong closure is off (m, rad): uniform in these ranges, random direction and sign.
const OFF_M: (f64, f64) = (0.5, 2.0);
const OFF_RAD: (f64, f64) = (3f64.to_radians(), 15f64.to_radians());
/// The covariance a wrong closure claims: a good match's (m², rad²).
const CLAIMED_SIGMA: [f64; 3] = [0.02, 0.02, 0.005];

impl WrongClosures {
    /// `fraction` wrong closures per loop-closure match of the mapper, drawn from `seed`.
    pub fn new(fraction: f64, seed: u64) -> WrongClosures {
        WrongClosures {
            fraction,
            draw: SplitMix::new(seed),
            owed: 0.0,
            matches_seen: 0,
            injected: Vec::new(),
        }
    }

    /// Wrong closures given to the mapper so far.
    pub fn injected(&self) -> usize {
        self.injected.len()
    }

    /// How many of them are edges of `graph` (got through the consistency check).
    pub fn accepted(&self, graph: &PoseGraph) -> usize {
        graph
            .edges
            .iter()
            .filter(|e| {
                self.injected
                    .iter()
                    .any(|&(from, to, z)| (e.from, e.to, e.measurement) == (from, to, z))
            })
            .count()
    }

    /// Call after each scan: for every loop-closure match the mapper's gate accepted since
    /// the last call, `fraction` of a wrong closure from the newest node to a random earlier
    /// node of its chain (at least `loop_min_node_gap` back), through
    /// [`Mapper2d::add_closure_candidate`]. Returns how many edges the mapper added.
    pub fn inject(&mut self, mapper: &mut Mapper2d) -> Result<usize, GraphError> {
        let matches = mapper.stats.loop_matches;
        self.owed += self.fraction * (matches - self.matches_seen) as f64;
        self.matches_seen = matches;
        let Some(newest) = mapper.graph.poses.len().checked_sub(1) else {
            return Ok(0);
        };
        let (robot, place) = mapper.node_robot[newest];
        let gap = mapper.params.loop_min_node_gap;
        let earlier: Vec<usize> = (0..newest)
            .filter(|&n| {
                let (r, p) = mapper.node_robot[n];
                r == robot && p + gap <= place
            })
            .collect();
        let mut added = 0;
        while self.owed >= 1.0 && !earlier.is_empty() {
            self.owed -= 1.0;
            let from = earlier[(self.draw.unit() * earlier.len() as f64) as usize];
            let truth = mapper.graph.poses[from].between(&mapper.graph.poses[newest]);
            let off = offset(&mut self.draw, OFF_M, OFF_RAD);
            let [sx, sy, st] = CLAIMED_SIGMA;
            let covariance = [
                [sx * sx, 0.0, 0.0],
                [0.0, sy * sy, 0.0],
                [0.0, 0.0, st * st],
            ];
            let measurement = truth.compose(&off);
            added += mapper.add_closure_candidate(from, newest, measurement, covariance)?;
            self.injected.push((from, newest, measurement));
        }
        Ok(added)
    }
}

/// A pose off by `off_m` (m, random direction) and `off_rad` (rad, random sign), drawn
/// from `draw`.
pub(super) fn offset(draw: &mut SplitMix, off_m: (f64, f64), off_rad: (f64, f64)) -> Pose2 {
    let (distance, direction) = (draw.uniform(off_m.0, off_m.1), draw.unit() * TAU);
    let sign = if draw.unit() < 0.5 { -1.0 } else { 1.0 };
    Pose2::new(
        distance * direction.cos(),
        distance * direction.sin(),
        sign * draw.uniform(off_rad.0, off_rad.1),
    )
}
