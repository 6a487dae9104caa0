//! The dense arithmetic of the smoother: an edge linearized into a quadratic factor, a
//! variable eliminated from the factors on it (a conditional on its separator and a new
//! factor on the separator), and the minimum-degree order of the variables re-eliminated in
//! an update.
//!
//! Every variable is a pose (x, y, θ): blocks are 3 × 3. Symmetric matrices are kept as their
//! upper triangles, row by row: half the arithmetic, and nothing to zero but what is summed.

use crate::network::RelativeEdge;
use crate::se2::Pose2;

/// A quadratic factor in information form on `vars`: ½ δᵀHδ − gᵀδ, H symmetric of (3k)²
/// kept as its upper triangle row by row (see [`packed`]), g of 3k.
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

/// Where row `r` of a packed symmetric matrix of `m` rows starts: its element (r, c), c ≥ r,
/// is at `packed(m, r) + c - r`.
pub(super) fn packed(m: usize, r: usize) -> usize {
    r * (2 * m + 1 - r) / 2
}

/// Eliminates the first variable of a combined factor on `vars` (`h` packed of (3k)², `g` of
/// 3k, the variable first) into `conditional`, its conditional on the rest, and `left`, the
/// factor left on the rest (both overwritten, their storage reused).
pub(super) fn eliminate_first(
    vars: &[u32],
    h: &[f64],
    g: &[f64],
    conditional: &mut Conditional,
    left: &mut Quadratic,
) -> Result<(), NotPositiveDefinite> {
    let m = 3 * vars.len();
    let at = |r: usize, c: usize| h[packed(m, r) + c - r];
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
    let (l10, l20) = (at(0, 1) / l00, at(0, 2) / l00);
    let l11 = pivot(at(1, 1) - l10 * l10)?;
    let l21 = (at(1, 2) - l20 * l10) / l11;
    let l22 = pivot(at(2, 2) - l20 * l20 - l21 * l21)?;
    let rest = m - 3;
    let s = &mut conditional.s;
    s.clear();
    s.resize(3 * rest, 0.0);
    {
        let (s0, s12) = s.split_at_mut(rest);
        let (s1, s2) = s12.split_at_mut(rest);
        let row = |r: usize| &h[packed(m, r) + 3 - r..packed(m, r + 1)];
        let (h0, h1, h2) = (row(0), row(1), row(2));
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
    left.h.clear();
    left.h.reserve(packed(rest, rest));
    left.g.clear();
    let (s0, s1, s2) = (&s[..rest], &s[rest..2 * rest], &s[2 * rest..]);
    for a in 0..rest {
        let (a0, a1, a2) = (s0[a], s1[a], s2[a]);
        left.g.push(g[3 + a] - (a0 * d[0] + a1 * d[1] + a2 * d[2]));
        let row = &h[packed(m, 3 + a)..packed(m, 4 + a)];
        left.h.extend(
            row.iter()
                .zip(&s0[a..])
                .zip(&s1[a..])
                .zip(&s2[a..])
                .map(|(((&hv, &b0), &b1), &b2)| hv - (a0 * b0 + a1 * b1 + a2 * b2)),
        );
    }
    conditional.sep.clear();
    conditional.sep.extend_from_slice(&vars[1..]);
    conditional.l = [l00, l10, l11, l20, l21, l22];
    conditional.d = d;
    Ok(())
}

/// Adds a factor (packed `fh`, `fg`) into a combined factor of `m` rows (packed `h`, `g`):
/// `slots[i]` is the combined block of the factor's i-th variable. A block that lands below
/// the diagonal is added transposed above it.
pub(super) fn add_into(
    (h, g): (&mut [f64], &mut [f64]),
    m: usize,
    slots: &[usize],
    (fh, fg): (&[f64], &[f64]),
) {
    let k = 3 * slots.len();
    let into = |r: usize, c: usize| packed(m, r) + c - r;
    for (i, &si) in slots.iter().enumerate() {
        for r in 0..3 {
            g[3 * si + r] += fg[3 * i + r];
        }
        for (j, &sj) in slots.iter().enumerate().skip(i) {
            let block = |r: usize, c: usize| fh[packed(k, 3 * i + r) + 3 * j + c - 3 * i - r];
            if i == j {
                for r in 0..3 {
                    for c in r..3 {
                        h[into(3 * si + r, 3 * si + c)] += block(r, c);
                    }
                }
            } else if si < sj {
                for r in 0..3 {
                    let at = into(3 * si + r, 3 * sj);
                    for (c, o) in h[at..at + 3].iter_mut().enumerate() {
                        *o += block(r, c);
                    }
                }
            } else {
                for c in 0..3 {
                    let at = into(3 * sj + c, 3 * si);
                    for (r, o) in h[at..at + 3].iter_mut().enumerate() {
                        *o += block(r, c);
                    }
                }
            }
        }
    }
}

/// The graph of `count` variables linked by cliques (each a run of `slots`, ended by
/// `ends`, of variables that share a factor): each variable's neighbours, once each.
pub(super) fn adjacency(count: usize, slots: &[u32], ends: &[usize]) -> Vec<Vec<u32>> {
    let mut adjacent: Vec<Vec<u32>> = vec![Vec::new(); count];
    let mut start = 0;
    for &end in ends {
        let clique = &slots[start..end];
        for &a in clique {
            adjacent[a as usize].extend(clique.iter().copied().filter(|&b| b != a));
        }
        start = end;
    }
    let mut mark = vec![u32::MAX; count];
    for (v, list) in adjacent.iter_mut().enumerate() {
        list.retain(|&b| std::mem::replace(&mut mark[b as usize], v as u32) != v as u32);
    }
    adjacent
}

/// A minimum-degree order of the graph `adjacent` (each neighbour once), the variables whose
/// `last` is true after all others. Variables wait in buckets by degree (a degree is at most
/// `count`), so the next one is found without a heap's comparisons; among equals the one
/// queued last goes first, so the order is deterministic.
pub(super) fn min_degree(mut adjacent: Vec<Vec<u32>>, last: &[bool]) -> Vec<u32> {
    let count = adjacent.len();
    let key = |v: usize, degree: usize| degree + if last[v] { count } else { 0 };
    // `mark[b] == stamp`: b is already in the list being extended.
    let (mut mark, mut stamp) = (vec![0u32; count], 0u32);
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); 2 * count];
    for (v, list) in adjacent.iter().enumerate() {
        buckets[key(v, list.len())].push(v as u32);
    }
    let mut lowest = 0;
    let mut eliminated = vec![false; count];
    let mut order = Vec::with_capacity(count);
    while lowest < buckets.len() {
        let Some(v) = buckets[lowest].pop() else {
            lowest += 1;
            continue;
        };
        let vi = v as usize;
        if eliminated[vi] || key(vi, adjacent[vi].len()) != lowest {
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
            let k = key(a as usize, list.len());
            buckets[k].push(a);
            lowest = lowest.min(k);
        }
    }
    order
}

/// An edge's quadratic on its poses other than node 0 (one or two): no heap, as an update
/// linearizes every edge of its top afresh.
#[derive(Clone, Copy, Debug)]
pub(super) struct EdgeFactor {
    vars: [u32; 2],
    len: usize,
    /// (3·len)², packed.
    h: [f64; 21],
    g: [f64; 6],
}

impl EdgeFactor {
    pub fn vars(&self) -> &[u32] {
        &self.vars[..self.len]
    }

    pub fn h(&self) -> &[f64] {
        &self.h[..packed(3 * self.len, 3 * self.len)]
    }

    pub fn g(&self) -> &[f64] {
        &self.g[..3 * self.len]
    }
}

/// An edge's quadratic at `theta` (H = JᵀΩJ, g = −JᵀΩe, the robust kernel's weight at the
/// current error folded into Ω).
pub(super) fn linearize_edge(e: &RelativeEdge, theta: &[Pose2]) -> EdgeFactor {
    let (err, ji, jj) = e.linearize(theta);
    let chi2 = err.dot(&(e.information * err));
    let omega = e.information * e.robust.weight(chi2);
    let mut f = EdgeFactor {
        vars: [0; 2],
        len: 0,
        h: [0.0; 21],
        g: [0.0; 6],
    };
    let mut jacobians = [ji; 2];
    for (v, j) in [(e.from, ji), (e.to, jj)] {
        if v != 0 {
            f.vars[f.len] = v as u32;
            jacobians[f.len] = j;
            f.len += 1;
        }
    }
    let k = 3 * f.len;
    let blocks = &jacobians[..f.len];
    for (a, ja) in blocks.iter().enumerate() {
        let oa = ja.transpose() * omega;
        let ga = -(oa * err);
        for (b, jb) in blocks.iter().enumerate().skip(a) {
            let hab = oa * jb;
            for r in 0..3 {
                for c in 0..3 {
                    let (row, col) = (3 * a + r, 3 * b + c);
                    if col >= row {
                        f.h[packed(k, row) + col - row] = hab[(r, c)];
                    }
                }
            }
        }
        for r in 0..3 {
            f.g[3 * a + r] = ga[r];
        }
    }
    f
}
