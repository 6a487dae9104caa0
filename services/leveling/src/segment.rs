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

    /// A real return within the range limits. Written as plain comparisons, which are false
    /// for NaN, because it runs for every point.
    #[inline]
    fn in_range(&self, p: &CylPoint) -> bool {
        // r > 0 excludes CylPoint::INVALID; NaN fails every comparison. φ is not checked:
        // CylPoint::from_xyz never gives a non-finite φ to a finite point.
        let min_r = self.min_range_m.max(f32::MIN_POSITIVE);
        (p.r_m >= min_r) & (p.r_m <= self.max_range_m) & (p.z_m.abs() <= self.max_range_m)
    }
}

/// The smaller of two numbers that are not NaN (in-range points): one instruction, where
/// `f32::min`'s NaN rule adds a blend to the running bounds' loop-carried chain.
#[inline]
fn min_of_numbers(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// The larger of two numbers that are not NaN; see [`min_of_numbers`].
#[inline]
fn max_of_numbers(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
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
    /// Points without a usable return.
    pub invalid: usize,
    /// Points on the ground or traversable.
    pub ground: usize,
    /// Points on a landmark, standing on a lower point (eq. 3.3).
    pub landmark: usize,
    /// Points with a farther point below them in their column (eq. 3.2).
    pub overhang: usize,
}

impl ClassCounts {
    /// Counts the classes of one scan's points.
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

/// Class by (overhang, landmark) flags; an overhang point is never tested for landmark.
const CLASS_OF: [PointClass; 4] = [
    PointClass::Ground,
    PointClass::Landmark,
    PointClass::Overhang,
    PointClass::Overhang,
];

/// The fast segmentation, with buffers reused from scan to scan.
///
/// For a landmark candidate `j` a lower point `k` must satisfy, at once, `z_k < z_j − H_t`,
/// `r_k + z_k·tan α < r_j + z_j·tan α` and `r_k − z_k·tan α > r_j − z_j·tan α` (the cone of
/// eq. 3.3 with the division cleared). Prefix minima/maxima of these three quantities tell, for
/// every `k`, whether any point at or below `k` could still match; the downward walk stops as
/// soon as one bound rules all of them out. On ground and slopes the running bounds already
/// fail, so most points cost O(1) (measured on KITTI: 2.5 steps per point on average).
#[derive(Clone, Debug, Default)]
pub struct Segmenter {
    params: SegmentParams,
    tan_alpha: f32,
    max_height_m: f32,
    /// Prefix bounds over the valid points 0..=k of the column being segmented.
    bounds: Vec<PrefixBounds>,
}

/// Over a column's valid points up to some index: min z, min (r + z·tan α), max (r − z·tan α).
#[derive(Clone, Copy, Debug, Default)]
struct PrefixBounds {
    min_z: f32,
    min_u: f32,
    max_v: f32,
}

impl Segmenter {
    /// A segmenter with its parameters and empty buffers.
    pub fn new(params: SegmentParams) -> Segmenter {
        Segmenter {
            params,
            tan_alpha: params.tan_alpha(),
            max_height_m: params.max_landmark_height_m(),
            bounds: Vec::new(),
        }
    }

    /// The parameters it segments with.
    pub fn params(&self) -> &SegmentParams {
        &self.params
    }

    /// Classifies one column bottom-up into `out`; returns the index of its first landmark
    /// point (the one eq. 3.4 projects), if any.
    pub fn segment_column(&mut self, points: &[CylPoint], out: &mut [PointClass]) -> Option<usize> {
        let mut counts = ClassCounts::default();
        self.segment_column_counting(points, out, &mut counts)
    }

    fn segment_column_counting(
        &mut self,
        points: &[CylPoint],
        out: &mut [PointClass],
        counts: &mut ClassCounts,
    ) -> Option<usize> {
        let params = &self.params;
        let (r_t, h_t, tan_a, h_max) = (
            params.min_overhang_distance_m,
            params.min_landmark_height_m,
            self.tan_alpha,
            self.max_height_m,
        );
        let out = &mut out[..points.len()];
        // Grown only, never shrunk: a resize per column would refill slots every point
        // overwrites before the walk reads them.
        if self.bounds.len() < points.len() {
            self.bounds.resize(points.len(), PrefixBounds::default());
        }
        let bounds = &mut self.bounds[..points.len()];

        // A valid lower point that was "below" an earlier landmark of this column.
        let mut witness: Option<usize> = None;
        let mut first_landmark = None;
        // Counters in registers: a per-class array in memory would chain every point through
        // a store and a load.
        let (mut n_invalid, mut n_landmark, mut n_overhang) = (0usize, 0usize, 0usize);
        let mut max_r = f32::NEG_INFINITY;
        let mut running = PrefixBounds {
            min_z: f32::INFINITY,
            min_u: f32::INFINITY,
            max_v: f32::NEG_INFINITY,
        };
        for (j, p_j) in points.iter().enumerate() {
            let class = if !params.in_range(p_j) {
                n_invalid += 1;
                PointClass::Invalid
            } else {
                let (r_j, z_j) = (p_j.r_m, p_j.z_m);
                let (u_j, v_j) = (r_j + tan_a * z_j, r_j - tan_a * z_j);
                let (z_lim, u_lim, v_lim) = (
                    z_j - h_t + PRUNE_SLACK_M,
                    u_j + PRUNE_SLACK_M,
                    v_j - PRUNE_SLACK_M,
                );
                let overhang = max_r > r_j + r_t;
                // The running bounds are the prefix bounds at j − 1: the O(1) rejection,
                // evaluated without short-circuit branches since it decides most points.
                let mut landmark = false;
                if !overhang
                    & (running.min_z < z_lim)
                    & (running.min_u < u_lim)
                    & (running.max_v > v_lim)
                {
                    // The point that made the last landmark usually lies below this one too
                    // (same surface, a little higher): try it before walking down.
                    landmark = witness.is_some_and(|k: usize| {
                        points
                            .get(k)
                            .is_some_and(|p_k| is_below(p_k, p_j, h_t, h_max, tan_a))
                    });
                    if !landmark {
                        for k in (0..j).rev() {
                            let b = &bounds[k];
                            if (b.min_z >= z_lim) | (b.min_u >= u_lim) | (b.max_v <= v_lim) {
                                break;
                            }
                            let p_k = &points[k];
                            if params.in_range(p_k) && is_below(p_k, p_j, h_t, h_max, tan_a) {
                                landmark = true;
                                witness = Some(k);
                                break;
                            }
                        }
                    }
                    if landmark && first_landmark.is_none() {
                        first_landmark = Some(j);
                    }
                }
                max_r = max_of_numbers(max_r, r_j);
                running = PrefixBounds {
                    min_z: min_of_numbers(running.min_z, z_j),
                    min_u: min_of_numbers(running.min_u, u_j),
                    max_v: max_of_numbers(running.max_v, v_j),
                };
                n_landmark += landmark as usize;
                n_overhang += overhang as usize;
                CLASS_OF[overhang as usize * 2 + landmark as usize]
            };
            out[j] = class;
            bounds[j] = running;
        }
        counts.invalid += n_invalid;
        counts.landmark += n_landmark;
        counts.overhang += n_overhang;
        counts.ground += points.len() - n_invalid - n_landmark - n_overhang;
        first_landmark
    }

    /// Classifies every point of `scan` into `classes` (resized to the point count); returns,
    /// per column, the index into `scan.points` of its first landmark point, and the counts.
    pub fn segment(
        &mut self,
        scan: &Scan3d,
        classes: &mut Vec<PointClass>,
    ) -> (Vec<Option<u32>>, ClassCounts) {
        classes.clear();
        classes.resize(scan.points.len(), PointClass::Invalid);
        let mut counts = ClassCounts::default();
        let first = scan
            .columns
            .iter()
            .map(|c| {
                let range = c.start as usize..(c.start + c.len) as usize;
                self.segment_column_counting(
                    &scan.points[range.clone()],
                    &mut classes[range],
                    &mut counts,
                )
                .map(|j| c.start + j as u32)
            })
            .collect();
        (first, counts)
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

        /// Whole scans: each column must come out as the reference form says, whatever the
        /// columns around it (the segmenter reuses its buffers from column to column).
        #[test]
        fn whole_scans_agree_with_reference_column_by_column(
            columns in prop::collection::vec(prop_oneof![prop::collection::vec(arb_point(), 0..40), arb_walk()], 0..20),
            params in arb_params(),
        ) {
            let mut scan = Scan3d::default();
            for column in &columns {
                scan.begin_column(0);
                column.iter().for_each(|p| scan.push(*p));
            }
            let mut classes = Vec::new();
            let (first, counts) = Segmenter::new(params).segment(&scan, &mut classes);
            prop_assert_eq!(first.len(), columns.len());
            for (i, c) in scan.columns.iter().enumerate() {
                let points = scan.column_points(i);
                let mut reference = vec![PointClass::Invalid; points.len()];
                segment_column_reference(points, &params, &mut reference);
                let range = c.start as usize..(c.start + c.len) as usize;
                prop_assert_eq!(&classes[range], &reference[..]);
                prop_assert_eq!(first[i], reference.iter().position(|&k| k == PointClass::Landmark).map(|j| c.start + j as u32));
            }
            prop_assert_eq!(counts, ClassCounts::of(&classes));
        }
    }
}
