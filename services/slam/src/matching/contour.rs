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

mod closest;
mod geometry;
mod range;

use super::scan::Scan2;
use geometry::{bearing_offset, dist2, surface_normal, wrap_index};
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

/// What the searches read of a segment a → b of the polyline.
#[derive(Clone, Copy, Debug)]
struct Segment {
    /// b − a (m); zero where a and b are not joined, which no projection falls inside.
    ab: [f64; 2],
    /// |b − a|² (m²).
    len2: f64,
    /// The smaller and the larger range of a and b (m); an empty interval (+∞, −∞) where
    /// not joined, which no range falls inside.
    range_lo: f64,
    range_hi: f64,
    /// Bearing from a to b (rad), `bearing_offset(bearing a, bearing b)`.
    gap: f64,
}

impl Segment {
    fn new(scan: &Scan2, i: usize, j: usize, joined: bool) -> Segment {
        let (points, bearings, ranges) = (scan.points(), scan.bearings_rad(), scan.ranges_m());
        if !joined {
            return Segment {
                ab: [0.0; 2],
                len2: 0.0,
                range_lo: f64::INFINITY,
                range_hi: f64::NEG_INFINITY,
                gap: 0.0,
            };
        }
        let (a, b) = (points[i], points[j]);
        let ab = [b[0] - a[0], b[1] - a[1]];
        Segment {
            ab,
            len2: ab[0] * ab[0] + ab[1] * ab[1],
            range_lo: ranges[i].min(ranges[j]),
            range_hi: ranges[i].max(ranges[j]),
            gap: bearing_offset(bearings[i], bearings[j]),
        }
    }
}

/// The reference scan with its joins and a bearing lookup table.
pub(super) struct Contour<'a> {
    points: &'a [[f64; 2]],
    bearings: &'a [f64],
    ranges: &'a [f64],
    /// `joined[i]`: the segment from return i to return (i + 1) mod n lies on one surface.
    joined: Vec<bool>,
    /// `segments[i]`: segment i → (i + 1) mod n as both searches read it, computed once
    /// rather than per query; empty where not joined, so the walks need not test `joined`.
    segments: Vec<Segment>,
    /// Surface normal at each return; `None` for an isolated return.
    normals: Vec<Option<[f64; 2]>>,
    /// `buckets[k]`: the first return whose [`bucket`] is ≥ k.
    buckets: Vec<u32>,
    /// buckets.len() / 2π.
    bucket_scale: f64,
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
        let segments = (0..n)
            .map(|i| Segment::new(scan, i, (i + 1) % n, joined[i]))
            .collect();
        let normals = vec![None; n];
        let len = (2 * n).max(64);
        let bucket_scale = len as f64 / TAU;
        let mut buckets = Vec::with_capacity(len);
        let mut i = 0;
        for k in 0..len {
            while i < n && bucket(bearings[i], bucket_scale, len) < k {
                i += 1;
            }
            buckets.push(i as u32);
        }
        Contour {
            points,
            bearings,
            ranges,
            joined,
            segments,
            normals,
            buckets,
            bucket_scale,
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
        let k = bucket(bearing, self.bucket_scale, self.buckets.len());
        let mut i = self.buckets[k] as usize;
        while i < n && self.bearings[i] < bearing {
            i += 1;
        }
        if i == n { 0 } else { i }
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
}

/// The bucket of a bearing among `len`, by multiplication (no division per query). It never
/// decreases with the bearing, so every return before `buckets[k]` lies before the bearing.
fn bucket(bearing: f64, scale: f64, len: usize) -> usize {
    (((bearing + PI) * scale) as usize).min(len - 1)
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
