//! Plane geometry of the contour: angle wrapping, index wrapping, surface normals.

use super::NORMAL_SPAN_M;
use std::f64::consts::{PI, TAU};

/// `i mod n` for `i < 2n`, without a division.
pub(super) fn wrap_index(i: usize, n: usize) -> usize {
    if i >= n { i - n } else { i }
}

/// An angle brought into (−π, π], for angles at most one turn outside.
pub(super) fn wrap(a: f64) -> f64 {
    if a > PI {
        a - TAU
    } else if a <= -PI {
        a + TAU
    } else {
        a
    }
}

/// `to − from` as an angle in (−π, π] (rad); both inputs in (−π, π].
pub(super) fn bearing_offset(from: f64, to: f64) -> f64 {
    wrap(to - from)
}

/// The normal at return j: of the chord between the joined returns about
/// `NORMAL_SPAN_M / 2` before and after it (fewer where the surface ends).
pub(super) fn surface_normal(points: &[[f64; 2]], joined: &[bool], j: usize) -> Option<[f64; 2]> {
    let n = points.len();
    let half2 = (NORMAL_SPAN_M / 2.0).powi(2);
    let (mut lo, mut hi) = (j, j);
    for _ in 0..n {
        let prev = if lo == 0 { n - 1 } else { lo - 1 };
        if !joined[prev] || prev == hi || dist2(points[lo], points[j]) >= half2 {
            break;
        }
        lo = prev;
    }
    for _ in 0..n {
        let next = if hi + 1 == n { 0 } else { hi + 1 };
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
pub(super) fn unit_normal(a: [f64; 2], b: [f64; 2]) -> Option<[f64; 2]> {
    unit([a[1] - b[1], b[0] - a[0]])
}

#[inline(always)]
pub(super) fn unit(v: [f64; 2]) -> Option<[f64; 2]> {
    let len = (v[0] * v[0] + v[1] * v[1]).sqrt();
    (len > 1e-12).then(|| [v[0] / len, v[1] / len])
}

pub(super) fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}
