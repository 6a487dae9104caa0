//! Pairwise consistency of loop closures (PCM, Mangelson et al. 2018): two closures are
//! consistent when the cycle they form with the chains of sequential edges between their ends
//! composes to the identity within its uncertainty (squared Mahalanobis distance below a χ²
//! bound); the closures trusted are a maximum clique of the consistency graph.
//!
//! Pure geometry: relative poses with first-order covariances (right perturbations, in the
//! pose's own frame, the convention of the network's information matrices), the chains'
//! prefix sums that give any path's pose and covariance in O(1), and an exact maximum-clique
//! search over a small candidate set.

use crate::se2::{Pose2, wrap_angle};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// A relative pose with the covariance of a right perturbation: `pose ⊕ Exp(δ)`, δ ~ N(0, Σ).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Uncertain {
    /// The pose (m, rad).
    pub pose: Pose2,
    /// Covariance of (x, y, θ) in the pose's own frame (m², rad²).
    pub covariance: Matrix3<f64>,
}

/// The SE(2) adjoint of `p`: `p ⊕ Exp(δ) = Exp(Ad(p)·δ) ⊕ p`.
fn adjoint(p: &Pose2) -> Matrix3<f64> {
    let (s, c) = p.theta.sin_cos();
    Matrix3::new(c, -s, p.y, s, c, -p.x, 0.0, 0.0, 1.0)
}

/// The inverse adjoint, Ad(p⁻¹).
fn adjoint_inverse(p: &Pose2) -> Matrix3<f64> {
    adjoint(&p.inverse())
}

impl Uncertain {
    /// A pose known exactly.
    pub fn exact(pose: Pose2) -> Uncertain {
        Uncertain {
            pose,
            covariance: Matrix3::zeros(),
        }
    }

    /// `self ⊕ other`, the perturbations independent.
    pub fn compose(&self, other: &Uncertain) -> Uncertain {
        let a = adjoint_inverse(&other.pose);
        Uncertain {
            pose: self.pose.compose(&other.pose),
            covariance: a * self.covariance * a.transpose() + other.covariance,
        }
    }

    /// The inverse motion.
    pub fn inverse(&self) -> Uncertain {
        let a = adjoint(&self.pose);
        Uncertain {
            pose: self.pose.inverse(),
            covariance: a * self.covariance * a.transpose(),
        }
    }

    /// Squared Mahalanobis distance of the pose from the identity (∞ when the covariance is
    /// singular).
    pub fn chi2_from_identity(&self) -> f64 {
        let e = Vector3::new(self.pose.x, self.pose.y, wrap_angle(self.pose.theta));
        self.covariance
            .try_inverse()
            .map_or(f64::INFINITY, |i| e.dot(&(i * e)))
    }
}

/// Where a node sits: its chain (robot) and its place in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChainPlace {
    /// The chain.
    pub chain: usize,
    /// The place along it (0 for its first node).
    pub place: usize,
}

/// Every chain's sequential measurements composed from its first node, with prefix sums of
/// their covariances carried to that node's frame, so the path between any two places of a
/// chain costs O(1).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct ChainPaths {
    /// By node: its chain and place.
    places: Vec<ChainPlace>,
    /// By chain, by place: the node.
    nodes: Vec<Vec<usize>>,
    /// By chain, by place: the node's pose composed from the chain's first node.
    poses: Vec<Vec<Pose2>>,
    /// By chain, by place: Σ Ad(P_k) Σ_k Ad(P_k)ᵀ over the steps up to the place.
    sums: Vec<Vec<Matrix3<f64>>>,
}

impl ChainPaths {
    /// Node `node` (the next node index) starts chain `chain`.
    pub fn start(&mut self, node: usize, chain: usize) {
        debug_assert_eq!(node, self.places.len());
        if self.poses.len() <= chain {
            self.poses.resize(chain + 1, Vec::new());
            self.sums.resize(chain + 1, Vec::new());
            self.nodes.resize(chain + 1, Vec::new());
        }
        self.nodes[chain].push(node);
        self.places.push(ChainPlace {
            chain,
            place: self.poses[chain].len(),
        });
        self.poses[chain].push(Pose2::IDENTITY);
        self.sums[chain].push(Matrix3::zeros());
    }

    /// Node `node` (the next node index) extends chain `chain` by `step` from its last node.
    pub fn extend(&mut self, node: usize, chain: usize, step: &Uncertain) {
        debug_assert_eq!(node, self.places.len());
        let (Some(&last), Some(&sum)) = (
            self.poses.get(chain).and_then(|p| p.last()),
            self.sums.get(chain).and_then(|s| s.last()),
        ) else {
            return self.start(node, chain);
        };
        let pose = last.compose(&step.pose);
        let a = adjoint(&pose);
        self.places.push(ChainPlace {
            chain,
            place: self.poses[chain].len(),
        });
        self.poses[chain].push(pose);
        self.nodes[chain].push(node);
        self.sums[chain].push(sum + a * step.covariance * a.transpose());
    }

    /// The nodes of chain `chain` so far, in order.
    pub fn chain_nodes(&self, chain: usize) -> &[usize] {
        self.nodes.get(chain).map_or(&[], Vec::as_slice)
    }

    /// Nodes in chain `chain` so far.
    pub fn chain_len(&self, chain: usize) -> usize {
        self.poses.get(chain).map_or(0, Vec::len)
    }

    /// The node `offset` places from node `node` along its chain, if there is one.
    pub fn neighbour(&self, node: usize, offset: isize) -> Option<usize> {
        let at = self.places[node];
        let place = at.place.checked_add_signed(offset)?;
        self.nodes[at.chain].get(place).copied()
    }

    /// Where node `node` sits.
    pub fn place(&self, node: usize) -> ChainPlace {
        self.places[node]
    }

    /// The path from node `a` to node `b` along their chain (`b` seen from `a`), `None` when
    /// they are on different chains.
    pub fn path(&self, a: usize, b: usize) -> Option<Uncertain> {
        let (pa, pb) = (self.places[a], self.places[b]);
        if pa.chain != pb.chain {
            return None;
        }
        let (poses, sums) = (&self.poses[pa.chain], &self.sums[pa.chain]);
        let (lo, hi) = (pa.place.min(pb.place), pa.place.max(pb.place));
        let end = adjoint_inverse(&poses[hi]);
        let forward = Uncertain {
            pose: poses[lo].between(&poses[hi]),
            covariance: end * (sums[hi] - sums[lo]) * end.transpose(),
        };
        Some(if pa.place <= pb.place {
            forward
        } else {
            forward.inverse()
        })
    }

    /// Places between nodes `a` and `b` along their chain, `None` on different chains.
    pub fn gap(&self, a: usize, b: usize) -> Option<usize> {
        let (pa, pb) = (self.places[a], self.places[b]);
        (pa.chain == pb.chain).then(|| pa.place.abs_diff(pb.place))
    }
}

/// A loop-closure candidate: node `to` seen from node `from`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Closure {
    /// The node it is seen from.
    pub from: usize,
    /// The node seen.
    pub to: usize,
    /// The measured relative pose and its covariance.
    pub measurement: Uncertain,
}

impl Closure {
    /// The same closure seen from its other end.
    fn reversed(&self) -> Closure {
        Closure {
            from: self.to,
            to: self.from,
            measurement: self.measurement.inverse(),
        }
    }
}

/// How `b` pairs with `a`: `b` itself or reversed, so that the ends are on the same chains,
/// with the larger of the two chain gaps; the pairing with the smaller one.
fn pairing(a: &Closure, b: &Closure, paths: &ChainPaths) -> Option<(Closure, usize)> {
    let gaps = |b: &Closure| Some(paths.gap(a.to, b.to)?.max(paths.gap(b.from, a.from)?));
    let direct = gaps(b).map(|g| (*b, g));
    let reversed = gaps(&b.reversed()).map(|g| (b.reversed(), g));
    match (direct, reversed) {
        (Some(d), Some(r)) => Some(if r.1 < d.1 { r } else { d }),
        (d, r) => d.or(r),
    }
}

/// The larger chain gap between the ends of `a` and `b` (paired as well as they can be),
/// `None` when their ends are not on common chains.
pub fn ends_gap(a: &Closure, b: &Closure, paths: &ChainPaths) -> Option<usize> {
    pairing(a, b, paths).map(|(_, g)| g)
}

/// Squared Mahalanobis distance of the cycle `a`, chain from `a.to` to `b.to`, `b` backwards,
/// chain from `b.from` to `a.from`; `None` when their ends are not on common chains.
pub fn cycle_chi2(a: &Closure, b: &Closure, paths: &ChainPaths) -> Option<f64> {
    let (b, _) = pairing(a, b, paths)?;
    let cycle = a
        .measurement
        .compose(&paths.path(a.to, b.to)?)
        .compose(&b.measurement.inverse())
        .compose(&paths.path(b.from, a.from)?);
    Some(cycle.chi2_from_identity())
}

/// A maximum clique of the graph on `n ≤ 64` vertices given by `adjacent` (bit j of
/// `adjacent[i]` set when i and j are consistent), as a bit set; ties go to the clique with
/// more of the `preferred` vertices. Exact (Bron–Kerbosch with pivoting).
pub fn maximum_clique(adjacent: &[u64], preferred: u64) -> u64 {
    let n = adjacent.len();
    assert!(n <= 64, "at most 64 vertices");
    let all = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
    let mut best = (0u32, 0u32, 0u64);
    expand(adjacent, preferred, 0, all, 0, &mut best);
    best.2
}

fn expand(
    adjacent: &[u64],
    preferred: u64,
    r: u64,
    mut p: u64,
    mut x: u64,
    best: &mut (u32, u32, u64),
) {
    if p == 0 {
        let score = (r.count_ones(), (r & preferred).count_ones());
        if x == 0 && score > (best.0, best.1) {
            *best = (score.0, score.1, r);
        }
        return;
    }
    // No clique through here can beat the best one.
    if r.count_ones() + p.count_ones() < best.0 {
        return;
    }
    let pivot = (p | x).trailing_zeros() as usize;
    let mut todo = p & !adjacent[pivot];
    while todo != 0 {
        let v = todo.trailing_zeros() as usize;
        let bit = 1u64 << v;
        todo &= !bit;
        expand(
            adjacent,
            preferred,
            r | bit,
            p & adjacent[v],
            x & adjacent[v],
            best,
        );
        p &= !bit;
        x |= bit;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step_covariance() -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::new(
            0.02f64.powi(2),
            0.02f64.powi(2),
            0.01f64.powi(2),
        ))
    }

    /// Two laps of a 10 m square, a node every metre, the steps measured exactly.
    fn two_laps() -> (Vec<Pose2>, ChainPaths) {
        let mut truth = vec![Pose2::IDENTITY];
        for k in 1..80 {
            let turn = if k % 10 == 0 {
                std::f64::consts::FRAC_PI_2
            } else {
                0.0
            };
            let last = truth[k - 1];
            truth.push(last.compose(&Pose2::new(1.0, 0.0, turn)));
        }
        let mut paths = ChainPaths::default();
        paths.start(0, 0);
        for k in 1..truth.len() {
            let step = Uncertain {
                pose: truth[k - 1].between(&truth[k]),
                covariance: step_covariance(),
            };
            paths.extend(k, 0, &step);
        }
        (truth, paths)
    }

    fn closure(truth: &[Pose2], from: usize, to: usize, off: Pose2) -> Closure {
        Closure {
            from,
            to,
            measurement: Uncertain {
                pose: truth[from].between(&truth[to]).compose(&off),
                covariance: step_covariance(),
            },
        }
    }

    #[test]
    fn a_path_from_prefix_sums_is_the_composed_steps() {
        let (truth, paths) = two_laps();
        let (a, b) = (7, 33);
        let mut composed = Uncertain::exact(Pose2::IDENTITY);
        for k in a..b {
            let step = Uncertain {
                pose: truth[k].between(&truth[k + 1]),
                covariance: step_covariance(),
            };
            composed = composed.compose(&step);
        }
        let path = paths.path(a, b).expect("one chain");
        assert!((path.covariance - composed.covariance).abs().max() < 1e-12);
        assert!(path.pose.between(&composed.pose).x.abs() < 1e-9);
        let back = paths.path(b, a).expect("one chain");
        assert!(
            (back.covariance - composed.inverse().covariance)
                .abs()
                .max()
                < 1e-12
        );
        assert_eq!(paths.gap(b, a), Some(b - a));
    }

    #[test]
    fn the_maximum_clique_keeps_right_closures_and_drops_wrong_ones() {
        let (truth, paths) = two_laps();
        // Right closures: the second lap seen from the first, a few millimetres off.
        let mut closures: Vec<Closure> = (40..80)
            .step_by(4)
            .map(|k| closure(&truth, k - 40, k, Pose2::new(0.005, -0.003, 0.001)))
            .collect();
        let right = closures.len();
        // Wrong ones near them (a similar place, a local minimum), off by 0.5–1.5 m and a
        // few degrees. (Far from every right one, over long chains, a wrong closure can look
        // consistent: the mapper compares closures within a window only and wants support.)
        for (from, to, off) in [
            (3, 47, Pose2::new(0.5, 0.3, 0.05)),
            (29, 71, Pose2::new(-1.0, 0.2, -0.1)),
            (25, 66, Pose2::new(0.2, 1.5, 0.2)),
            (30, 78, Pose2::new(-0.4, -0.4, 0.08)),
        ] {
            closures.push(closure(&truth, from, to, off));
        }
        let mut adjacent = vec![0u64; closures.len()];
        for i in 0..closures.len() {
            for j in i + 1..closures.len() {
                let chi2 = cycle_chi2(&closures[i], &closures[j], &paths).expect("one chain");
                if chi2 <= 11.34 {
                    adjacent[i] |= 1 << j;
                    adjacent[j] |= 1 << i;
                }
            }
        }
        let clique = maximum_clique(&adjacent, 0);
        assert_eq!(clique, (1 << right) - 1, "{clique:b}");
    }

    #[test]
    fn a_closure_is_consistent_with_itself_reversed() {
        let (truth, paths) = two_laps();
        let a = closure(&truth, 5, 45, Pose2::IDENTITY);
        let chi2 = cycle_chi2(&a, &a.reversed(), &paths).expect("one chain");
        assert!(chi2 < 1e-12, "{chi2}");
        assert_eq!(ends_gap(&a, &a.reversed(), &paths), Some(0));
    }

    #[test]
    fn ties_between_cliques_go_to_the_preferred_vertices() {
        // 0–1 and 2–3 are cliques of two; 4 alone.
        let adjacent = [0b0010, 0b0001, 0b1000, 0b0100, 0];
        assert_eq!(maximum_clique(&adjacent, 0b1000).count_ones(), 2);
        assert_eq!(maximum_clique(&adjacent, 0b1000), 0b1100);
        assert_eq!(maximum_clique(&adjacent, 0b0001), 0b0011);
        // A triangle beats a preferred pair.
        let adjacent = [0b110, 0b101, 0b011, 0b10000, 0b01000];
        assert_eq!(maximum_clique(&adjacent, 0b11000), 0b111);
    }
}
