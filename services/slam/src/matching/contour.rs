//! The reference scan as IDC reads it: a polyline through its returns in bearing order, joined
//! where neighbouring returns lie on one surface (Lu & Milios interpolate the reference scan
//! between its samples). It answers the two correspondence rules for a point of the current
//! scan already moved into the reference frame:
//! - closest point: the nearest point of the polyline (used for translation);
//! - matching-range point: within a bearing window, the polyline point whose range from the
//!   reference origin equals the point's range (used for rotation).
//!
//! Both searches walk outward in bearing from the point's own bearing and stop on a bound, so
//! no uniform beam grid is assumed and no spatial index is needed: any polyline point at
//! bearing offset δ (|δ| ≤ 90°) from a point at range r is at least `r·sin|δ|` away from it,
//! and both rules drop pairs further apart than the outlier distance.

use super::scan::Scan2;
use std::f64::consts::{PI, TAU};

/// Weight of bearing against range in the matching-range rule (m of range per m of arc at
/// the point's range): 1 cm of range mismatch is worth 0.2 m of arc, 1.1° at 10 m.
const MRP_BEARING_WEIGHT: f64 = 0.001;

/// Surface normals are those of the chord across about this length of joined returns (m):
/// from neighbour to neighbour, a centimetre of range noise on returns a few centimetres
/// apart would tilt them by tens of degrees.
const NORMAL_SPAN_M: f64 = 0.4;

/// Neighbouring returns further apart in bearing than this are never joined (rad): a wider
/// gap is beams without return, not surface.
const MAX_JOIN_BEARING_RAD: f64 = 10.0 * PI / 180.0;

/// A closest-point correspondence.
#[derive(Clone, Copy, Debug)]
pub(super) struct Closest {
    /// The polyline point (reference frame, m).
    pub point: [f64; 2],
    /// Its distance to the query point (m).
    pub distance_m: f64,
    /// Unit normal of the reference surface there (see [`NORMAL_SPAN_M`]); `None` at an
    /// isolated return, where the residual has no preferred direction.
    pub normal: Option<[f64; 2]>,
    /// The point is the open end of a surface (a return joined on one side only) and the
    /// query lies beyond it: the surface may go on beyond what the reference saw, so this
    /// is no evidence for a pose, though a point this close still agrees with the reference.
    pub open_end: bool,
}

/// A point of the other scan moved into the contour's frame, with its polar coordinates.
#[derive(Clone, Copy, Debug)]
pub(super) struct Query {
    /// The point (m).
    pub point: [f64; 2],
    /// Its range from the contour's origin (m).
    pub range_m: f64,
    /// Its bearing (rad, in (−π, π]).
    pub bearing_rad: f64,
    /// The first return at or after its bearing.
    start: usize,
}

/// A matching-range correspondence.
#[derive(Clone, Copy, Debug)]
pub(super) struct RangeMatchPoint {
    /// The polyline point, at the query's range where it lies on a segment (m).
    pub point: [f64; 2],
    /// Its range (m).
    pub range_m: f64,
    /// Weight of the pair in the rotation estimate (m²): a range match says little about
    /// rotation where the range hardly changes with bearing (a wall seen square on).
    pub weight: f64,
}

/// The reference scan with its joins and a bearing lookup table.
pub(super) struct Contour<'a> {
    points: &'a [[f64; 2]],
    bearings: &'a [f64],
    ranges: &'a [f64],
    /// `joined[i]`: the segment from return i to return (i + 1) mod n lies on one surface.
    joined: Vec<bool>,
    /// Surface normal at each return; `None` for an isolated return.
    normals: Vec<Option<[f64; 2]>>,
    /// `buckets[k]`: the first return whose bearing is ≥ −π + k·2π/len (len = buckets.len()).
    buckets: Vec<u32>,
}

impl<'a> Contour<'a> {
    /// Joins returns i and i + 1 when they are at most `join_distance_m +
    /// join_distance_per_m · range` apart (range: the nearer of the two), and no more than
    /// [`MAX_JOIN_BEARING_RAD`] apart in bearing. The last return joins the first only when
    /// the scan closes the circle that way.
    pub fn new(scan: &'a Scan2, join_distance_m: f64, join_distance_per_m: f64) -> Contour<'a> {
        let mut contour = Contour::outline(scan, join_distance_m, join_distance_per_m);
        contour.normals = (0..contour.len())
            .map(|j| surface_normal(contour.points, &contour.joined, j))
            .collect();
        contour
    }

    /// The contour without surface normals, for distances only (`distance_within`,
    /// `min_range_near`): cheaper to build.
    pub fn outline(scan: &'a Scan2, join_distance_m: f64, join_distance_per_m: f64) -> Contour<'a> {
        let (points, bearings, ranges) = (scan.points(), scan.bearings_rad(), scan.ranges_m());
        let n = points.len();
        let joined: Vec<bool> = (0..n)
            .map(|i| {
                let j = (i + 1) % n;
                let gap = bearing_offset(bearings[i], bearings[j]);
                let limit = join_distance_m + join_distance_per_m * ranges[i].min(ranges[j]);
                n > 1
                    && (0.0..=MAX_JOIN_BEARING_RAD).contains(&gap)
                    && dist2(points[i], points[j]) <= limit * limit
            })
            .collect();
        let normals = vec![None; n];
        let len = (2 * n).max(64);
        let mut buckets = Vec::with_capacity(len);
        let mut i = 0;
        for k in 0..len {
            let lower = -PI + TAU * k as f64 / len as f64;
            while i < n && bearings[i] < lower {
                i += 1;
            }
            buckets.push(i as u32);
        }
        Contour {
            points,
            bearings,
            ranges,
            joined,
            normals,
            buckets,
        }
    }

    /// The returns (m, in the scan's frame), in bearing order.
    pub fn points(&self) -> &[[f64; 2]] {
        self.points
    }

    /// Number of returns.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Locates a point (in this contour's frame) by bearing; `None` at the origin.
    pub fn query(&self, point: [f64; 2]) -> Option<Query> {
        let range_m = (point[0] * point[0] + point[1] * point[1]).sqrt();
        if range_m.is_nan() || range_m <= 0.0 {
            return None;
        }
        let bearing_rad = point[1].atan2(point[0]);
        Some(Query {
            point,
            range_m,
            bearing_rad,
            start: self.position(bearing_rad),
        })
    }

    /// Index of the first return at or after `bearing` going counter-clockwise (wrapping to 0).
    fn position(&self, bearing: f64) -> usize {
        let n = self.len();
        let len = self.buckets.len();
        let k = (((bearing + PI) / TAU * len as f64) as usize).min(len - 1);
        let mut i = self.buckets[k] as usize;
        while i < n && self.bearings[i] < bearing {
            i += 1;
        }
        if i == n { 0 } else { i }
    }

    /// The closest point of the polyline to the query, if one is within `max_distance_m`.
    pub fn closest(&self, query: &Query, max_distance_m: f64) -> Option<Closest> {
        let n = self.len();
        let q = query.point;
        let mut best = Best {
            d2: max_distance_m * max_distance_m,
            hit: None,
        };
        // Right (counter-clockwise): at each return, first the segment that leads to it.
        let mut visited = 0;
        for k in 0..n {
            let j = wrap_index(query.start + k, n);
            let i = if j == 0 { n - 1 } else { j - 1 };
            if self.joined[i] {
                self.try_segment(q, i, &mut best);
            }
            if self.beyond(query, j, best.d2) {
                break;
            }
            self.try_return(q, j, &mut best);
            visited += 1;
        }
        // Left (clockwise), over the returns the right walk did not reach.
        for k in 0..n.saturating_sub(visited) {
            let j = wrap_index(query.start + n - 1 - k, n);
            if k > 0 && self.joined[j] {
                self.try_segment(q, j, &mut best);
            }
            if self.beyond(query, j, best.d2) {
                break;
            }
            self.try_return(q, j, &mut best);
        }
        let distance_m = best.d2.sqrt();
        Some(match best.hit? {
            Hit::Segment { point, segment, s } => Closest {
                point,
                distance_m,
                normal: self.blended_normal(segment, s),
                open_end: false,
            },
            Hit::Return(j) => Closest {
                point: self.points[j],
                distance_m,
                normal: self.normals[j],
                open_end: self.joined[(j + n - 1) % n] != self.joined[j],
            },
        })
    }

    /// The distance from the query to the polyline, if within `max_distance_m`.
    pub fn distance_within(&self, query: &Query, max_distance_m: f64) -> Option<f64> {
        self.closest(query, max_distance_m).map(|c| c.distance_m)
    }

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
            if self.joined[i] {
                self.try_range(i, query, window, weight, &mut best);
            }
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
            if k > 0 && self.joined[j] {
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

    /// The smallest range among the returns within `window_rad` of the query's bearing: how
    /// far the scan saw free space around that bearing. `None` when it has no return there
    /// (outside its field of view, or no echo).
    pub fn min_range_near(&self, query: &Query, window_rad: f64) -> Option<f64> {
        let n = self.len();
        let mut min: Option<f64> = None;
        let mut visited = 0;
        for k in 0..n {
            let j = wrap_index(query.start + k, n);
            if !(0.0..=window_rad).contains(&bearing_offset(query.bearing_rad, self.bearings[j])) {
                break;
            }
            min = Some(min.map_or(self.ranges[j], |m| m.min(self.ranges[j])));
            visited += 1;
        }
        for k in 0..n.saturating_sub(visited) {
            let j = wrap_index(query.start + n - 1 - k, n);
            if !(0.0..=window_rad).contains(&bearing_offset(self.bearings[j], query.bearing_rad)) {
                break;
            }
            min = Some(min.map_or(self.ranges[j], |m| m.min(self.ranges[j])));
        }
        min
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

    fn try_return(&self, q: [f64; 2], j: usize, best: &mut Best) {
        let d2 = dist2(q, self.points[j]);
        if d2 < best.d2 {
            *best = Best {
                d2,
                hit: Some(Hit::Return(j)),
            };
        }
    }

    /// The projection of `q` on segment i → i + 1, when it falls strictly inside (the ends
    /// are returns, tried on their own).
    fn try_segment(&self, q: [f64; 2], i: usize, best: &mut Best) {
        let j = if i + 1 == self.len() { 0 } else { i + 1 };
        let (a, b) = (self.points[i], self.points[j]);
        let ab = [b[0] - a[0], b[1] - a[1]];
        let aq = [q[0] - a[0], q[1] - a[1]];
        let len2 = ab[0] * ab[0] + ab[1] * ab[1];
        let along = aq[0] * ab[0] + aq[1] * ab[1];
        // Outside the segment (or a segment of length 0): its ends are tried on their own.
        if along <= 0.0 || along >= len2 {
            return;
        }
        // Squared distance to the line, cross² / len2, compared before dividing.
        let cross = aq[0] * ab[1] - aq[1] * ab[0];
        if cross * cross >= best.d2 * len2 {
            return;
        }
        let s = along / len2;
        let point = [a[0] + s * ab[0], a[1] + s * ab[1]];
        let hit = Some(Hit::Segment {
            point,
            segment: i,
            s,
        });
        *best = Best {
            d2: cross * cross / len2,
            hit,
        };
    }

    /// The surface normal at fraction s of segment i → i + 1: both ends are joined, so both
    /// have normals; blended along the segment.
    fn blended_normal(&self, i: usize, s: f64) -> Option<[f64; 2]> {
        let j = if i + 1 == self.len() { 0 } else { i + 1 };
        let (na, nb) = (
            self.normals[i].unwrap_or_default(),
            self.normals[j].unwrap_or_default(),
        );
        unit([(1.0 - s) * na[0] + s * nb[0], (1.0 - s) * na[1] + s * nb[1]])
            .or_else(|| unit_normal(self.points[i], self.points[j]))
    }

    /// On segment i → i + 1, the bearing where the linearly interpolated range is the
    /// query's, if the segment spans that range and the bearing is within `window_rad`.
    fn try_range(
        &self,
        i: usize,
        query: &Query,
        window_rad: f64,
        weight: f64,
        best: &mut RangeMatch,
    ) {
        let j = if i + 1 == self.len() { 0 } else { i + 1 };
        let (ra, rb, r_q) = (self.ranges[i], self.ranges[j], query.range_m);
        if r_q < ra.min(rb) || r_q > ra.max(rb) {
            return;
        }
        let s = if rb == ra {
            0.5
        } else {
            (r_q - ra) / (rb - ra)
        };
        let bearing =
            wrap(self.bearings[i] + s * bearing_offset(self.bearings[i], self.bearings[j]));
        let offset = bearing_offset(query.bearing_rad, bearing).abs();
        if offset <= window_rad {
            best.consider(weight * offset, RangeAt::Segment { segment: i, s });
        }
    }
}

struct Best {
    d2: f64,
    hit: Option<Hit>,
}

enum Hit {
    Return(usize),
    /// At fraction s of segment i → i + 1.
    Segment {
        point: [f64; 2],
        segment: usize,
        s: f64,
    },
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

/// `i mod n` for `i < 2n`, without a division.
fn wrap_index(i: usize, n: usize) -> usize {
    if i >= n { i - n } else { i }
}

/// An angle brought into (−π, π], for angles at most one turn outside.
fn wrap(a: f64) -> f64 {
    if a > PI {
        a - TAU
    } else if a <= -PI {
        a + TAU
    } else {
        a
    }
}

/// `to − from` as an angle in (−π, π] (rad); both inputs in (−π, π].
fn bearing_offset(from: f64, to: f64) -> f64 {
    wrap(to - from)
}

/// The normal at return j: of the chord between the joined returns about
/// `NORMAL_SPAN_M / 2` before and after it (fewer where the surface ends).
fn surface_normal(points: &[[f64; 2]], joined: &[bool], j: usize) -> Option<[f64; 2]> {
    let n = points.len();
    let half2 = (NORMAL_SPAN_M / 2.0).powi(2);
    let (mut lo, mut hi) = (j, j);
    for _ in 0..n {
        let prev = (lo + n - 1) % n;
        if !joined[prev] || prev == hi || dist2(points[lo], points[j]) >= half2 {
            break;
        }
        lo = prev;
    }
    for _ in 0..n {
        let next = (hi + 1) % n;
        if !joined[hi] || next == lo || dist2(points[hi], points[j]) >= half2 {
            break;
        }
        hi = next;
    }
    if lo == hi {
        None
    } else {
        unit_normal(points[lo], points[hi])
    }
}

/// The unit normal of the line from a to b (to the left), if they differ.
fn unit_normal(a: [f64; 2], b: [f64; 2]) -> Option<[f64; 2]> {
    unit([a[1] - b[1], b[0] - a[0]])
}

fn unit(v: [f64; 2]) -> Option<[f64; 2]> {
    let len = (v[0] * v[0] + v[1] * v[1]).sqrt();
    (len > 1e-12).then(|| [v[0] / len, v[1] / len])
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall x = 2 seen from the origin, one return per degree from −40° to 40°.
    fn wall() -> Scan2 {
        let bearings: Vec<f32> = (-40..=40).map(|d| (d as f32).to_radians()).collect();
        let ranges: Vec<f32> = bearings.iter().map(|b| 2.0 / b.cos()).collect();
        Scan2::from_polar(&bearings, &ranges, 50.0).expect("same lengths")
    }

    #[test]
    fn closest_point_projects_on_the_wall() {
        let scan = wall();
        let contour = Contour::new(&scan, 0.3, 0.05);
        let query = contour.query([2.1, 0.3]).expect("not the origin");
        let c = contour.closest(&query, 0.5).expect("near the wall");
        // Returns come from f32 beams: agree to f32 precision.
        assert!((c.point[0] - 2.0).abs() < 1e-5 && (c.point[1] - 0.3).abs() < 1e-5);
        assert!((c.distance_m - 0.1).abs() < 1e-5);
        let n = c.normal.expect("inside a segment");
        assert!(n[0].abs() > 0.999);
        assert!(contour.closest(&query, 0.05).is_none());
    }

    #[test]
    fn beyond_the_end_of_a_surface_is_an_open_end() {
        let scan = wall();
        let contour = Contour::new(&scan, 0.3, 0.05);
        // The wall was seen up to y = 2·tan 40° ≈ 1.68 m; this point is past its end.
        let query = contour.query([2.0, 1.75]).expect("not the origin");
        assert!(contour.closest(&query, 0.5).expect("near the end").open_end);
        // A point beside the wall, at a return: the normal is the wall's.
        let query = contour
            .query([2.05, 2.0 * 10f64.to_radians().tan()])
            .expect("not the origin");
        let c = contour.closest(&query, 0.5).expect("near the wall");
        assert!(!c.open_end && c.normal.is_some_and(|n| n[0].abs() > 0.999));
    }

    #[test]
    fn matching_range_point_has_the_same_range_nearest_in_bearing() {
        let scan = wall();
        let contour = Contour::new(&scan, 0.3, 0.05);
        // A point rotated 2° away from the wall point at 10°: same range, bearing 12°.
        let r = 2.0 / 10f64.to_radians().cos();
        let (s, c) = 12f64.to_radians().sin_cos();
        let query = contour.query([r * c, r * s]).expect("not the origin");
        let m = contour
            .matching_range(&query, 0.1, 0.5)
            .expect("in window")
            .point;
        assert!((m[0].hypot(m[1]) - r).abs() < 1e-5);
        let bearing = m[1].atan2(m[0]);
        assert!(
            (bearing - 10f64.to_radians()).abs() < 1e-3,
            "bearing {}",
            bearing.to_degrees()
        );
        // With an outlier distance of 5 cm the exact point, 7 cm away, is out of reach: a
        // return nearer in bearing, close in range, stands in.
        let m = contour
            .matching_range(&query, 0.1, 0.05)
            .expect("in reach")
            .point;
        assert!((m[1].atan2(m[0]) - 12f64.to_radians()).abs() < 1.5f64.to_radians());
    }

    #[test]
    fn min_range_near_sees_free_space_and_the_field_of_view() {
        let scan = wall();
        let contour = Contour::new(&scan, 0.3, 0.05);
        let ahead = contour.query([1.0, 0.0]).expect("not the origin");
        let near = contour.min_range_near(&ahead, 0.02).expect("in view");
        assert!((near - 2.0).abs() < 1e-3);
        let behind = contour.query([-1.0, 0.1]).expect("not the origin");
        assert!(contour.min_range_near(&behind, 0.02).is_none());
    }
}
