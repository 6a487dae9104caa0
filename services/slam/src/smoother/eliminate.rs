//! The dense arithmetic of the smoother: an edge linearized into a quadratic factor, a
//! variable eliminated from the factors on it (a conditional on its separator and a new
//! factor on the separator), and the minimum-degree order of the variables re-eliminated in
//! an update.
//!
//! Every variable is a pose (x, y, θ): blocks are 3 × 3, matrices row-major.

use crate::network::RelativeEdge;
use crate::se2::Pose2;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// A quadratic factor in information form on `vars`: ½ δᵀHδ − gᵀδ, H of (3k)², g of 3k.
#[derive(Clone, Debug, Default)]
pub(super) struct Quadratic {
    pub h: Vec<f64>,
    pub g: Vec<f64>,
}

/// `R δᵥ + S δ_sep = d`, with R = Lᵀ (L lower, 3 × 3, stored as L00 L10 L11 L20 L21 L22)
/// and S of 3 × 3|sep|.
#[derive(Clone, Debug, Default)]
pub(super) struct Conditional {
    pub sep: Vec<u32>,
    pub l: [f64; 6],
    pub s: Vec<f64>,
    pub d: [f64; 3],
}

impl Conditional {
    /// δᵥ given the steps of the separator.
    pub fn solve(&self, delta: &[[f64; 3]]) -> [f64; 3] {
        let cols = 3 * self.sep.len();
        let mut rhs = self.d;
        for (j, &u) in self.sep.iter().enumerate() {
            let du = &delta[u as usize];
            for (r, value) in rhs.iter_mut().enumerate() {
                let row = &self.s[r * cols + 3 * j..r * cols + 3 * j + 3];
                *value -= row[0] * du[0] + row[1] * du[1] + row[2] * du[2];
            }
        }
        let l = &self.l;
        let x2 = rhs[2] / l[5];
        let x1 = (rhs[1] - l[4] * x2) / l[2];
        let x0 = (rhs[0] - l[1] * x1 - l[3] * x2) / l[0];
        [x0, x1, x2]
    }
}

/// The variable's information is not positive definite: nothing fixes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct NotPositiveDefinite;

/// Eliminates the first variable of a combined factor on `vars` (`h` of (3k)², `g` of 3k,
/// the variable first) into `conditional`, its conditional on the rest, and `left`, the
/// factor left on the rest (both overwritten, their storage reused).
pub(super) fn eliminate_first(
    vars: &[u32],
    h: &[f64],
    g: &[f64],
    conditional: &mut Conditional,
    left: &mut Quadratic,
) -> Result<(), NotPositiveDefinite> {
    let m = 3 * vars.len();
    let at = |r: usize, c: usize| h[r * m + c];
    let scale = at(0, 0).max(at(1, 1)).max(at(2, 2));
    let tiny = 1e-12 * scale.max(f64::MIN_POSITIVE);
    let pivot = |x: f64| {
        if x > tiny {
            Ok(x.sqrt())
        } else {
            Err(NotPositiveDefinite)
        }
    };
    let l00 = pivot(at(0, 0))?;
    let (l10, l20) = (at(1, 0) / l00, at(2, 0) / l00);
    let l11 = pivot(at(1, 1) - l10 * l10)?;
    let l21 = (at(2, 1) - l20 * l10) / l11;
    let l22 = pivot(at(2, 2) - l20 * l20 - l21 * l21)?;
    let rest = m - 3;
    let s = &mut conditional.s;
    s.clear();
    s.resize(3 * rest, 0.0);
    {
        let (s0, s12) = s.split_at_mut(rest);
        let (s1, s2) = s12.split_at_mut(rest);
        let (h0, h1, h2) = (&h[3..m], &h[m + 3..2 * m], &h[2 * m + 3..3 * m]);
        for c in 0..rest {
            let x0 = h0[c] / l00;
            let x1 = (h1[c] - l10 * x0) / l11;
            s0[c] = x0;
            s1[c] = x1;
            s2[c] = (h2[c] - l20 * x0 - l21 * x1) / l22;
        }
    }
    let d0 = g[0] / l00;
    let d1 = (g[1] - l10 * d0) / l11;
    let d = [d0, d1, (g[2] - l20 * d0 - l21 * d1) / l22];
    // Filled row by row, not zeroed first: for a large separator the zeroing costs as much
    // as the update.
    left.h.clear();
    left.h.reserve(rest * rest);
    left.g.clear();
    let (s0, s1, s2) = (&s[..rest], &s[rest..2 * rest], &s[2 * rest..]);
    for a in 0..rest {
        let (a0, a1, a2) = (s0[a], s1[a], s2[a]);
        left.g.push(g[3 + a] - (a0 * d[0] + a1 * d[1] + a2 * d[2]));
        let row = &h[(3 + a) * m + 3..(4 + a) * m];
        left.h.extend(
            row.iter()
                .zip(s0)
                .zip(s1)
                .zip(s2)
                .map(|(((&hv, &b0), &b1), &b2)| hv - (a0 * b0 + a1 * b1 + a2 * b2)),
        );
    }
    conditional.sep.clear();
    conditional.sep.extend_from_slice(&vars[1..]);
    conditional.l = [l00, l10, l11, l20, l21, l22];
    conditional.d = d;
    Ok(())
}

/// Adds a factor on `from_vars` into a combined factor on `into_slots` places: `slot[i]`
/// is the combined block of the factor's i-th variable.
pub(super) fn add_into(h: &mut [f64], g: &mut [f64], m: usize, slots: &[usize], f: &Quadratic) {
    let k = 3 * slots.len();
    for (i, &si) in slots.iter().enumerate() {
        for r in 0..3 {
            g[3 * si + r] += f.g[3 * i + r];
            let row = &f.h[(3 * i + r) * k..(3 * i + r + 1) * k];
            let out = &mut h[(3 * si + r) * m..(3 * si + r + 1) * m];
            for (j, &sj) in slots.iter().enumerate() {
                out[3 * sj] += row[3 * j];
                out[3 * sj + 1] += row[3 * j + 1];
                out[3 * sj + 2] += row[3 * j + 2];
            }
        }
    }
}

/// The graph of `count` variables linked by `cliques` (each a list of variables that share a
/// factor): each variable's neighbours, once each.
pub(super) fn adjacency(count: usize, cliques: &[Vec<u32>]) -> Vec<Vec<u32>> {
    let mut adjacent: Vec<Vec<u32>> = vec![Vec::new(); count];
    for clique in cliques {
        for &a in clique {
            adjacent[a as usize].extend(clique.iter().copied().filter(|&b| b != a));
        }
    }
    let mut mark = vec![u32::MAX; count];
    for (v, list) in adjacent.iter_mut().enumerate() {
        list.retain(|&b| std::mem::replace(&mut mark[b as usize], v as u32) != v as u32);
    }
    adjacent
}

/// A minimum-degree order of the graph `adjacent` (each neighbour once), the variables whose
/// `last` is true after all others. Ties go to the lower index, so the order is deterministic.
pub(super) fn min_degree(mut adjacent: Vec<Vec<u32>>, last: &[bool]) -> Vec<u32> {
    let count = adjacent.len();
    // `mark[b] == stamp`: b is already in the list being extended.
    let (mut mark, mut stamp) = (vec![0u32; count], 0u32);
    let mut heap = BinaryHeap::with_capacity(2 * count);
    for (v, list) in adjacent.iter().enumerate() {
        heap.push(Reverse((last[v], list.len(), v as u32)));
    }
    let mut eliminated = vec![false; count];
    let mut order = Vec::with_capacity(count);
    while let Some(Reverse((_, degree, v))) = heap.pop() {
        let vi = v as usize;
        if eliminated[vi] || degree != adjacent[vi].len() {
            continue;
        }
        eliminated[vi] = true;
        order.push(v);
        let neighbours = std::mem::take(&mut adjacent[vi]);
        for &a in &neighbours {
            let list = &mut adjacent[a as usize];
            if let Some(at) = list.iter().position(|&b| b == v) {
                list.swap_remove(at);
            }
            stamp += 1;
            for &b in list.iter() {
                mark[b as usize] = stamp;
            }
            mark[a as usize] = stamp;
            list.extend(
                neighbours
                    .iter()
                    .copied()
                    .filter(|&b| mark[b as usize] != stamp),
            );
            heap.push(Reverse((last[a as usize], list.len(), a)));
        }
    }
    order
}

/// An edge's quadratic at `theta`, on its poses other than node 0 (H = JᵀΩJ, g = −JᵀΩe, the
/// robust kernel's weight at the current error folded into Ω).
pub(super) fn linearize_edge(e: &RelativeEdge, theta: &[Pose2]) -> (Vec<u32>, Quadratic) {
    let (err, ji, jj) = e.linearize(theta);
    let chi2 = err.dot(&(e.information * err));
    let omega = e.information * e.robust.weight(chi2);
    let mut blocks = Vec::with_capacity(2);
    if e.from != 0 {
        blocks.push((e.from as u32, ji));
    }
    if e.to != 0 {
        blocks.push((e.to as u32, jj));
    }
    let k = 3 * blocks.len();
    let mut q = Quadratic {
        h: vec![0.0; k * k],
        g: vec![0.0; k],
    };
    for (a, (_, ja)) in blocks.iter().enumerate() {
        let oa = ja.transpose() * omega;
        let ga = -(oa * err);
        for (b, (_, jb)) in blocks.iter().enumerate() {
            let hab = oa * jb;
            for r in 0..3 {
                for c in 0..3 {
                    q.h[(3 * a + r) * k + 3 * b + c] = hab[(r, c)];
                }
            }
        }
        for r in 0..3 {
            q.g[3 * a + r] = ga[r];
        }
    }
    (blocks.iter().map(|(v, _)| *v).collect(), q)
}
