//! The mapping core of levelmap, after the scan-based SLAM of Wulf, Brenneke and Wagner
//! (section 4): nodes are collection positions, edges are odometry, scan matches (IDC) and
//! GPS fixes; the network is solved as full nonlinear least squares on SE(2) (beyond the
//! paper's linear solution). Pure library: no I/O, no async.

pub mod matching;
pub mod se2;

pub use se2::{Pose2, wrap_angle};
