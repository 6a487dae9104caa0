//! Scoring a segmentation against per-point ground truth (labels or simulator truth).

use crate::segment::PointClass;
use serde::Serialize;

/// Share of landmark points, and of projected beams, that are not ground.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Precision {
    /// Landmark points with a scored truth.
    pub landmark_scored: usize,
    /// Of those, points whose truth is ground (false landmarks).
    pub landmark_on_ground: usize,
    /// Projected beams with a scored truth.
    pub beam_scored: usize,
    /// Of those, beams whose truth is ground (false beams).
    pub beam_on_ground: usize,
}

impl Precision {
    /// Scores `classes` and the projected points `first_landmarks`; `is_ground(i)` gives the
    /// truth of point `i` of the scan, `None` for points the truth does not score.
    pub fn score(
        classes: &[PointClass],
        first_landmarks: &[Option<u32>],
        is_ground: impl Fn(usize) -> Option<bool>,
    ) -> Precision {
        let mut p = Precision::default();
        for (i, _) in classes
            .iter()
            .enumerate()
            .filter(|(_, c)| **c == PointClass::Landmark)
        {
            if let Some(ground) = is_ground(i) {
                p.landmark_scored += 1;
                p.landmark_on_ground += ground as usize;
            }
        }
        for &i in first_landmarks.iter().flatten() {
            if let Some(ground) = is_ground(i as usize) {
                p.beam_scored += 1;
                p.beam_on_ground += ground as usize;
            }
        }
        p
    }

    /// Share of scored landmark points that are not ground (NaN when none was scored).
    pub fn landmark_precision(&self) -> f64 {
        1.0 - self.landmark_on_ground as f64 / self.landmark_scored as f64
    }

    /// Share of scored beams that are not ground (NaN when none was scored).
    pub fn beam_precision(&self) -> f64 {
        1.0 - self.beam_on_ground as f64 / self.beam_scored as f64
    }
}
