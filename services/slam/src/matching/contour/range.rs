//! The matching-range rule: within a bearing window, the polyline point at the query's
//! range from the reference origin.

use super::geometry::{bearing_offset, wrap, wrap_index};
use super::{Contour, MRP_BEARING_WEIGHT, Query, RangeMatchPoint};
use std::f64::consts::PI;

impl Contour<'_> {
    /// The matching-range point of the query: within `window_rad` of its bearing and
    /// `max_distance_m` of it, the polyline point whose range best matches the query's,
    /// nearest in bearing among equally good ones. "Best" is the cost `|Δrange| +
    /// MRP_BEARING_WEIGHT · range · |Δbearing|`: an exact range far off in bearing must not
    /// beat a return a millimetre off next to the point, which happens at every local
    /// extremum of the range (corners, the foot of a wall) under noise.
    pub fn matching_range(
        &self,
        query: &Query,
        window_rad: f64,
        max_distance_m: f64,
    ) -> Option<RangeMatchPoint> {
        let n = self.len();
        let r_q = query.range_m;
        let weight = MRP_BEARING_WEIGHT * r_q;
        // A bearing offset beyond asin(d / r) puts any candidate further than the outlier
        // distance d; d / r is a hair smaller, and costs no arcsine.
        let reach = if max_distance_m < r_q {
            max_distance_m / r_q
        } else {
            PI
        };
        let window = window_rad.min(reach);
        // A candidate whose range alone is off by the outlier distance is no candidate.
        let mut best = RangeMatch {
            cost: max_distance_m,
            at: None,
        };
        let mut visited = 0;
        for k in 0..n {
            let j = wrap_index(query.start + k, n);
            let offset = bearing_offset(query.bearing_rad, self.bearings[j]);
            let i = if j == 0 { n - 1 } else { j - 1 };
            self.try_range(i, query, window, weight, &mut best);
            if !(0.0..=window).contains(&offset) || weight * offset > best.cost {
                break;
            }
            best.consider(
                (self.ranges[j] - r_q).abs() + weight * offset,
                RangeAt::Return(j),
            );
            visited += 1;
        }
        for k in 0..n.saturating_sub(visited) {
            let j = wrap_index(query.start + n - 1 - k, n);
            let offset = bearing_offset(self.bearings[j], query.bearing_rad);
            if k > 0 {
                self.try_range(j, query, window, weight, &mut best);
            }
            if !(0.0..=window).contains(&offset) || weight * offset > best.cost {
                break;
            }
            best.consider(
                (self.ranges[j] - r_q).abs() + weight * offset,
                RangeAt::Return(j),
            );
        }
        let (point, range_m, normal) = match best.at? {
            RangeAt::Return(j) => (self.points[j], self.ranges[j], self.normals[j]),
            RangeAt::Segment { segment, s } => {
                // At the query's range, in the direction of the chord point at the same
                // fraction: within a small part of the beam spacing of the interpolated
                // bearing, and no trigonometry.
                let j = if segment + 1 == n { 0 } else { segment + 1 };
                let (a, b) = (self.points[segment], self.points[j]);
                let u = [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])];
                let scale = r_q / (u[0] * u[0] + u[1] * u[1]).sqrt();
                (
                    [u[0] * scale, u[1] * scale],
                    r_q,
                    self.blended_normal(segment, s),
                )
            }
        };
        // Rotation information of the pair: how far a small turn about the origin moves the
        // point across the surface, (n · perp(q))²; in full (r²) at an isolated return.
        let weight = match normal {
            Some(n) => (n[1] * query.point[0] - n[0] * query.point[1]).powi(2),
            None => r_q * r_q,
        };
        Some(RangeMatchPoint {
            point,
            range_m,
            weight,
        })
    }

    /// On segment i → i + 1, the bearing where the linearly interpolated range is the
    /// query's, if the segment spans that range (an unjoined one spans none) and the
    /// bearing is within `window_rad`.
    #[inline(always)]
    fn try_range(
        &self,
        i: usize,
        query: &Query,
        window_rad: f64,
        weight: f64,
        best: &mut RangeMatch,
    ) {
        let (seg, r_q) = (&self.segments[i], query.range_m);
        if r_q < seg.range_lo || r_q > seg.range_hi {
            return;
        }
        let j = if i + 1 == self.len() { 0 } else { i + 1 };
        let (ra, rb) = (self.ranges[i], self.ranges[j]);
        let s = if rb == ra {
            0.5
        } else {
            (r_q - ra) / (rb - ra)
        };
        let bearing = wrap(self.bearings[i] + s * seg.gap);
        let offset = bearing_offset(query.bearing_rad, bearing).abs();
        if offset <= window_rad {
            best.consider(weight * offset, RangeAt::Segment { segment: i, s });
        }
    }
}

/// The best matching-range candidate so far.
struct RangeMatch {
    cost: f64,
    at: Option<RangeAt>,
}

enum RangeAt {
    /// A return of the reference.
    Return(usize),
    /// The point at the query's range at fraction s of segment i → i + 1.
    Segment { segment: usize, s: f64 },
}

impl RangeMatch {
    fn consider(&mut self, cost: f64, at: RangeAt) {
        if cost < self.cost {
            *self = RangeMatch { cost, at: Some(at) };
        }
    }
}
