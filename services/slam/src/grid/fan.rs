//! A scan as the grid takes it: every beam in bearing order, with or without a return, each
//! from the place it was seen from, so that neighbouring beams can fill the wedge between
//! them.

use crate::matching::Scan2;

/// One beam of a [`BeamFan`], in the scan's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FanBeam {
    /// Where the sensor was when it measured the beam (m): the scan's origin for a scan taken
    /// from one place, elsewhere for a column of a scan taken while driving.
    pub from_m: [f64; 2],
    /// Direction from `from_m` (rad).
    pub bearing_rad: f64,
    /// Range from `from_m` (m); `None` for a beam without a return.
    pub range_m: Option<f64>,
    /// A beam without a return: how far from `from_m` the space is known free (m; a
    /// leveled scan's column saw the ground that far). `None`: the grid's
    /// `no_return_free_m` applies.
    pub free_to_m: Option<f64>,
}

impl From<(f64, Option<f64>)> for FanBeam {
    /// A beam seen from the scan's origin: (bearing in rad, range in m or `None`).
    fn from((bearing_rad, range_m): (f64, Option<f64>)) -> FanBeam {
        FanBeam {
            from_m: [0.0, 0.0],
            bearing_rad,
            range_m,
            free_to_m: None,
        }
    }
}

/// A scan's beams in ascending bearing order (each bearing as seen from its own place).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BeamFan {
    beams: Vec<FanBeam>,
}

impl BeamFan {
    /// The beams, sorted by bearing; a beam with a non-finite bearing or place, a range that
    /// is not finite and positive (a zero range is no return: give `None`), or a negative or
    /// non-finite free length is left out.
    pub fn new(beams: impl IntoIterator<Item = impl Into<FanBeam>>) -> BeamFan {
        let mut beams: Vec<FanBeam> = beams
            .into_iter()
            .map(Into::into)
            .filter(|b| {
                b.bearing_rad.is_finite()
                    && b.from_m.iter().all(|v| v.is_finite())
                    && b.range_m.is_none_or(|r| r.is_finite() && r > 0.0)
                    && b.free_to_m.is_none_or(|r| r.is_finite() && r >= 0.0)
            })
            .collect();
        beams.sort_by(|a, b| a.bearing_rad.total_cmp(&b.bearing_rad));
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
    pub fn beams(&self) -> &[FanBeam] {
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
                let mut gap = self.beams[j].bearing_rad - self.beams[i].bearing_rad;
                if j < i {
                    gap += std::f64::consts::TAU;
                }
                (gap > 0.0 && gap <= max_gap_rad).then_some((i, j, gap))
            })
    }
}
