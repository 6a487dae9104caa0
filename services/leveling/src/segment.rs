//! Obstacle/ground segmentation within each vertical base scan (paper 3.1, eqs. 3.2–3.3).
//!
//! Two forms share the paper's predicates and must agree point for point (a property test
//! checks it): [`segment_column_reference`] searches every lower point, as the equations read;
//! [`Segmenter`] is the fast form: a prefix maximum decides overhang in O(1), and the landmark
//! search walks down only while prefix bounds still allow a match.

use crate::scan::{CylPoint, Scan3d};
use serde::{Deserialize, Serialize};

/// Class of one point of a 3D scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum PointClass {
    /// No measurement, or outside the configured range limits.
    Invalid = 0,
    /// Ground or traversable: neither overhang nor landmark.
    Ground = 1,
    /// Vertically aligned surface standing on something below it (eq. 3.3): trunks, walls, cars.
    Landmark = 2,
    /// Has a farther point below it in its column (eq. 3.2): tree tops, roofs, bridge decks.
    Overhang = 3,
}

/// Segmentation thresholds. The defaults were chosen on the labelled KITTI frames and the
/// 3DTK and simulated scans; `docs/leveling.md` gives the reasoning.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentParams {
    /// R_t: minimum overhang distance (m). A point is overhang when a lower point of its
    /// column lies farther than this beyond it.
    pub min_overhang_distance_m: f32,
    /// H_t: minimum landmark height (m): the rise over a lower point that makes a landmark.
    pub min_landmark_height_m: f32,
    /// α_t: maximum misalignment from the vertical (degrees) of the line from the lower point.
    pub max_misalignment_deg: f32,
    /// Returns nearer than this horizontal distance (m) are invalid (robot body, dust).
    pub min_range_m: f32,
    /// Returns farther than this horizontal distance or height (m) are invalid.
    pub max_range_m: f32,
}

impl Default for SegmentParams {
    fn default() -> Self {
        SegmentParams {
            min_overhang_distance_m: 0.5,
            min_landmark_height_m: 0.3,
            max_misalignment_deg: 20.0,
            min_range_m: 0.3,
            max_range_m: 120.0,
        }
    }
}

impl SegmentParams {
    /// tan α_t.
    pub fn tan_alpha(&self) -> f32 {
        self.max_misalignment_deg.to_radians().tan()
    }

    /// H_max = R_t / tan α_t (eq. 3.3): the highest rise that still counts as "below".
    pub fn max_landmark_height_m(&self) -> f32 {
        self.min_overhang_distance_m / self.tan_alpha()
    }

    /// Checks that the thresholds describe a usable segmentation.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |name: &str, v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} must be a positive number, got {v}"))
            }
        };
        positive("min_overhang_distance_m", self.min_overhang_distance_m)?;
        positive("min_landmark_height_m", self.min_landmark_height_m)?;
        positive("max_range_m", self.max_range_m)?;
        if !(self.max_misalignment_deg > 0.0 && self.max_misalignment_deg < 90.0) {
            return Err(format!(
                "max_misalignment_deg must lie in (0, 90), got {}",
                self.max_misalignment_deg
            ));
        }
        if !(self.min_range_m >= 0.0 && self.min_range_m < self.max_range_m) {
            return Err(format!(
                "min_range_m must lie in [0, max_range_m), got {} (max {})",
                self.min_range_m, self.max_range_m
            ));
        }
        if self.max_landmark_height_m() <= self.min_landmark_height_m {
            return Err(format!(
                "H_max = R_t / tan(α_t) = {:.3} m must exceed min_landmark_height_m {}",
                self.max_landmark_height_m(),
                self.min_landmark_height_m
            ));
        }
        Ok(())
    }

    #[inline]
    fn in_range(&self, p: &CylPoint) -> bool {
        p.is_valid()
            && p.r_m >= self.min_range_m
            && p.r_m <= self.max_range_m
            && p.z_m.abs() <= self.max_range_m
    }
}

/// Eq. 3.2 for one pair: lower point `k` lies farther than `p_j` by more than R_t.
#[inline]
fn overhangs(r_k: f32, p_j: &CylPoint, r_t: f32) -> bool {
    r_k > p_j.r_m + r_t
}

/// Eq. 3.3 for one pair, written as the paper does: `p_k` is "below" `p_j`.
#[inline]
fn is_below(p_k: &CylPoint, p_j: &CylPoint, h_t: f32, h_max: f32, tan_alpha: f32) -> bool {
    let dz = p_j.z_m - p_k.z_m;
    h_t < dz && dz < h_max && ((p_j.r_m - p_k.r_m) / dz).abs() < tan_alpha
}

/// Literal form of eqs. 3.2–3.3: every pair of points (O(m²) per column). The specification
/// the fast form is tested against; slow on purpose.
pub fn segment_column_reference(
    points: &[CylPoint],
    params: &SegmentParams,
    out: &mut [PointClass],
) {
    let (r_t, h_t, tan_alpha, h_max) = (
        params.min_overhang_distance_m,
        params.min_landmark_height_m,
        params.tan_alpha(),
        params.max_landmark_height_m(),
    );
    for (j, p_j) in points.iter().enumerate() {
        out[j] = if !params.in_range(p_j) {
            PointClass::Invalid
        } else if points[..j]
            .iter()
            .any(|p_k| params.in_range(p_k) && overhangs(p_k.r_m, p_j, r_t))
        {
            PointClass::Overhang
        } else if points[..j]
            .iter()
            .any(|p_k| params.in_range(p_k) && is_below(p_k, p_j, h_t, h_max, tan_alpha))
        {
            PointClass::Landmark
        } else {
            PointClass::Ground
        };
    }
}

/// Points per class in one scan.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClassCounts {
    pub invalid: usize,
    pub ground: usize,
    pub landmark: usize,
    pub overhang: usize,
}

impl ClassCounts {
    pub fn of(classes: &[PointClass]) -> ClassCounts {
        let mut c = ClassCounts::default();
        for class in classes {
            match class {
                PointClass::Invalid => c.invalid += 1,
                PointClass::Ground => c.ground += 1,
                PointClass::Landmark => c.landmark += 1,
                PointClass::Overhang => c.overhang += 1,
            }
        }
        c
    }
}

/// Rounding slack (m) for the prefix bounds, so that pruning never rejects a pair the exact
/// predicate would accept.
const PRUNE_SLACK_M: f32 = 1e-3;

/// The fast segmentation, with buffers reused from scan to scan.
///
/// For a landmark candidate `j` a lower point `k` must satisfy, at once, `z_k < z_j − H_t`,
/// `r_k + z_k·tan α < r_j + z_j·tan α` and `r_k − z_k·tan α > r_j − z_j·tan α` (the cone of
/// eq. 3.3 with the division cleared). Prefix minima/maxima of these three quantities tell, for
/// every `k`, whether any point at or below `k` could still match; the downward walk stops as
/// soon as one bound rules all of them out. On ground and slopes the first check already
/// fails, so most points cost O(1); the walk is bounded by H_max in practice, never by m².
#[derive(Clone, Debug, Default)]
pub struct Segmenter {
    params: SegmentParams,
    min_z: Vec<f32>,
    min_u: Vec<f32>,
    max_v: Vec<f32>,
}

impl Segmenter {
    pub fn new(params: SegmentParams) -> Segmenter {
        Segmenter {
            params,
            min_z: Vec::new(),
            min_u: Vec::new(),
            max_v: Vec::new(),
        }
    }

    pub fn params(&self) -> &SegmentParams {
        &self.params
    }

    /// Classifies one column bottom-up into `out`; returns the index of its first landmark
    /// point (the one eq. 3.4 projects), if any.
    pub fn segment_column(&mut self, points: &[CylPoint], out: &mut [PointClass]) -> Option<usize> {
        let p = self.params;
        let (r_t, h_t, tan_a, h_max) = (
            p.min_overhang_distance_m,
            p.min_landmark_height_m,
            p.tan_alpha(),
            p.max_landmark_height_m(),
        );
        let m = points.len();
        self.min_z.resize(m, 0.0);
        self.min_u.resize(m, 0.0);
        self.max_v.resize(m, 0.0);
        let (min_z, min_u, max_v) = (
            &mut self.min_z[..],
            &mut self.min_u[..],
            &mut self.max_v[..],
        );

        let mut first_landmark = None;
        let (mut max_r, mut lo_z, mut lo_u, mut hi_v) = (
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
        );
        for (j, p_j) in points.iter().enumerate() {
            let valid = p.in_range(p_j);
            out[j] = if !valid {
                PointClass::Invalid
            } else if overhangs(max_r, p_j, r_t) {
                PointClass::Overhang
            } else {
                let (z_lim, u_j, v_j) = (
                    p_j.z_m - h_t,
                    p_j.r_m + tan_a * p_j.z_m,
                    p_j.r_m - tan_a * p_j.z_m,
                );
                let ruled_out = |k: usize| {
                    min_z[k] >= z_lim + PRUNE_SLACK_M
                        || min_u[k] >= u_j + PRUNE_SLACK_M
                        || max_v[k] <= v_j - PRUNE_SLACK_M
                };
                let mut landmark = false;
                for k in (0..j).rev() {
                    if ruled_out(k) {
                        break;
                    }
                    let p_k = &points[k];
                    if p.in_range(p_k) && is_below(p_k, p_j, h_t, h_max, tan_a) {
                        landmark = true;
                        break;
                    }
                }
                if landmark {
                    first_landmark.get_or_insert(j);
                    PointClass::Landmark
                } else {
                    PointClass::Ground
                }
            };
            if valid {
                max_r = max_r.max(p_j.r_m);
                lo_z = lo_z.min(p_j.z_m);
                lo_u = lo_u.min(p_j.r_m + tan_a * p_j.z_m);
                hi_v = hi_v.max(p_j.r_m - tan_a * p_j.z_m);
            }
            (min_z[j], min_u[j], max_v[j]) = (lo_z, lo_u, hi_v);
        }
        first_landmark
    }

    /// Classifies every point of `scan` into `classes` (resized to the point count) and
    /// returns, per column, the index into `scan.points` of its first landmark point.
    pub fn segment(&mut self, scan: &Scan3d, classes: &mut Vec<PointClass>) -> Vec<Option<u32>> {
        classes.clear();
        classes.resize(scan.points.len(), PointClass::Invalid);
        scan.columns
            .iter()
            .map(|c| {
                let range = c.start as usize..(c.start + c.len) as usize;
                self.segment_column(&scan.points[range.clone()], &mut classes[range])
                    .map(|j| c.start + j as u32)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn column(points: &[(f32, f32)]) -> Vec<CylPoint> {
        points
            .iter()
            .map(|&(r, z)| CylPoint {
                r_m: r,
                phi_rad: 0.0,
                z_m: z,
            })
            .collect()
    }

    fn classify(points: &[CylPoint], params: &SegmentParams) -> (Vec<PointClass>, Option<usize>) {
        let mut out = vec![PointClass::Invalid; points.len()];
        let first = Segmenter::new(*params).segment_column(points, &mut out);
        (out, first)
    }

    #[test]
    fn ground_then_wall_then_tree_crown() {
        use PointClass::*;
        // Flat ground 1.5 m below the sensor, a wall at 8 m, then a crown hanging over it.
        let points = column(&[
            (3.0, -1.5),
            (5.0, -1.5),
            (7.9, -1.5),
            (8.0, -1.35),
            (8.0, -0.9),
            (8.05, -0.4),
            (6.0, 1.5),
            (f32::NAN, 0.0),
        ]);
        let params = SegmentParams::default();
        let (classes, first) = classify(&points, &params);
        assert_eq!(
            classes,
            vec![
                Ground, Ground, Ground, Ground, Landmark, Landmark, Overhang, Invalid
            ]
        );
        assert_eq!(first, Some(4));
    }

    #[test]
    fn slope_is_ground_however_long() {
        // A 25° slope rising away from the robot: never within 20° of the vertical.
        let points: Vec<_> = (0..200)
            .map(|i| {
                let r = 2.0 + 0.2 * i as f32;
                CylPoint {
                    r_m: r,
                    phi_rad: 0.0,
                    z_m: -1.0 + (r - 2.0) * 0.466,
                }
            })
            .collect();
        let (classes, first) = classify(&points, &SegmentParams::default());
        assert!(classes.iter().all(|&c| c == PointClass::Ground));
        assert_eq!(first, None);
    }

    #[test]
    fn out_of_range_points_are_invalid() {
        let params = SegmentParams {
            max_range_m: 50.0,
            ..Default::default()
        };
        let (classes, _) = classify(
            &column(&[(0.1, -1.0), (60.0, -1.0), (10.0, 1e9), (10.0, -1.0)]),
            &params,
        );
        assert_eq!(&classes[..3], &[PointClass::Invalid; 3]);
        assert_eq!(classes[3], PointClass::Ground);
    }

    #[test]
    fn validate_rejects_nonsense() {
        assert!(SegmentParams::default().validate().is_ok());
        assert!(
            SegmentParams {
                max_misalignment_deg: 95.0,
                ..Default::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            SegmentParams {
                min_landmark_height_m: 5.0,
                ..Default::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            SegmentParams {
                min_overhang_distance_m: f32::NAN,
                ..Default::default()
            }
            .validate()
            .is_err()
        );
    }

    fn arb_point() -> impl Strategy<Value = CylPoint> {
        prop_oneof![
            9 => (0.0f32..30.0, -3.0f32..4.0).prop_map(|(r, z)| CylPoint { r_m: r, phi_rad: 0.0, z_m: z }),
            1 => Just(CylPoint::INVALID),
        ]
    }

    /// Columns shaped like real ones: a random walk up and out, with jumps (occlusion edges).
    fn arb_walk() -> impl Strategy<Value = Vec<CylPoint>> {
        prop::collection::vec(
            (-0.6f32..1.5, -0.3f32..0.6, prop::bool::weighted(0.05)),
            0..120,
        )
        .prop_map(|steps| {
            let (mut r, mut z) = (2.0f32, -1.5f32);
            steps
                .into_iter()
                .map(|(dr, dz, invalid)| {
                    r = (r + dr).max(0.05);
                    z += dz;
                    if invalid {
                        CylPoint::INVALID
                    } else {
                        CylPoint {
                            r_m: r,
                            phi_rad: 0.0,
                            z_m: z,
                        }
                    }
                })
                .collect()
        })
    }

    fn arb_params() -> impl Strategy<Value = SegmentParams> {
        (0.1f32..2.0, 0.05f32..0.5, 5.0f32..45.0).prop_map(|(r_t, h_t, a)| SegmentParams {
            min_overhang_distance_m: r_t,
            min_landmark_height_m: h_t,
            max_misalignment_deg: a,
            min_range_m: 0.2,
            max_range_m: 25.0,
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn fast_form_agrees_with_reference_on_random_columns(
            points in prop_oneof![prop::collection::vec(arb_point(), 0..80), arb_walk()],
            params in arb_params(),
        ) {
            let mut reference = vec![PointClass::Invalid; points.len()];
            segment_column_reference(&points, &params, &mut reference);
            let (fast, first) = classify(&points, &params);
            prop_assert_eq!(&fast, &reference);
            prop_assert_eq!(first, reference.iter().position(|&c| c == PointClass::Landmark));
        }
    }
}
