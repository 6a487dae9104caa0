//! Scan matching of 2D range scans (docs/slam.md, "Scan matching"): iterative dual
//! correspondence (Lu & Milios 1997) between two leveled scans gives the relative pose, its
//! covariance and a quality; a match below the [`QualityGate`] is rejected, never added as a
//! constraint.
//!
//! Reading order: [`Scan2`] (a scan as a bearing-ordered point set), the reference
//! contour (`contour`: the two correspondence rules), [`idc`] (the iteration), `validate`
//! (covariance and quality of the result), [`accept`] (the gate), [`refine`] (a
//! point-to-line polish of a match, against one scan or several). [`correlative`] finds a
//! scan in a submap without a good guess (branch and bound over a window, for loop
//! closure). [`metric`] scores poses against ground-truth relations (Kümmerle et al. 2009);
//! [`synthetic`] ray casts test scenes.

mod contour;
pub mod correlative;
mod idc;
pub mod metric;
mod refine;
mod scan;
pub mod synthetic;
mod validate;

pub use idc::{IdcParams, Match, idc};
pub use refine::{Prior, Reference, RefineParams, refine, refine_against};
pub use scan::Scan2;
#[cfg(feature = "solver")]
pub(crate) use validate::evaluate;
pub use validate::{QualityGate, accept};

use std::fmt;

/// Why two scans could not be matched. Never a panic: bad input and hopeless pairs end here.
#[derive(Clone, Debug, PartialEq)]
pub enum MatchError {
    /// `from_polar` got different numbers of bearings and ranges.
    LengthMismatch {
        /// Bearings given.
        bearings: usize,
        /// Ranges given.
        ranges: usize,
    },
    /// A scan has fewer valid returns than [`IdcParams::min_correspondences`].
    TooFewPoints {
        /// Which scan: "reference" or "current".
        scan: &'static str,
        /// Its valid returns.
        found: usize,
        /// Returns needed.
        needed: usize,
    },
    /// The initial pose has a NaN or infinite component.
    NonFiniteInitial,
    /// An iteration found too few correspondences of one rule: the scans do not overlap at
    /// this initial pose.
    TooFewCorrespondences {
        /// The iteration (from 1).
        iteration: u32,
        /// The rule: "closest-point" or "matching-range".
        rule: &'static str,
        /// Pairs found.
        found: usize,
        /// Pairs needed.
        needed: usize,
    },
    /// A parameter is out of its range.
    InvalidParams(String),
}

impl fmt::Display for MatchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MatchError::LengthMismatch { bearings, ranges } => {
                write!(f, "scan has {bearings} bearings but {ranges} ranges")
            }
            MatchError::TooFewPoints {
                scan,
                found,
                needed,
            } => {
                write!(f, "{scan} scan has {found} valid returns, {needed} needed")
            }
            MatchError::NonFiniteInitial => write!(f, "initial pose is not finite"),
            MatchError::TooFewCorrespondences {
                iteration,
                rule,
                found,
                needed,
            } => write!(
                f,
                "iteration {iteration}: {found} {rule} correspondences, {needed} needed (no overlap)"
            ),
            MatchError::InvalidParams(why) => write!(f, "invalid IDC parameters: {why}"),
        }
    }
}

impl std::error::Error for MatchError {}
