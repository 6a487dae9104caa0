//! The closest-point rule: the nearest point of the polyline to a query, with the surface
//! normal there.

use super::geometry::{dist2, unit, unit_normal, wrap_index};
use super::{Closest, Contour, Query};

impl Contour<'_> {
    /// The closest point of the polyline to the query, if one is within `max_distance_m`.
    pub fn closest(&self, query: &Query, max_distance_m: f64) -> Option<Closest> {
        let n = self.len();
        let q = query.point;
        let mut best = Best {
            d2: max_distance_m * max_distance_m,
            at: usize::MAX,
            on_segment: false,
            s: 0.0,
        };
        // Right (counter-clockwise): at each return, first the segment that leads to it.
        let mut visited = 0;
        for k in 0..n {
            let j = wrap_index(query.start + k, n);
            let i = if j == 0 { n - 1 } else { j - 1 };
            self.try_segment(q, i, &mut best);
            if self.beyond(query, j, best.d2) {
                break;
            }
            self.try_return(q, j, &mut best);
            visited += 1;
        }
        // Left (clockwise), over the returns the right walk did not reach.
        for k in 0..n.saturating_sub(visited) {
            let j = wrap_index(query.start + n - 1 - k, n);
            if k > 0 {
                self.try_segment(q, j, &mut best);
            }
            if self.beyond(query, j, best.d2) {
                break;
            }
            self.try_return(q, j, &mut best);
        }
        if best.at == usize::MAX {
            return None;
        }
        let distance_m = best.d2.sqrt();
        let j = best.at;
        Some(if best.on_segment {
            let (a, ab) = (self.points[j], self.segments[j].ab);
            Closest {
                point: [a[0] + best.s * ab[0], a[1] + best.s * ab[1]],
                distance_m,
                normal: self.blended_normal(j, best.s),
                open_end: false,
            }
        } else {
            let before = if j == 0 { n - 1 } else { j - 1 };
            Closest {
                point: self.points[j],
                distance_m,
                normal: self.normals[j],
                open_end: self.joined[before] != self.joined[j],
            }
        })
    }

    /// The distance from the query to the polyline, if within `max_distance_m`.
    pub fn distance_within(&self, query: &Query, max_distance_m: f64) -> Option<f64> {
        self.closest(query, max_distance_m).map(|c| c.distance_m)
    }

    /// Whether every polyline point at the bearing of return j or further from the query's
    /// bearing is more than √d2 from the query. The bound is `r·sin δ` (δ: bearing offset,
    /// r: the query's range), or r past a right angle; compared squared, without division.
    fn beyond(&self, query: &Query, j: usize, d2: f64) -> bool {
        let (q, p) = (query.point, self.points[j]);
        if q[0] * p[0] + q[1] * p[1] <= 0.0 {
            return query.range_m * query.range_m > d2;
        }
        let cross = q[0] * p[1] - q[1] * p[0];
        cross * cross > d2 * self.ranges[j] * self.ranges[j]
    }

    /// Branch-free: whether a return beats the best is as often yes as no.
    #[inline(always)]
    fn try_return(&self, q: [f64; 2], j: usize, best: &mut Best) {
        let d2 = dist2(q, self.points[j]);
        let better = d2 < best.d2;
        best.d2 = if better { d2 } else { best.d2 };
        best.at = if better { j } else { best.at };
        best.on_segment &= !better;
    }

    /// The projection of `q` on segment i → i + 1, when it falls strictly inside (the ends
    /// are returns, tried on their own; an unjoined segment is empty).
    #[inline(always)]
    fn try_segment(&self, q: [f64; 2], i: usize, best: &mut Best) {
        let (a, seg) = (self.points[i], &self.segments[i]);
        let (ab, len2) = (seg.ab, seg.len2);
        let aq = [q[0] - a[0], q[1] - a[1]];
        let along = aq[0] * ab[0] + aq[1] * ab[1];
        // Squared distance to the line, cross² / len2, compared before dividing.
        let cross = aq[0] * ab[1] - aq[1] * ab[0];
        // Inside the segment (not at or past an end, not of length 0) and nearer than the
        // best: one branch, rarely taken, instead of three hard to predict.
        let nearer = (along > 0.0) & (along < len2) & (cross * cross < best.d2 * len2);
        if !nearer {
            return;
        }
        *best = Best {
            d2: cross * cross / len2,
            at: i,
            on_segment: true,
            s: along / len2,
        };
    }

    /// The surface normal at fraction s of segment i → i + 1: both ends are joined, so both
    /// have normals; blended along the segment.
    #[inline(always)]
    pub(super) fn blended_normal(&self, i: usize, s: f64) -> Option<[f64; 2]> {
        let j = if i + 1 == self.len() { 0 } else { i + 1 };
        let (na, nb) = (
            self.normals[i].unwrap_or_default(),
            self.normals[j].unwrap_or_default(),
        );
        unit([(1.0 - s) * na[0] + s * nb[0], (1.0 - s) * na[1] + s * nb[1]])
            .or_else(|| unit_normal(self.points[i], self.points[j]))
    }
}

/// The nearest candidate so far: return `at`, or the point at fraction `s` of segment
/// `at` → `at` + 1 when `on_segment`; `at` is `usize::MAX` while there is none.
struct Best {
    d2: f64,
    at: usize,
    on_segment: bool,
    s: f64,
}
