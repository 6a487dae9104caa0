//! A scan as the grid takes it: every beam in bearing order, with or without a return, so
//! that neighbouring beams can fill the wedge between them.

use crate::matching::Scan2;

/// A scan's beams in ascending bearing order: (bearing in rad, range in m or `None` for a
/// beam without a return).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BeamFan {
    beams: Vec<(f64, Option<f64>)>,
}

impl BeamFan {
    /// The beams, sorted by bearing; a beam with a non-finite bearing, or a range that is not
    /// finite and positive, is left out (a zero range is no return: give `None`).
    pub fn new(beams: impl IntoIterator<Item = (f64, Option<f64>)>) -> BeamFan {
        let mut beams: Vec<(f64, Option<f64>)> = beams
            .into_iter()
            .filter(|(b, r)| b.is_finite() && r.is_none_or(|r| r.is_finite() && r > 0.0))
            .collect();
        beams.sort_by(|a, b| a.0.total_cmp(&b.0));
        BeamFan { beams }
    }

    /// The returns of a matching scan (it holds no beam without a return).
    pub fn of_returns(scan: &Scan2) -> BeamFan {
        BeamFan::new(
            scan.bearings_rad()
                .iter()
                .zip(scan.ranges_m())
                .map(|(&b, &r)| (b, Some(r))),
        )
    }

    /// The beams, in ascending bearing.
    pub fn beams(&self) -> &[(f64, Option<f64>)] {
        &self.beams
    }

    /// Neighbouring beams (by index) whose bearings are at most `max_gap_rad` apart, the last
    /// and the first included when the fan closes the circle.
    pub fn neighbours(&self, max_gap_rad: f64) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        let n = self.beams.len();
        let wrap = (n > 2).then(|| (n - 1, 0));
        (0..n.saturating_sub(1))
            .map(|i| (i, i + 1))
            .chain(wrap)
            .filter_map(move |(i, j)| {
                let mut gap = self.beams[j].0 - self.beams[i].0;
                if j < i {
                    gap += std::f64::consts::TAU;
                }
                (gap > 0.0 && gap <= max_gap_rad).then_some((i, j, gap))
            })
    }
}
