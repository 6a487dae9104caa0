//! One re-elimination of the top: the edges among it linearized, the orphans' factors
//! taken as they were left, a minimum-degree order with the update's poses last, and the
//! poses eliminated one at a time into their conditionals.

use super::eliminate::{
    EdgeFactor, add_into, adjacency, eliminate_first, linearize_edge, min_degree, packed,
};
use super::{IncrementalSmoother, NONE, SmootherError, UpdateStats};

/// The buffers of one re-elimination, kept so that an update allocates nothing once the
/// smoother has seen an update as large.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    fresh: Vec<EdgeFactor>,
    sources: Vec<Source>,
    /// Each source's poses as top slots, one after another; `clique_ends[i]` ends source i.
    clique_slots: Vec<u32>,
    clique_ends: Vec<usize>,
    is_last: Vec<bool>,
    /// `on[slot]`: the live sources on the top pose in `slot`.
    on: Vec<Vec<usize>>,
    alive: Vec<bool>,
    /// The combined factor of the pose being eliminated.
    h: Vec<f64>,
    g: Vec<f64>,
    vars: Vec<u32>,
    slots: Vec<usize>,
    /// `place[slot] = (k, i)`: the top pose in `slot` is the i-th of the combined factor of
    /// the k-th elimination.
    place: Vec<(u32, u32)>,
    here: Vec<usize>,
}

/// A factor of one elimination: a fresh linearization of an edge, or what a pose left.
#[derive(Clone, Copy, Debug)]
enum Source {
    Edge(usize),
    Left(u32),
}

impl IncrementalSmoother {
    /// Removes the top above `affected`, eliminates it again with `last` at the end, and
    /// solves; returns the poses whose step was recomputed.
    pub(super) fn reeliminate(
        &mut self,
        affected: &[u32],
        last: &[u32],
        stats: &mut UpdateStats,
    ) -> Result<Vec<u32>, SmootherError> {
        stats.rounds += 1;
        let stamp = self.next_stamp();
        let top = self.remove_top(affected, stamp);
        let mut orphans = Vec::new();
        for &t in &top {
            let kids = std::mem::take(&mut self.children[t as usize]);
            orphans.extend(
                kids.into_iter()
                    .filter(|&c| self.work.mark[c as usize] != stamp),
            );
        }
        for (i, &t) in top.iter().enumerate() {
            self.work.slot[t as usize] = i as u32;
        }
        let mut x = std::mem::take(&mut self.work.elimination);
        self.linearize_top(&top, stamp, &mut x.fresh);
        x.sources.clear();
        x.sources.extend((0..x.fresh.len()).map(Source::Edge));
        x.sources.extend(orphans.iter().map(|&w| Source::Left(w)));
        x.clique_slots.clear();
        x.clique_ends.clear();
        for source in &x.sources {
            let vars = match *source {
                Source::Edge(i) => x.fresh[i].vars(),
                Source::Left(w) => &self.conditionals[w as usize].sep,
            };
            x.clique_slots
                .extend(vars.iter().map(|&v| self.work.slot[v as usize]));
            x.clique_ends.push(x.clique_slots.len());
        }
        x.is_last.clear();
        x.is_last.resize(top.len(), false);
        for &v in last {
            if self.work.mark[v as usize] == stamp {
                x.is_last[self.work.slot[v as usize] as usize] = true;
            }
        }
        let adjacent = adjacency(top.len(), &x.clique_slots, &x.clique_ends);
        let order: Vec<u32> = min_degree(adjacent, &x.is_last)
            .into_iter()
            .map(|i| top[i as usize])
            .collect();
        let eliminated = self.eliminate_in_order(&order, &mut x);
        self.work.elimination = x;
        eliminated?;
        stats.eliminated += order.len();
        for &v in order.iter().chain(&orphans) {
            let p = self.conditionals[v as usize]
                .sep
                .iter()
                .copied()
                .min_by_key(|&u| self.position[u as usize])
                .unwrap_or(NONE);
            self.parent[v as usize] = p;
            if p != NONE {
                self.children[p as usize].push(v);
            }
        }
        let solved = self.solve_down(&order, stamp);
        stats.solved += solved.len();
        Ok(solved)
    }

    /// Marks `affected` and every ancestor; returns them.
    fn remove_top(&mut self, affected: &[u32], stamp: u32) -> Vec<u32> {
        let mut top = Vec::new();
        for &a in affected {
            let mut v = a;
            while v != NONE && self.work.mark[v as usize] != stamp {
                self.work.mark[v as usize] = stamp;
                top.push(v);
                v = self.parent[v as usize];
            }
        }
        top
    }

    /// The edges whose every pose is in the top, linearized at the current points: each as
    /// its poses (node 0 left out: it is held) and its quadratic.
    fn linearize_top(&mut self, top: &[u32], stamp: u32, fresh: &mut Vec<EdgeFactor>) {
        self.work.edge_mark.resize(self.edges.len(), 0);
        fresh.clear();
        for &t in top {
            for &k in &self.edges_of[t as usize] {
                let k = k as usize;
                if self.work.edge_mark[k] == stamp {
                    continue;
                }
                let e = &self.edges[k];
                let in_top = |v: usize| v == 0 || self.work.mark[v] == stamp;
                if !(in_top(e.from) && in_top(e.to)) {
                    continue;
                }
                self.work.edge_mark[k] = stamp;
                fresh.push(linearize_edge(e, &self.theta));
            }
        }
    }

    fn eliminate_in_order(&mut self, order: &[u32], x: &mut Scratch) -> Result<(), SmootherError> {
        let top_len = order.len();
        if x.on.len() < top_len {
            x.on.resize(top_len, Vec::new());
        }
        x.on[..top_len].iter_mut().for_each(Vec::clear);
        let mut start = 0;
        for (i, &end) in x.clique_ends.iter().enumerate() {
            for &local in &x.clique_slots[start..end] {
                x.on[local as usize].push(i);
            }
            start = end;
        }
        x.alive.clear();
        x.alive.resize(x.sources.len(), true);
        x.place.clear();
        x.place.resize(top_len, (u32::MAX, 0));
        for (k, &v) in order.iter().enumerate() {
            let k = k as u32;
            self.position[v as usize] = self.next_position;
            self.next_position += 1;
            let local = self.work.slot[v as usize] as usize;
            x.here.clear();
            x.here
                .extend(x.on[local].iter().copied().filter(|&i| x.alive[i]));
            x.vars.clear();
            x.vars.push(v);
            x.place[local] = (k, 0);
            for &i in &x.here {
                x.alive[i] = false;
                let factor_vars = match x.sources[i] {
                    Source::Edge(f) => x.fresh[f].vars(),
                    Source::Left(w) => &self.conditionals[w as usize].sep,
                };
                for &u in factor_vars {
                    let at = &mut x.place[self.work.slot[u as usize] as usize];
                    if at.0 != k {
                        *at = (k, x.vars.len() as u32);
                        x.vars.push(u);
                    }
                }
            }
            let m = 3 * x.vars.len();
            x.h.clear();
            x.h.resize(packed(m, m), 0.0);
            x.g.clear();
            x.g.resize(m, 0.0);
            for &i in &x.here {
                let (factor_vars, factor) = match x.sources[i] {
                    Source::Edge(f) => {
                        let f = &x.fresh[f];
                        (f.vars(), (f.h(), f.g()))
                    }
                    Source::Left(w) => {
                        let left = &self.left[w as usize];
                        (
                            &self.conditionals[w as usize].sep[..],
                            (&left.h[..], &left.g[..]),
                        )
                    }
                };
                x.slots.clear();
                x.slots.extend(
                    factor_vars
                        .iter()
                        .map(|&u| x.place[self.work.slot[u as usize] as usize].1 as usize),
                );
                add_into((&mut x.h, &mut x.g), m, &x.slots, factor);
            }
            eliminate_first(
                &x.vars,
                &x.h,
                &x.g,
                &mut self.conditionals[v as usize],
                &mut self.left[v as usize],
            )
            .map_err(|_| SmootherError::Unconstrained(v as usize))?;
            if x.vars.len() > 1 {
                let id = x.sources.len();
                x.sources.push(Source::Left(v));
                x.alive.push(true);
                for &u in &x.vars[1..] {
                    x.on[self.work.slot[u as usize] as usize].push(id);
                }
            }
        }
        Ok(())
    }
}
